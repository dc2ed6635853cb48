/* Renders the built-in "paper" scene at 64 x 48 with an f/2.8 lens to paper.png. */
#include <stdio.h>
#include "dofray.h"

static int on_progress(const char *phase, uint64_t done, uint64_t total, void *user_data) {
    (void)user_data;
    fprintf(stderr, "%s %llu/%llu\n", phase, (unsigned long long)done, (unsigned long long)total);
    return 0; /* nonzero cancels the render */
}

int main(void) {
    DofrayScene *scene = NULL;
    DofrayImage *image = NULL;
    int ok = dofray_scene_load("paper", &scene) == DOFRAY_OK
        && dofray_scene_set_size(scene, 64, 48) == DOFRAY_OK
        && dofray_scene_set_f_number(scene, 2.8f) == DOFRAY_OK
        && dofray_render(scene, NULL, on_progress, NULL, NULL, &image) == DOFRAY_OK
        && dofray_image_write(image, "paper.png") == DOFRAY_OK;
    if (ok) {
        const float *rgba = dofray_image_rgba(image); /* linear RGBA, 4 floats per pixel */
        printf("%ux%u, %llu rays, first pixel %.3f %.3f %.3f\n", dofray_image_width(image),
               dofray_image_height(image), (unsigned long long)dofray_image_rays(image),
               rgba[0], rgba[1], rgba[2]);
    } else {
        fprintf(stderr, "dofray: %s\n", dofray_last_error_message());
    }
    dofray_image_free(image); /* freeing NULL does nothing */
    dofray_scene_free(scene);
    return ok ? 0 : 1;
}
