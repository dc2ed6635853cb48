/* The C API's test program (compiled and run by capi/tests/c_api.rs): a render with a
 * progress callback and its buffers, files written, error paths, cancelled renders, NULL
 * handles. Usage: smoke OUTPUT_DIR. Exit status 0 when every check passed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
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

/* A status, and the last error message containing `needle`. */
#define CHECK_ERROR(call, status, needle)                                             \
    do {                                                                              \
        DofrayStatus s_ = (call);                                                     \
        const char *m_ = dofray_last_error_message();                                 \
        printf("%s -> %s: %s\n", #call, dofray_status_name(s_), m_);                  \
        if (s_ != (status) || strstr(m_, (needle)) == NULL) {                         \
            fprintf(stderr, "%s:%d: %s gave %s (%s), expected %s with \"%s\"\n",      \
                    __FILE__, __LINE__, #call, dofray_status_name(s_), m_,            \
                    dofray_status_name(status), needle);                              \
            failures++;                                                               \
        }                                                                             \
    } while (0)

struct progress_log {
    int calls;
    int phases;           /* calls with done == 0 */
    int cancel_at;        /* cancel at this call (1-based); 0: never */
    int out_of_range;     /* calls with done > total */
    char first_phase[32];
    DofrayCancel *token;  /* cancelled (and 0 returned) at the first call, if not NULL */
};

static int on_progress(const char *phase, uint64_t done, uint64_t total, void *user_data) {
    struct progress_log *log = user_data;
    log->calls++;
    if (done == 0) log->phases++;
    if (done > total) log->out_of_range++;
    if (log->calls == 1) snprintf(log->first_phase, sizeof log->first_phase, "%s", phase);
    if (log->token != NULL) dofray_cancel(log->token);
    return log->cancel_at != 0 && log->calls >= log->cancel_at;
}

static int file_exists(const char *path) {
    FILE *f = fopen(path, "rb");
    if (f == NULL) return 0;
    fclose(f);
    return 1;
}

/* adaptive: the scene is in adaptive mode (with sample reuse, the default), else dense. */
static void render_and_check(DofrayScene *scene, DofrayDevice *device, const char *dir,
                             int adaptive) {
    struct progress_log log = {0};
    DofrayImage *image = NULL;
    CHECK(dofray_render(scene, device, on_progress, &log, NULL, &image) == DOFRAY_OK);
    CHECK(image != NULL);
    if (image == NULL) return;
    printf("progress: %d calls, %d phases, first \"%s\"\n", log.calls, log.phases,
           log.first_phase);
    CHECK(log.phases >= 2); /* depth, then adaptive */
    CHECK(strcmp(log.first_phase, "depth") == 0);
    CHECK(log.out_of_range == 0);

    uint32_t w = dofray_image_width(image), h = dofray_image_height(image);
    CHECK(w == 64 && h == 48);
    const float *rgba = dofray_image_rgba(image);
    const float *depth = dofray_image_depth(image);
    const float *coc = dofray_image_coc(image);
    CHECK(rgba != NULL && depth != NULL && coc != NULL);
    size_t n = (size_t)w * h, hits = 0, lit = 0, bad = 0;
    double sum = 0;
    for (size_t i = 0; i < n; i++) {
        for (int c = 0; c < 4; c++) {
            float v = rgba[4 * i + c];
            if (!isfinite(v) || v < 0) bad++;
            if (c < 3) sum += v;
        }
        if (rgba[4 * i + 3] != 1.0f) bad++; /* opaque background */
        if (rgba[4 * i] + rgba[4 * i + 1] + rgba[4 * i + 2] > 0) lit++;
        if (isfinite(depth[i])) {
            hits++;
            if (!(depth[i] > 0)) bad++;
        } else if (!(isinf(depth[i]) && depth[i] > 0)) {
            bad++; /* a miss is +inf, never NaN */
        }
        if (!isfinite(coc[i]) || coc[i] < 0) bad++;
    }
    printf("%ux%u: %zu hits, %zu lit pixels, mean %.4f, %llu rays, %llu sites, %.3f s\n", w, h,
           hits, lit, sum / (3.0 * n), (unsigned long long)dofray_image_rays(image),
           (unsigned long long)dofray_image_sample_sites(image), dofray_image_seconds(image));
    CHECK(bad == 0);
    CHECK(hits > n / 2); /* paper's floor and objects fill most of the picture */
    CHECK(lit > n / 2);
    CHECK(dofray_image_rays(image) >= n);
    CHECK(dofray_image_sample_sites(image) > 0);
    CHECK(dofray_image_sample_sites(image) <= n);
    CHECK(dofray_image_seconds(image) >= 0);
    /* paper at f/0.5 blurs its near floor; adaptive sites lend to each other, dense's never */
    CHECK(dofray_image_defocused_sites(image) > 0);
    CHECK(dofray_image_defocused_sites(image) <= dofray_image_sample_sites(image));
    CHECK(adaptive ? dofray_image_borrowing_sites(image) > 0
                   : dofray_image_borrowing_sites(image) == 0);
    CHECK(dofray_image_borrowing_sites(image) <= dofray_image_defocused_sites(image));

    char path[4096];
    snprintf(path, sizeof path, "%s/smoke.png", dir);
    remove(path);
    CHECK(dofray_image_write(image, path) == DOFRAY_OK);
    CHECK(file_exists(path));
    snprintf(path, sizeof path, "%s/smoke.exr", dir);
    remove(path);
    CHECK(dofray_image_write(image, path) == DOFRAY_OK);
    CHECK(file_exists(path));
    snprintf(path, sizeof path, "%s/smoke.jpg", dir);
    CHECK_ERROR(dofray_image_write(image, path), DOFRAY_USAGE, "smoke.jpg");
    snprintf(path, sizeof path, "%s/no/such/dir/smoke.png", dir);
    CHECK_ERROR(dofray_image_write(image, path), DOFRAY_IO, "smoke.png");
    dofray_image_free(image);
}

static const char SPHERE[] =
    "[image]\nwidth = 32\nheight = 24\n\n"
    "[camera]\neye = [0, 0, 0]\nlook_at = [0, 0, 6]\naperture_radius = 0.1\n\n"
    "[[objects]]\ntype = \"sphere\"\ncenter = [0, 0, 6]\nradius = 1\n";

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s OUTPUT_DIR LENS_FILE\n", argv[0]);
        return 2;
    }
    const char *dir = argv[1];
    const char *lens = argv[2];
    printf("dofray %s\n", dofray_version());
    CHECK(strlen(dofray_version()) > 0);
    CHECK(strcmp(dofray_status_name(DOFRAY_CANCELLED), "cancelled") == 0);
    CHECK(strcmp(dofray_status_name(1234), "unknown") == 0);

    /* A render on a device of our own, with a progress callback. */
    DofrayDevice *device = NULL;
    CHECK(dofray_device_new("threads=2", &device) == DOFRAY_OK);
    CHECK(strcmp(dofray_last_error_message(), "") == 0);
    DofrayScene *scene = NULL;
    CHECK(dofray_scene_load("paper", &scene) == DOFRAY_OK);
    CHECK(dofray_scene_set_size(scene, 64, 48) == DOFRAY_OK);
    CHECK(dofray_scene_set_f_number(scene, 0.5f) == DOFRAY_OK);
    CHECK(dofray_scene_set_spp(scene, 8) == DOFRAY_OK);
    CHECK(dofray_scene_set_seed(scene, 7) == DOFRAY_OK);
    render_and_check(scene, device, dir, 1);
    /* Again, with a device the scene makes, in dense mode. */
    CHECK(dofray_scene_set_mode(scene, "dense") == DOFRAY_OK);
    render_and_check(scene, NULL, dir, 0);

    /* Cancelled from the callback: at its first call, then in the middle of a render. */
    DofrayImage *image = NULL;
    for (int at = 1; at <= 2; at++) {
        struct progress_log log = {0};
        log.cancel_at = at;
        image = (DofrayImage *)&log; /* must be reset to NULL */
        CHECK_ERROR(dofray_render(scene, device, on_progress, &log, NULL, &image),
                    DOFRAY_CANCELLED, "cancelled");
        CHECK(image == NULL);
        CHECK(log.calls == at); /* no calls after it said stop */
    }
    /* Cancelled by a token, before the render starts; reset, the same token renders. */
    DofrayCancel *token = NULL;
    CHECK(dofray_cancel_new(&token) == DOFRAY_OK);
    dofray_cancel(token);
    CHECK_ERROR(dofray_render(scene, device, NULL, NULL, token, &image), DOFRAY_CANCELLED,
                "cancelled");
    CHECK(image == NULL);
    /* Cancelled by the token during the render (as another thread would: the callback
     * only cancels the token and returns 0). */
    dofray_cancel_reset(token);
    {
        struct progress_log log = {0};
        log.token = token;
        CHECK_ERROR(dofray_render(scene, device, on_progress, &log, token, &image),
                    DOFRAY_CANCELLED, "cancelled");
        CHECK(image == NULL);
        CHECK(log.calls == 1);
    }
    dofray_cancel_reset(token);
    CHECK(dofray_render(scene, device, NULL, NULL, token, &image) == DOFRAY_OK);
    CHECK(dofray_image_width(image) == 64);
    dofray_image_free(image);
    image = NULL;
    dofray_cancel_free(token);

    /* Bad overrides: the render fails naming the setter; the scene stays usable. */
    CHECK(dofray_scene_set_f_number(scene, -1.0f) == DOFRAY_OK);
    CHECK_ERROR(dofray_render(scene, device, NULL, NULL, NULL, &image), DOFRAY_USAGE,
                "dofray_scene_set_f_number must be a finite number > 0");
    CHECK(image == NULL);
    CHECK(dofray_scene_set_f_number(scene, 4.0f) == DOFRAY_OK);
    CHECK(dofray_scene_set_spp(scene, 0) == DOFRAY_OK);
    CHECK_ERROR(dofray_render(scene, device, NULL, NULL, NULL, &image), DOFRAY_USAGE,
                "dofray_scene_set_spp must be 1 to 65536");
    CHECK_ERROR(dofray_scene_set_mode(scene, "fast"), DOFRAY_INVALID_ARGUMENT, "fast");
    CHECK(dofray_scene_reset_overrides(scene) == DOFRAY_OK);
    CHECK(dofray_scene_set_size(scene, 32, 0) == DOFRAY_OK); /* the height follows */
    CHECK(dofray_scene_set_mode(scene, "pinhole") == DOFRAY_OK);
    CHECK(dofray_render(scene, device, NULL, NULL, NULL, &image) == DOFRAY_OK);
    CHECK(dofray_image_width(image) == 32 && dofray_image_height(image) == 24);
    dofray_image_free(image);
    image = NULL;

    /* A real lens from its prescription file, stopped down; a broken file is bad input
     * naming its line, and leaves the scene's lens as it was. */
    CHECK(dofray_scene_reset_overrides(scene) == DOFRAY_OK);
    CHECK(dofray_scene_set_size(scene, 48, 32) == DOFRAY_OK);
    CHECK(dofray_scene_set_spp(scene, 4) == DOFRAY_OK);
    CHECK(dofray_scene_set_lens(scene, lens) == DOFRAY_OK);
    CHECK(dofray_scene_set_f_number(scene, 4.0f) == DOFRAY_OK);
    CHECK(dofray_render(scene, device, NULL, NULL, NULL, &image) == DOFRAY_OK);
    if (image != NULL) {
        const float *rgba = dofray_image_rgba(image);
        size_t centre = 16 * 48 + 24;
        printf("real lens: centre %.3f\n", rgba[4 * centre]);
        CHECK(rgba[4 * centre] > 0.0f && isfinite(rgba[4 * centre]));
    }
    dofray_image_free(image);
    image = NULL;
    char bad_lens[4096];
    snprintf(bad_lens, sizeof bad_lens, "%s/bad-lens.dat", dir);
    FILE *bad = fopen(bad_lens, "w");
    CHECK(bad != NULL);
    if (bad != NULL) {
        fputs("# bad\n10 2 1.5\n", bad);
        fclose(bad);
    }
    CHECK_ERROR(dofray_scene_set_lens(scene, bad_lens), DOFRAY_BAD_INPUT, "bad-lens.dat:2");
    CHECK(dofray_scene_set_lens(scene, NULL) == DOFRAY_OK);
    CHECK(dofray_scene_set_f_number(scene, -1.0f) == DOFRAY_OK);
    CHECK_ERROR(dofray_render(scene, device, NULL, NULL, NULL, &image), DOFRAY_USAGE,
                "dofray_scene_set_f_number");
    dofray_scene_free(scene);
    scene = NULL;

    /* A missing file: bad input, the message names it; no scene. */
    char path[4096];
    snprintf(path, sizeof path, "%s/missing-scene.toml", dir);
    scene = (DofrayScene *)path; /* must be reset to NULL */
    CHECK_ERROR(dofray_scene_load(path, &scene), DOFRAY_BAD_INPUT, "missing-scene.toml");
    CHECK(scene == NULL);
    CHECK_ERROR(dofray_scene_load("no-such-builtin", &scene), DOFRAY_BAD_INPUT,
                "no-such-builtin");

    /* A scene from a buffer; a broken one names the path it was given. */
    CHECK(dofray_scene_parse(SPHERE, strlen(SPHERE), "sphere.toml", &scene) == DOFRAY_OK);
    CHECK(dofray_scene_set_focus_distance(scene, 5.0f) == DOFRAY_OK);
    CHECK(dofray_scene_set_transparent(scene, 1) == DOFRAY_OK);
    CHECK(dofray_render(scene, device, NULL, NULL, NULL, &image) == DOFRAY_OK);
    if (image != NULL) {
        const float *rgba = dofray_image_rgba(image);
        const float *depth = dofray_image_depth(image);
        size_t centre = 12 * 32 + 16;
        printf("sphere: centre depth %.3f alpha %.3f, corner alpha %.3f\n", depth[centre],
               rgba[4 * centre + 3], rgba[3]);
        CHECK(fabsf(depth[centre] - 5.0f) < 0.05f);
        CHECK(rgba[4 * centre + 3] > 0.99f);
        CHECK(rgba[3] == 0.0f && isinf(depth[0])); /* the corner sees the background */
        snprintf(path, sizeof path, "%s/sphere.png", dir);
        CHECK(dofray_image_write(image, path) == DOFRAY_OK);
        CHECK(file_exists(path));
    }
    dofray_image_free(image);
    image = NULL;
    /* Autofocus on a pixel that sees nothing: the caller's camera, a usage error. */
    CHECK(dofray_scene_set_autofocus(scene, 0, 0) == DOFRAY_OK);
    CHECK_ERROR(dofray_render(scene, device, NULL, NULL, NULL, &image), DOFRAY_USAGE, "");
    dofray_scene_free(scene);
    scene = NULL;
    const char broken[] = "[camera]\neye = [0, 0\n";
    CHECK_ERROR(dofray_scene_parse(broken, strlen(broken), "broken.toml", &scene),
                DOFRAY_BAD_INPUT, "broken.toml");
    CHECK(scene == NULL);
    const char bad_utf8[] = "[image]\nwidth = \xff\n";
    CHECK_ERROR(dofray_scene_parse(bad_utf8, strlen(bad_utf8), NULL, &scene),
                DOFRAY_INVALID_ARGUMENT, "UTF-8");

    /* NULL handles and out-pointers: errors, never crashes. */
    CHECK_ERROR(dofray_scene_load(NULL, &scene), DOFRAY_INVALID_ARGUMENT, "NULL");
    CHECK_ERROR(dofray_scene_load("paper", NULL), DOFRAY_INVALID_ARGUMENT, "NULL");
    CHECK_ERROR(dofray_scene_set_spp(NULL, 4), DOFRAY_INVALID_ARGUMENT, "scene");
    CHECK_ERROR(dofray_render(NULL, device, NULL, NULL, NULL, &image), DOFRAY_INVALID_ARGUMENT,
                "scene");
    CHECK_ERROR(dofray_image_write(NULL, "x.png"), DOFRAY_INVALID_ARGUMENT, "image");
    CHECK(dofray_image_width(NULL) == 0 && dofray_image_rgba(NULL) == NULL);
    CHECK(dofray_image_defocused_sites(NULL) == 0 && dofray_image_borrowing_sites(NULL) == 0);
    CHECK(dofray_device_new("", NULL) == DOFRAY_INVALID_ARGUMENT);
    dofray_cancel(NULL);
    dofray_image_free(NULL);
    dofray_scene_free(NULL);
    dofray_device_free(NULL);
    dofray_cancel_free(NULL);
    dofray_device_free(device);

    if (failures != 0) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("all checks passed\n");
    return 0;
}
