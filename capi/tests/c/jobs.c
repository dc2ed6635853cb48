/* The C API's job-loop test (compiled and run by capi/tests/c_api.rs): frames of an animated
 * scene rendered to a frame pattern, re-run with skip_existing, refused with no_overwrite and
 * fail_fast, a 2x2 tiled still merged, a cancelled run, bad options.
 * Usage: jobs SCENE.toml (run in the output directory). Exit status 0 when every check passed. */
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

struct job_log {
    int calls;
    size_t last_count;
    int64_t frames[8];
    int cancel_at; /* return nonzero at this call (1-based); 0: never */
};

static int on_job(size_t index, size_t count, int64_t frame, int has_frame, const char *output,
                  void *user_data) {
    struct job_log *log = user_data;
    printf("job %zu/%zu: %s (frame %lld, has_frame %d)\n", index + 1, count, output,
           (long long)frame, has_frame);
    if (log->calls < 8) log->frames[log->calls] = has_frame ? frame : -1;
    log->calls++;
    log->last_count = count;
    return log->cancel_at != 0 && log->calls >= log->cancel_at;
}

static int file_exists(const char *path) {
    FILE *f = fopen(path, "rb");
    if (f == NULL) return 0;
    fclose(f);
    return 1;
}

static void print_summary(const DofrayJobs *jobs) {
    printf("%zu jobs: %zu rendered, %zu skipped, %zu failed, %zu merged\n",
           dofray_jobs_count(jobs), dofray_jobs_rendered(jobs), dofray_jobs_skipped(jobs),
           dofray_jobs_failed(jobs), dofray_jobs_merged(jobs));
}

/* Three frames to shot_##.png, then the same again with skip_existing (nothing renders). */
static void frames_then_skip(DofrayScene *scene) {
    DofrayJobOptions options = {0};
    options.frames = "1-3";
    struct job_log log = {0};
    DofrayJobs *jobs = NULL;
    CHECK(dofray_render_jobs(scene, NULL, "frames/shot_##.png", &options, on_job, &log, NULL,
                             &jobs) == DOFRAY_OK);
    CHECK(jobs != NULL);
    print_summary(jobs);
    CHECK(dofray_jobs_count(jobs) == 3 && dofray_jobs_rendered(jobs) == 3);
    CHECK(dofray_jobs_skipped(jobs) == 0 && dofray_jobs_failed(jobs) == 0);
    CHECK(dofray_jobs_first_failure(jobs) == DOFRAY_OK);
    CHECK(strcmp(dofray_jobs_first_failure_message(jobs), "") == 0);
    CHECK(log.calls == 3 && log.last_count == 3);
    CHECK(log.frames[0] == 1 && log.frames[1] == 2 && log.frames[2] == 3);
    int64_t frame = 0;
    CHECK(dofray_jobs_frame(jobs, 2, &frame) == 1 && frame == 3);
    CHECK(strcmp(dofray_jobs_output(jobs, 0), "frames/shot_01.png") == 0);
    CHECK(dofray_jobs_status(jobs, 1) == DOFRAY_JOB_RENDERED);
    CHECK(dofray_jobs_error(jobs, 1) == DOFRAY_OK);
    CHECK(strcmp(dofray_jobs_error_message(jobs, 1), "") == 0);
    /* Out of range: the fallbacks. */
    CHECK(dofray_jobs_output(jobs, 3) == NULL);
    CHECK(dofray_jobs_status(jobs, 3) == DOFRAY_JOB_NOT_RUN);
    CHECK(dofray_jobs_error(jobs, 3) == DOFRAY_INVALID_ARGUMENT);
    CHECK(dofray_jobs_frame(jobs, 3, &frame) == 0);
    dofray_jobs_free(jobs);
    CHECK(file_exists("frames/shot_01.png") && file_exists("frames/shot_02.png") &&
          file_exists("frames/shot_03.png"));

    options.skip_existing = 1;
    struct job_log again = {0};
    jobs = NULL;
    CHECK(dofray_render_jobs(scene, NULL, "frames/shot_##.png", &options, on_job, &again,
                             NULL, &jobs) == DOFRAY_OK);
    print_summary(jobs);
    CHECK(dofray_jobs_count(jobs) == 3 && dofray_jobs_skipped(jobs) == 3);
    CHECK(dofray_jobs_rendered(jobs) == 0 && again.calls == 0);
    CHECK(dofray_jobs_status(jobs, 0) == DOFRAY_JOB_SKIPPED);
    dofray_jobs_free(jobs);
}

