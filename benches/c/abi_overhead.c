/* Cost of the C ABI on top of the Rust push, measured in one process, interleaved:
 * rounds of 1000 frames pushed one call at a time (ikid_stream_push) against the same 1000
 * frames in one ikid_stream_push_many call (the loop inside Rust). Prints JSON with the
 * per-frame medians over rounds and the push latency p50/p99.
 *   abi_overhead MODEL FRAMES.csv */
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

int main(int argc, char **argv) {
    if (argc != 3) return 2;
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
           "\"push_p50_us\": %.3f, \"push_p99_us\": %.3f}\n",
           one[ROUNDS / 2], many[ROUNDS / 2], diff[ROUNDS / 2], lat[SINGLES / 2] / 1e3, lat[SINGLES * 99 / 100] / 1e3);
    ikid_stream_free(stream);
    ikid_model_free(model);
    free(frames); free(out); free(diff); free(one); free(many); free(lat);
    return 0;
}
