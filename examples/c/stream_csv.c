/* A host program embedding libikid: load a model, stream a CSV trial frame by frame (one
 * frame per line, the model's frame_len values, e.g. 18 marker coordinates in metres),
 * print the predictions and the per-frame latency.
 *
 *   stream_csv MODEL.safetensors TRIAL.csv [--every N]
 *
 * Build: cc -O2 stream_csv.c $(pkg-config --cflags --libs ikid) -o stream_csv
 * (or `make c` in the repository). */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#include "ikid.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
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

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: %s MODEL.safetensors TRIAL.csv [--every N]\n", argv[0]);
        return 2;
    }
    long every = argc >= 5 && strcmp(argv[3], "--every") == 0 ? strtol(argv[4], NULL, 10) : 100;
    if (every < 1) every = 1;

    ikid_model *model = NULL;
    if (ikid_model_load(argv[1], &model) != IKID_STATUS_OK) {
        fprintf(stderr, "cannot load model: %s\n", ikid_last_error());
        return 1;
    }
    ikid_model_info info;
    ikid_model_get_info(model, &info);
    ikid_stream *stream = NULL;
    ikid_stream_new(model, &stream);

    FILE *csv = fopen(argv[2], "r");
    if (!csv) {
        perror(argv[2]);
        return 1;
    }
    float *frame = malloc(info.frame_len * sizeof *frame);
    float *out = malloc(info.n_outputs * sizeof *out);
    size_t cap = 1 << 16, n = 0;
    double *lat = malloc(cap * sizeof *lat);
    char line[8192];
    int status = 0;

    printf("frame");
    for (size_t k = 0; k < info.n_outputs; k++) printf(",%s", ikid_model_output_name(model, k));
    printf("\n");
    while (fgets(line, sizeof line, csv)) {
        char *p = line, *end;
        size_t k = 0;
        for (; k < info.frame_len; k++) {
            frame[k] = strtof(p, &end);
            if (end == p) break;
            p = end + (*end == ',');
        }
        if (k == 0) continue; /* header or blank line */
        bool ready = false;
        double t0 = now_ns();
        ikid_status s = ikid_stream_push(stream, frame, k, out, info.n_outputs, &ready);
        double dt = now_ns() - t0;
        if (s != IKID_STATUS_OK) {
            fprintf(stderr, "frame %zu: %s\n", n, ikid_last_error());
            status = 1;
            break;
        }
        if (n == cap) lat = realloc(lat, (cap *= 2) * sizeof *lat);
        lat[n] = dt;
        if (ready && n % (size_t)every == 0) {
            printf("%zu", n);
            for (size_t j = 0; j < info.n_outputs; j++) printf(",%.6f", out[j]);
            printf("\n");
        }
        n++;
    }
    fclose(csv);
    if (n > info.window) {
        size_t m = n - info.window; /* frames that ran the network */
        qsort(lat + info.window, m, sizeof *lat, by_value);
        fprintf(stderr, "%zu frames; ikid_stream_push latency p50 %.2f us, p99 %.2f us\n", n,
                lat[info.window + m / 2] / 1e3, lat[info.window + (m * 99) / 100] / 1e3);
    }
    free(lat);
    free(frame);
    free(out);
    ikid_stream_free(stream);
    ikid_model_free(model);
    return status;
}