/* no_overwrite refuses the frames that exist; with fail_fast the run stops at the first. */
static void refused(DofrayScene *scene) {
    DofrayJobOptions options = {0};
    options.frames = "1-3";
    options.no_overwrite = 1;
    options.fail_fast = 1;
    DofrayJobs *jobs = NULL;
    CHECK(dofray_render_jobs(scene, NULL, "frames/shot_##.png", &options, NULL, NULL, NULL,
                             &jobs) == DOFRAY_OK);
    print_summary(jobs);
    CHECK(dofray_jobs_failed(jobs) == 1 && dofray_jobs_rendered(jobs) == 0);
    CHECK(dofray_jobs_status(jobs, 0) == DOFRAY_JOB_FAILED);
    CHECK(dofray_jobs_error(jobs, 0) == DOFRAY_IO);
    printf("refused: %s\n", dofray_jobs_error_message(jobs, 0));
    CHECK(strstr(dofray_jobs_error_message(jobs, 0), "shot_01.png") != NULL);
    CHECK(dofray_jobs_status(jobs, 1) == DOFRAY_JOB_NOT_RUN);
    CHECK(dofray_jobs_status(jobs, 2) == DOFRAY_JOB_NOT_RUN);
    CHECK(dofray_jobs_first_failure(jobs) == DOFRAY_IO);
    CHECK(strstr(dofray_jobs_first_failure_message(jobs), "exists") != NULL);
    dofray_jobs_free(jobs);
}

/* A still (the output has no frame pattern) in 2x2 tiles, merged and the tiles removed. */
static void tiled_still(DofrayScene *scene) {
    DofrayJobOptions options = {0};
    options.tile_columns = 2;
    options.tile_rows = 2;
    struct job_log log = {0};
    DofrayJobs *jobs = NULL;
    CHECK(dofray_render_jobs(scene, NULL, "still.png", &options, on_job, &log, NULL, &jobs) ==
          DOFRAY_OK);
    print_summary(jobs);
    CHECK(dofray_jobs_count(jobs) == 4 && dofray_jobs_rendered(jobs) == 4);
    CHECK(dofray_jobs_merged(jobs) == 1);
    CHECK(log.calls == 4 && log.frames[0] == -1);
    CHECK(dofray_jobs_frame(jobs, 0, NULL) == 0);
    CHECK(strcmp(dofray_jobs_output(jobs, 3), "still.tile-003.png") == 0);
    CHECK(file_exists("still.png"));
    CHECK(!file_exists(dofray_jobs_output(jobs, 0)));
    dofray_jobs_free(jobs);
}

/* Cancelled by the callback at the second job: no summary, the first frame written. */
static void cancelled(DofrayScene *scene) {
    DofrayJobOptions options = {0};
    options.frames = "4-6";
    struct job_log log = {0};
    log.cancel_at = 2;
    DofrayJobs *jobs = NULL;
    DofrayStatus s = dofray_render_jobs(scene, NULL, "frames/shot_##.png", &options, on_job,
                                        &log, NULL, &jobs);
    printf("cancelled run -> %s: %s\n", dofray_status_name(s), dofray_last_error_message());
    CHECK(s == DOFRAY_CANCELLED && jobs == NULL && log.calls == 2);
    CHECK(file_exists("frames/shot_04.png") && !file_exists("frames/shot_05.png"));

    DofrayCancel *token = NULL;
    CHECK(dofray_cancel_new(&token) == DOFRAY_OK);
    dofray_cancel(token);
    s = dofray_render_jobs(scene, NULL, "frames/shot_##.png", &options, NULL, NULL, token, &jobs);
    CHECK(s == DOFRAY_CANCELLED && jobs == NULL);
    dofray_cancel_free(token);
}

