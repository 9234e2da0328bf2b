/* Cost of the C ABI on top of the Rust push, measured in one process, interleaved:
 * rounds of 1000 frames pushed one call at a time (ikid_stream_push) against the same 1000
 * frames in one ikid_stream_push_many call (the loop inside Rust). Prints JSON with the
 * per-frame medians over rounds and the push latency p50/p99. For a marker model (18 values
 * a frame) also the latency of ikid_tracker_push over the same frames (as doubles; default
 * settings): `tracker_push_p50_us`/`_p99_us`, and with REFINER (e.g. the shipped
 * wrist-track) `tracker_refined_push_p50_us`/`_p99_us`.
 *   abi_overhead MODEL FRAMES.csv [REFINER] */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#include "ikid.h"

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

static int by_value(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

enum { N = 1000, ROUNDS = 200, SINGLES = 200000 };

/* p50 and p99 (us) of SINGLES ikid_tracker_push calls cycling through `frames` (N frames of
 * 18 doubles), after one pass to warm up; refiner may be NULL. Fails on a refused push. */
static int tracker_latency(const double *frames, const ikid_model *refiner, double *lat, double *p50, double *p99) {
    ikid_tracker_settings settings = ikid_tracker_settings_default();
    settings.rate_hz = 1000.0; /* the frames' rate */
    ikid_tracker *tracker = NULL;
    if (ikid_tracker_new(&settings, refiner, &tracker) != IKID_STATUS_OK) { fprintf(stderr, "%s\n", ikid_last_error()); return 1; }
    double out[12];
    ikid_tracker_flags flags;
    int status = 0;
    for (int i = 0; i < N + SINGLES && !status; i++) {
        double t0 = now_ns();
        if (ikid_tracker_push(tracker, frames + (i % N) * 18, 18, out, 12, &flags) != IKID_STATUS_OK) {
            fprintf(stderr, "tracker push %d: %s\n", i, ikid_last_error());
            status = 1;
        }
        if (i >= N) lat[i - N] = now_ns() - t0;
    }
    ikid_tracker_free(tracker);
    qsort(lat, SINGLES, sizeof *lat, by_value);
    *p50 = lat[SINGLES / 2] / 1e3;
    *p99 = lat[SINGLES * 99 / 100] / 1e3;
    return status;
}

int main(int argc, char **argv) {
    if (argc != 3 && argc != 4) { fprintf(stderr, "usage: %s MODEL FRAMES.csv [REFINER]\n", argv[0]); return 2; }
    ikid_model *model = NULL;
    if (ikid_model_load(argv[1], &model) != IKID_STATUS_OK) { fprintf(stderr, "%s\n", ikid_last_error()); return 1; }
    ikid_model_info info;
    ikid_model_get_info(model, &info);
    FILE *f = fopen(argv[2], "r");
    if (!f) return 1;
    float *frames = malloc(N * info.frame_len * sizeof *frames);
    for (size_t i = 0; i < N * info.frame_len; i++)
        if (fscanf(f, "%f%*[, \n]", &frames[i]) != 1) { fprintf(stderr, "need %d frames\n", N); return 1; }
    fclose(f);
    float *out = malloc(N * info.n_outputs * sizeof *out);
    ikid_stream *stream = NULL;
    ikid_stream_new(model, &stream);
    size_t rows;
    bool ready;
    ikid_stream_push_many(stream, frames, N, info.frame_len, out, N * info.n_outputs, &rows); /* warm up */

    double *diff = malloc(ROUNDS * sizeof *diff), *one = malloc(ROUNDS * sizeof *one), *many = malloc(ROUNDS * sizeof *many);
    for (int r = 0; r < ROUNDS; r++) {
        double t0 = now_ns();
        for (int i = 0; i < N; i++) ikid_stream_push(stream, frames + i * info.frame_len, info.frame_len, out, info.n_outputs, &ready);
        double t1 = now_ns();
        ikid_stream_push_many(stream, frames, N, info.frame_len, out, N * info.n_outputs, &rows);
        double t2 = now_ns();
        one[r] = (t1 - t0) / N;
        many[r] = (t2 - t1) / N;
        diff[r] = one[r] - many[r];
    }
    double *lat = malloc(SINGLES * sizeof *lat);
    for (int i = 0; i < SINGLES; i++) {
        double t0 = now_ns();
        ikid_stream_push(stream, frames + (i % N) * info.frame_len, info.frame_len, out, info.n_outputs, &ready);
        lat[i] = now_ns() - t0;
    }
    qsort(diff, ROUNDS, sizeof *diff, by_value);
    qsort(one, ROUNDS, sizeof *one, by_value);
    qsort(many, ROUNDS, sizeof *many, by_value);
    qsort(lat, SINGLES, sizeof *lat, by_value);
    printf("{\"push_per_frame_ns\": %.1f, \"push_many_per_frame_ns\": %.1f, \"abi_overhead_ns\": %.1f, "
           "\"push_p50_us\": %.3f, \"push_p99_us\": %.3f",
           one[ROUNDS / 2], many[ROUNDS / 2], diff[ROUNDS / 2], lat[SINGLES / 2] / 1e3, lat[SINGLES * 99 / 100] / 1e3);
    int status = 0;
    if (info.frame_len == 18) {
        double *marker_frames = malloc(N * 18 * sizeof *marker_frames), p50, p99;
        for (size_t i = 0; i < N * 18; i++) marker_frames[i] = frames[i];
        status |= tracker_latency(marker_frames, NULL, lat, &p50, &p99);
        printf(", \"tracker_push_p50_us\": %.3f, \"tracker_push_p99_us\": %.3f", p50, p99);
        if (argc == 4) {
            ikid_model *refiner = NULL;
            if (ikid_model_load(argv[3], &refiner) != IKID_STATUS_OK) { fprintf(stderr, "%s\n", ikid_last_error()); status = 1; }
            else {
                status |= tracker_latency(marker_frames, refiner, lat, &p50, &p99);
                printf(", \"tracker_refined_push_p50_us\": %.3f, \"tracker_refined_push_p99_us\": %.3f", p50, p99);
            }
            ikid_model_free(refiner);
        }
        free(marker_frames);
    }
    printf("}\n");
    ikid_stream_free(stream);
    ikid_model_free(model);
    free(frames); free(out); free(diff); free(one); free(many); free(lat);
    return status;
}
