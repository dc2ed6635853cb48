/* Run by capi/tests/c_api.rs under `ulimit -v` (an address-space limit of about 3 GB): an
 * image too large for the limit is refused with DOFRAY_RESOURCE_LIMIT and a message naming
 * the limit, and the host process lives on to render a small image. Usage: memory. Exit
 * status 0 when every check passed. */
#include <stdio.h>
#include <string.h>

#include "dofray.h"

static int failures = 0;

#define CHECK(cond)                                                                   \
    do {                                                                              \
        if (!(cond)) {                                                                \
            fprintf(stderr, "%s:%d: check failed: %s (last error: %s)\n", __FILE__,   \
                    __LINE__, #cond, dofray_last_error_message());                    \
            failures++;                                                               \
        }                                                                             \
    } while (0)

int main(void) {
    DofrayScene *scene = NULL;
    DofrayImage *image = NULL;
    CHECK(dofray_scene_load("paper", &scene) == DOFRAY_OK);
    if (scene == NULL) return 1;

    /* 1 x 200,000,000 pixels: about 24 GiB of render buffers. */
    CHECK(dofray_scene_set_size(scene, 1, 200000000) == DOFRAY_OK);
    DofrayStatus s = dofray_render(scene, NULL, NULL, NULL, NULL, &image);
    const char *m = dofray_last_error_message();
    printf("huge render -> %s: %s\n", dofray_status_name(s), m);
    CHECK(s == DOFRAY_RESOURCE_LIMIT);
    CHECK(strstr(m, "1x200000000") != NULL);
    CHECK(strstr(m, "address-space limit") != NULL);
    CHECK(image == NULL);

    /* The process is still here, and renders what fits. */
    CHECK(dofray_scene_set_size(scene, 32, 24) == DOFRAY_OK);
    CHECK(dofray_scene_set_spp(scene, 4) == DOFRAY_OK);
    CHECK(dofray_render(scene, NULL, NULL, NULL, NULL, &image) == DOFRAY_OK);
    CHECK(image != NULL);
    if (image != NULL) {
        CHECK(dofray_image_width(image) == 32 && dofray_image_height(image) == 24);
        dofray_image_free(image);
    }
    dofray_scene_free(scene);
    if (failures > 0) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("memory checks passed\n");
    return 0;
}