/* Bad options and arguments: a status and a message, never a crash. */
static void bad_arguments(DofrayScene *scene) {
    DofrayJobOptions options = {0};
    DofrayJobs *jobs = NULL;
    options.frames = "1-x";
    CHECK(dofray_render_jobs(scene, NULL, "f_##.png", &options, NULL, NULL, NULL, &jobs) ==
          DOFRAY_USAGE);
    CHECK(strstr(dofray_last_error_message(), "frame list") != NULL);
    options.frames = "1-3";
    CHECK(dofray_render_jobs(scene, NULL, "one.png", &options, NULL, NULL, NULL, &jobs) ==
          DOFRAY_USAGE);
    options.frames = NULL;
    options.tile_columns = 1000;
    options.tile_rows = 1;
    CHECK(dofray_render_jobs(scene, NULL, "t.png", &options, NULL, NULL, NULL, &jobs) ==
          DOFRAY_USAGE);
    CHECK(strstr(dofray_last_error_message(), "tiles") != NULL);
    options.tile_columns = 0;
    options.tile_rows = 0;
    options.shard_index = 2;
    options.shard_count = 2;
    CHECK(dofray_render_jobs(scene, NULL, "t.png", &options, NULL, NULL, NULL, &jobs) ==
          DOFRAY_USAGE);
    CHECK(strstr(dofray_last_error_message(), "shard") != NULL);
    options.shard_index = 0;
    options.shard_count = 0;
    options.skip_existing = 1;
    options.no_overwrite = 1;
    CHECK(dofray_render_jobs(scene, NULL, "t.png", &options, NULL, NULL, NULL, &jobs) ==
          DOFRAY_USAGE);
    CHECK(jobs == NULL);
    CHECK(dofray_render_jobs(NULL, NULL, "t.png", NULL, NULL, NULL, NULL, &jobs) ==
          DOFRAY_INVALID_ARGUMENT);
    CHECK(dofray_render_jobs(scene, NULL, NULL, NULL, NULL, NULL, NULL, &jobs) ==
          DOFRAY_INVALID_ARGUMENT);
    CHECK(dofray_render_jobs(scene, NULL, "t.png", NULL, NULL, NULL, NULL, NULL) ==
          DOFRAY_INVALID_ARGUMENT);
    /* A bad setting is named by its setter. */
    CHECK(dofray_scene_set_spp(scene, 0) == DOFRAY_OK);
    CHECK(dofray_render_jobs(scene, NULL, "t.png", NULL, NULL, NULL, NULL, &jobs) ==
          DOFRAY_USAGE);
    CHECK(strstr(dofray_last_error_message(), "dofray_scene_set_spp") != NULL);
    CHECK(dofray_scene_set_spp(scene, 4) == DOFRAY_OK);
    CHECK(dofray_jobs_count(NULL) == 0 && dofray_jobs_output(NULL, 0) == NULL);
    CHECK(dofray_jobs_first_failure(NULL) == DOFRAY_INVALID_ARGUMENT);
    dofray_jobs_free(NULL);
}

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: jobs SCENE.toml\n");
        return 2;
    }
    DofrayScene *scene = NULL;
    CHECK(dofray_scene_load(argv[1], &scene) == DOFRAY_OK);
    if (scene == NULL) return 1;
    CHECK(dofray_scene_set_size(scene, 32, 24) == DOFRAY_OK);
    CHECK(dofray_scene_set_spp(scene, 4) == DOFRAY_OK);
    CHECK(dofray_scene_set_aa(scene, 1) == DOFRAY_OK);

    frames_then_skip(scene);
    refused(scene);
    tiled_still(scene);
    cancelled(scene);
    bad_arguments(scene);

    dofray_scene_free(scene);
    if (failures != 0) {
        fprintf(stderr, "%d checks failed\n", failures);
        return 1;
    }
    printf("all checks passed\n");
    return 0;
}
