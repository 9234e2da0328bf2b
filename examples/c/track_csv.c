/* A host program embedding libikid's tracker: stream a CSV trial of marker frames (one frame
 * per line, the 18 marker coordinates in metres, NaN for a missing marker) through
 * ikid_tracker_push and print each estimated frame's wrist angles q (rad) and torques tau
 * (N·m), then the per-frame latency.
 *
 *   track_csv TRIAL.csv --rate HZ [--refiner MODEL.safetensors] [--length-scale X]
 *             [--mass-scale X] [--up X,Y,Z] [--every N]
 *
 * --rate is the frames' rate (required: the tracker has none of its own); --up the lab's up
 * direction (default 0,1,0; 0,0,1 for a Z-up lab), which the torques depend on.
 *
 * Values are printed with %.17g, so they read back as exactly the doubles computed.
 * Build: cc -O2 track_csv.c $(pkg-config --cflags --libs ikid) -o track_csv
 * (or `make c` in the repository). */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#include "ikid.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

enum { FRAME = 18, VALUES = 12 };

/* The tracker's coordinates, in output order (as the header documents them). */
static const char *const COORDINATES[3] = {"ra_wr_s_p", "ra_wr_e_f", "ra_wr_ad_ab"};

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
    if (argc < 2 || argc % 2 != 0) {
        fprintf(stderr, "usage: %s TRIAL.csv --rate HZ [--refiner MODEL.safetensors] [--length-scale X] [--mass-scale X] [--up X,Y,Z] [--every N]\n", argv[0]);
        return 2;
    }
    ikid_tracker_settings settings = ikid_tracker_settings_default();
    const char *refiner_path = NULL;
    long every = 1;
    for (int a = 2; a + 1 < argc; a += 2) {
        const char *opt = argv[a], *value = argv[a + 1];
        if (strcmp(opt, "--refiner") == 0) refiner_path = value;
        else if (strcmp(opt, "--length-scale") == 0) settings.length_scale = strtod(value, NULL);
        else if (strcmp(opt, "--mass-scale") == 0) settings.mass_scale = strtod(value, NULL);
        else if (strcmp(opt, "--rate") == 0) settings.rate_hz = strtod(value, NULL);
        else if (strcmp(opt, "--up") == 0) {
            if (sscanf(value, "%lf,%lf,%lf", &settings.up[0], &settings.up[1], &settings.up[2]) != 3) {
                fprintf(stderr, "--up %s: expected three numbers X,Y,Z\n", value);
                return 2;
            }
        } else if (strcmp(opt, "--every") == 0) every = strtol(value, NULL, 10);
        else {
            fprintf(stderr, "unknown option %s\n", opt);
            return 2;
        }
    }
    if (every < 1) every = 1;

    ikid_model *refiner = NULL;
    if (refiner_path && ikid_model_load(refiner_path, &refiner) != IKID_STATUS_OK) {
        fprintf(stderr, "cannot load refiner: %s\n", ikid_last_error());
        return 1;
    }
    ikid_tracker *tracker = NULL;
    ikid_status created = ikid_tracker_new(&settings, refiner, &tracker);
    ikid_model_free(refiner); /* the tracker holds its own reference */
    if (created != IKID_STATUS_OK) {
        fprintf(stderr, "cannot create the tracker: %s\n", ikid_last_error());
        return 1;
    }

    FILE *csv = fopen(argv[1], "r");
    if (!csv) {
        perror(argv[1]);
        ikid_tracker_free(tracker);
        return 1;
    }
    double frame[FRAME], out[VALUES];
    size_t cap = 1 << 16, n = 0, timed = 0;
    double *lat = malloc(cap * sizeof *lat);
    char line[8192];
    int status = 0;

    printf("frame");
    for (int k = 0; k < 3; k++) printf(",q.%s", COORDINATES[k]);
    for (int k = 0; k < 3; k++) printf(",tau.%s", COORDINATES[k]);
    printf(",missing,refined\n");
    while (fgets(line, sizeof line, csv)) {
        char *p = line, *end;
        size_t k = 0;
        for (; k < FRAME; k++) {
            frame[k] = strtod(p, &end); /* reads "nan" too */
            if (end == p) break;
            p = end + (*end == ',');
        }
        if (k == 0) continue; /* header or blank line */
        ikid_tracker_flags flags;
        double t0 = now_ns();
        ikid_status s = ikid_tracker_push(tracker, frame, k, out, VALUES, &flags);
        double dt = now_ns() - t0;
        if (s != IKID_STATUS_OK) {
            fprintf(stderr, "frame %zu: %s\n", n, ikid_last_error());
            status = 1;
            break;
        }
        if (flags.ready) {
            if (timed == cap) lat = realloc(lat, (cap *= 2) * sizeof *lat);
            lat[timed++] = dt;
            if (n % (size_t)every == 0) {
                printf("%zu", n);
                for (int j = 0; j < 3; j++) printf(",%.17g", out[j]);     /* q */
                for (int j = 9; j < 12; j++) printf(",%.17g", out[j]);    /* tau */
                printf(",%u,%d\n", (unsigned)flags.missing, flags.refined ? 1 : 0);
            }
        }
        n++;
    }
    fclose(csv);
    if (timed > 0) {
        qsort(lat, timed, sizeof *lat, by_value);
        fprintf(stderr, "%zu frames, %zu estimated; ikid_tracker_push latency p50 %.2f us, p99 %.2f us\n", n, timed,
                lat[timed / 2] / 1e3, lat[(timed * 99) / 100] / 1e3);
    }
    free(lat);
    ikid_tracker_free(tracker);
    return status;
}
