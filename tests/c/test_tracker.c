/* Tests of libikid's tracker ABI (ikid_tracker_*): results equal the Python API's bit for bit
 * (push one frame at a time, run over the whole trial and over blocks, with and without the
 * refiner), every error path returns its status and a readable message and writes nothing.
 * Run natively and under valgrind by tests/test_capi_tracker.py, which writes the fixtures:
 *   test_tracker FRAMES.csv EXPECTED.csv NOISE.csv REFINER EXPECTED_REFINED.csv NOT_A_REFINER
 * FRAMES.csv: 18 marker values per line (m, NaN = missing); EXPECTED*.csv: per frame q, qd, qdd,
 * tau (12), missing, refined, noise, from ikid.Tracker(length_scale=1.1, mass_scale=1.2).run
 * (NaN rows before the start); NOISE.csv: the unrefined tracker's marker_noise after the trial,
 * then its output_sd (q then tau).
 * All written with %.17g, so each double reads back exactly. Prints "N passed, N failed". */
#include "ikid.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"

enum { FRAME = 18, VALUES = 12, EXPECTED_COLS = 16 };

/* Every value of a CSV file (commas, spaces, newlines between them; "nan" allowed). */
static double *read_csv(const char *path, size_t cols, size_t *rows) {
    FILE *f = fopen(path, "r");
    if (!f) { perror(path); exit(2); }
    size_t cap = 4096, n = 0;
    double *v = malloc(cap * sizeof *v);
    char token[64];
    while (fscanf(f, " %63[^,\n]%*[, \n]", token) == 1) {
        if (n == cap) { cap *= 2; v = realloc(v, cap * sizeof *v); }
        v[n++] = strtod(token, NULL);
    }
    fclose(f);
    *rows = n / cols;
    return v;
}

static int contains(const char *haystack, const char *needle) { return strstr(haystack, needle) != NULL; }

/* Bit-identical, with any NaN equal to any NaN (the CSV's "nan" and Rust's NaN). */
static int same(double a, double b) { return (isnan(a) && isnan(b)) || memcmp(&a, &b, sizeof a) == 0; }

/* Frame i's 12 values and flags against row i of EXPECTED (12 values, missing, refined, noise). */
static int matches(const double *values, const ikid_tracker_flags *flags, const double *row) {
    for (int k = 0; k < VALUES; k++)
        if (!same(values[k], row[k])) return 0;
    return flags->missing == (uint32_t)row[12] && flags->refined == (row[13] != 0) && same(flags->noise, row[14])
           && flags->status == (uint32_t)row[15] && flags->ready == !isnan(row[0]);
}

/* First frame of EXPECTED with an estimate. */
static size_t first_ready(const double *expected, size_t n) {
    size_t i = 0;
    while (i < n && isnan(expected[i * EXPECTED_COLS])) i++;
    return i;
}

/* Runs `frames` through `tracker` in blocks of `block` frames and counts the frames whose
 * results differ from EXPECTED (and a wrong start). */
static int run_in_blocks(ikid_tracker *tracker, const double *frames, const double *expected, size_t n, size_t block) {
    double *out = malloc(block * VALUES * sizeof *out);
    ikid_tracker_flags *flags = malloc(block * sizeof *flags);
    size_t start_expected = first_ready(expected, n);
    int bad = 0;
    for (size_t b = 0; b < n; b += block) {
        size_t k = n - b < block ? n - b : block, start = 999999;
        if (ikid_tracker_run(tracker, frames + b * FRAME, k * FRAME, out, k * VALUES, flags, k, &start) != IKID_STATUS_OK) {
            bad++;
            break;
        }
        size_t want = start_expected <= b ? 0 : start_expected < b + k ? start_expected - b : k;
        if (start != want) bad++;
        for (size_t i = 0; i < k; i++) bad += !matches(out + i * VALUES, &flags[i], expected + (b + i) * EXPECTED_COLS);
    }
    free(out);
    free(flags);
    return bad;
}

static ikid_tracker_settings subject(void) {
    ikid_tracker_settings s = ikid_tracker_settings_default();
    s.rate_hz = 1000.0;
    s.length_scale = 1.1;
    s.mass_scale = 1.2;
    return s;
}

int main(int argc, char **argv) {
    if (argc != 7) {
        fprintf(stderr, "usage: %s FRAMES.csv EXPECTED.csv NOISE.csv REFINER EXPECTED_REFINED.csv NOT_A_REFINER\n", argv[0]);
        return 2;
    }
    size_t n = 0, n_expected = 0, n_refined = 0, n_noise = 0;
    double *frames = read_csv(argv[1], FRAME, &n);
    double *expected = read_csv(argv[2], EXPECTED_COLS, &n_expected);
    double *noise_expected = read_csv(argv[3], 15, &n_noise);
    double *expected_refined = read_csv(argv[5], EXPECTED_COLS, &n_refined);
    CHECK(n > 100 && n_expected == n && n_refined == n && n_noise == 1, "fixture sizes %zu %zu %zu %zu", n, n_expected, n_refined, n_noise);

    /* Settings: the core's defaults; no rate (it has to be given) and +Y up. */
    ikid_tracker_settings d = ikid_tracker_settings_default();
    CHECK(d.length_scale == 1.0 && d.mass_scale == 1.0 && isnan(d.rate_hz) && d.jerk_noise == 3e3 && d.noise_memory_s == 10.0
          && d.initial_marker_noise == 1e-3 && d.up[0] == 0.0 && d.up[1] == 1.0 && d.up[2] == 0.0, "default settings");

    /* Creation: every failure has its status and a message naming the problem, and no handle. */
    ikid_model *refiner = NULL, *not_refiner = NULL;
    CHECK(ikid_model_load(argv[4], &refiner) == IKID_STATUS_OK && ikid_model_load(argv[6], &not_refiner) == IKID_STATUS_OK, "models");
    ikid_tracker_settings s = subject();
    ikid_tracker *tracker = NULL;
    CHECK(ikid_tracker_new(NULL, NULL, &tracker) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "settings is NULL") && !tracker, "NULL settings");
    CHECK(ikid_tracker_new(&s, NULL, NULL) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "out is NULL"), "NULL out");
    ikid_tracker_settings bad = s;
    bad.jerk_noise = 0.0;
    CHECK(ikid_tracker_new(&bad, NULL, &tracker) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "jerk_noise") && !tracker, "zero jerk noise");
    bad = s;
    bad.length_scale = NAN;
    CHECK(ikid_tracker_new(&bad, NULL, &tracker) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "length_scale") && !tracker, "NaN length scale");
    ikid_tracker *unrated = NULL;
    CHECK(ikid_tracker_new(&d, NULL, &unrated) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "rate_hz: is not set") && !unrated,
          "no rate: %s", ikid_last_error());
    bad = s;
    bad.up[0] = 0.0; bad.up[1] = 0.0; bad.up[2] = 0.0;
    CHECK(ikid_tracker_new(&bad, NULL, &tracker) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "up") && !tracker, "zero up");
    bad = s;
    bad.rate_hz = 500.0;
    CHECK(ikid_tracker_new(&bad, refiner, &tracker) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "500 Hz") && !tracker, "refiner at another rate");
    CHECK(ikid_tracker_new(&s, not_refiner, &tracker) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "cannot refine") && !tracker, "not a refiner: %s", ikid_last_error());
    ikid_model_free(not_refiner);
    CHECK(ikid_tracker_new(&s, NULL, &tracker) == IKID_STATUS_OK && tracker, "new");

    /* Marker noise: the initial guess, then (after the trial) Python's. */
    double noise[10];
    CHECK(ikid_tracker_marker_noise(tracker, noise, 9) == IKID_STATUS_OK && noise[0] == 1e-3 && noise[8] == 1e-3, "initial noise");
    noise[0] = 7;
    CHECK(ikid_tracker_marker_noise(tracker, noise, 8) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "room for 8") && noise[0] == 7, "short noise buffer");
    CHECK(ikid_tracker_marker_noise(tracker, NULL, 9) == IKID_STATUS_NULL_PARAMETER, "NULL noise buffer");
    CHECK(ikid_tracker_marker_noise(NULL, noise, 9) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "tracker is NULL"), "noise of NULL tracker");

    /* Push one frame at a time equals Python's run, bit for bit; halfway, every bad push is
       refused, writes nothing and leaves the tracker as it was (the rest still matches). */
    double out[VALUES + 1];
    ikid_tracker_flags flags;
    int mismatches = 0;
    size_t half = n / 2;
    for (size_t i = 0; i < n; i++) {
        if (i == half) {
            const double *f = frames + i * FRAME;
            double sentinel[VALUES];
            for (int k = 0; k < VALUES; k++) sentinel[k] = 7.0;
            ikid_tracker_flags flags_sentinel = {77, true, true, 7.0, 77};
            double inf_frame[FRAME];
            memcpy(inf_frame, f, sizeof inf_frame);
            inf_frame[13] = INFINITY;
            CHECK(ikid_tracker_push(tracker, inf_frame, FRAME, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_INPUT
                  && contains(ikid_last_error(), "MC5.y") && sentinel[0] == 7.0 && flags_sentinel.missing == 77, "infinite value: %s", ikid_last_error());
            inf_frame[13] = -INFINITY;
            CHECK(ikid_tracker_push(tracker, inf_frame, FRAME, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_INPUT, "minus infinity");
            CHECK(ikid_tracker_push(tracker, f, 17, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_INPUT
                  && contains(ikid_last_error(), "17 values") && sentinel[0] == 7.0, "short frame: %s", ikid_last_error());
            CHECK(ikid_tracker_push(tracker, f, 19, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_INPUT && contains(ikid_last_error(), "19"), "long frame");
            CHECK(ikid_tracker_push(tracker, f, FRAME, sentinel, VALUES - 1, &flags_sentinel) == IKID_STATUS_INVALID_ARGUMENT
                  && contains(ikid_last_error(), "room for 11") && sentinel[0] == 7.0 && flags_sentinel.noise == 7.0, "short out");
            CHECK(ikid_tracker_push(NULL, f, FRAME, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "tracker is NULL"), "NULL tracker");
            CHECK(ikid_tracker_push(tracker, NULL, FRAME, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "frame is NULL"), "NULL frame");
            CHECK(ikid_tracker_push(tracker, f, FRAME, NULL, VALUES, &flags_sentinel) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "out is NULL"), "NULL out");
            CHECK(ikid_tracker_push(tracker, f, FRAME, sentinel, VALUES, NULL) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "flags is NULL"), "NULL flags");
            CHECK(ikid_tracker_push(tracker, (const double *)((const char *)f + 1), FRAME, sentinel, VALUES, &flags_sentinel) == IKID_STATUS_INVALID_ARGUMENT
                  && contains(ikid_last_error(), "aligned"), "misaligned frame");
            CHECK(sentinel[0] == 7.0 && sentinel[VALUES - 1] == 7.0 && flags_sentinel.missing == 77 && flags_sentinel.ready, "nothing written by refused pushes");
        }
        out[VALUES] = 42.0; /* room beyond the 12 values is left alone */
        if (ikid_tracker_push(tracker, frames + i * FRAME, FRAME, out, VALUES + 1, &flags) != IKID_STATUS_OK) mismatches++;
        else if (!matches(out, &flags, expected + i * EXPECTED_COLS) || out[VALUES] != 42.0) mismatches++;
    }
    CHECK(mismatches == 0, "push vs Python: %d mismatches", mismatches);
    CHECK(ikid_tracker_marker_noise(tracker, noise, 10) == IKID_STATUS_OK && memcmp(noise, noise_expected, 9 * sizeof(double)) == 0, "marker noise vs Python");
    double sd[7] = {7, 7, 7, 7, 7, 7, 42.0};
    CHECK(ikid_tracker_output_sd(tracker, sd, 7) == IKID_STATUS_OK && memcmp(sd, noise_expected + 9, 6 * sizeof(double)) == 0 && sd[6] == 42.0, "output sd vs Python");
    CHECK(ikid_tracker_output_sd(tracker, sd, 5) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "room for 5"), "short sd buffer");
    CHECK(ikid_tracker_output_sd(tracker, NULL, 6) == IKID_STATUS_NULL_PARAMETER, "NULL sd buffer");
    CHECK(ikid_tracker_output_sd(NULL, sd, 6) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "tracker is NULL"), "sd of NULL tracker");

    /* The fixture's own missing markers (NaN) were reported, not refused; and a NaN marker
       pushed now is missing, not an error. */
    int missing_frames = 0;
    for (size_t i = 0; i < n; i++) missing_frames += expected[i * EXPECTED_COLS + 12] != 0;
    CHECK(missing_frames > 0 && first_ready(expected, n) > 0, "the fixture has missing markers (%d frames) and a late start", missing_frames);
    double holed[FRAME];
    memcpy(holed, frames + (n - 1) * FRAME, sizeof holed);
    holed[16] = NAN; /* MCB.y */
    CHECK(ikid_tracker_push(tracker, holed, FRAME, out, VALUES, &flags) == IKID_STATUS_OK && flags.ready && flags.missing == 1u << 5 && !isnan(out[0]), "NaN marker is missing");

    /* Reset: the same trial again gives the same results (a whole-trial run this time). */
    CHECK(ikid_tracker_reset(NULL) == IKID_STATUS_NULL_PARAMETER, "reset NULL");
    CHECK(ikid_tracker_reset(tracker) == IKID_STATUS_OK && ikid_tracker_marker_noise(tracker, noise, 9) == IKID_STATUS_OK && noise[4] == 1e-3, "reset");
    CHECK(ikid_tracker_output_sd(tracker, sd, 6) == IKID_STATUS_OK && isnan(sd[0]) && isnan(sd[5]), "no sd before the start");
    CHECK(run_in_blocks(tracker, frames, expected, n, n) == 0, "run over the whole trial vs Python");

    /* Run in blocks of 37 (a fresh tracker) equals Python too; start counts within a block. */
    ikid_tracker *blocks = NULL;
    CHECK(ikid_tracker_new(&s, NULL, &blocks) == IKID_STATUS_OK && run_in_blocks(blocks, frames, expected, n, 37) == 0, "run in blocks of 37 vs Python");

    /* Bad runs: status, message, start not written. */
    double *rows = malloc(n * VALUES * sizeof *rows);
    ikid_tracker_flags *fl = malloc(n * sizeof *fl);
    size_t start = 12345;
    CHECK(ikid_tracker_run(blocks, frames, 19, rows, n * VALUES, fl, n, &start) == IKID_STATUS_INVALID_ARGUMENT
          && contains(ikid_last_error(), "whole number") && start == 12345, "partial frame: %s", ikid_last_error());
    CHECK(ikid_tracker_run(blocks, frames, 10 * FRAME, rows, 10 * VALUES - 1, fl, 10, &start) == IKID_STATUS_INVALID_ARGUMENT
          && contains(ikid_last_error(), "room for 119") && start == 12345, "short out");
    CHECK(ikid_tracker_run(blocks, frames, 10 * FRAME, rows, 10 * VALUES, fl, 9, &start) == IKID_STATUS_INVALID_ARGUMENT
          && contains(ikid_last_error(), "flags has room for 9") && start == 12345, "short flags");
    CHECK(ikid_tracker_run(blocks, frames, 10 * FRAME, rows, 10 * VALUES, fl, 10, NULL) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "start is NULL"), "NULL start");
    CHECK(ikid_tracker_run(blocks, NULL, 10 * FRAME, rows, 10 * VALUES, fl, 10, &start) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "frames is NULL"), "NULL frames");
    CHECK(ikid_tracker_run(blocks, frames, 10 * FRAME, NULL, 10 * VALUES, fl, 10, &start) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "out is NULL"), "NULL out");
    CHECK(ikid_tracker_run(blocks, frames, 10 * FRAME, rows, 10 * VALUES, NULL, 10, &start) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "flags is NULL"), "NULL flags");
    CHECK(ikid_tracker_run(NULL, frames, 10 * FRAME, rows, 10 * VALUES, fl, 10, &start) == IKID_STATUS_NULL_PARAMETER, "NULL tracker");
    CHECK(ikid_tracker_run(blocks, NULL, 0, NULL, 0, NULL, 0, &start) == IKID_STATUS_OK && start == 0, "an empty block");
    /* An infinite value in frame 4 of a block: named by its index, the frames before it pushed. */
    ikid_tracker_reset(blocks);
    double *bad_block = malloc(10 * FRAME * sizeof *bad_block);
    memcpy(bad_block, frames, 10 * FRAME * sizeof *bad_block);
    bad_block[4 * FRAME + 1] = INFINITY;
    start = 12345;
    CHECK(ikid_tracker_run(blocks, bad_block, 10 * FRAME, rows, 10 * VALUES, fl, 10, &start) == IKID_STATUS_INPUT
          && contains(ikid_last_error(), "frame 4") && contains(ikid_last_error(), "RSP.y") && start == 12345, "infinite value in a block: %s", ikid_last_error());
    int before = 0;
    for (size_t i = 0; i < 4; i++) before += !matches(rows + i * VALUES, &fl[i], expected + i * EXPECTED_COLS);
    CHECK(before == 0, "rows before the refused frame: %d mismatches", before);
    /* A block where no frame has every marker: start is the frame count, rows NaN, masks set. */
    ikid_tracker_reset(blocks);
    memcpy(bad_block, frames + 100 * FRAME, 3 * FRAME * sizeof *bad_block); /* complete frames */
    for (size_t i = 0; i < 3; i++) bad_block[i * FRAME + 3 * (2 * i) + 2] = NAN; /* markers 0, 2, 4 */
    CHECK(ikid_tracker_run(blocks, bad_block, 3 * FRAME, rows, 3 * VALUES, fl, 3, &start) == IKID_STATUS_OK && start == 3
          && !fl[2].ready && isnan(rows[0]) && isnan(rows[3 * VALUES - 1]) && isnan(fl[0].noise) && fl[0].missing == 1 && fl[1].missing == 4
          && fl[2].missing == 16, "no complete frame: start %zu", start);
    free(bad_block);
    ikid_tracker_free(blocks);

    /* With the refiner (its model handle freed first: the tracker keeps its own reference):
       push and run in blocks equal Python's, refined frames and all. */
    ikid_tracker *refined = NULL;
    CHECK(ikid_tracker_new(&s, refiner, &refined) == IKID_STATUS_OK, "new with refiner");
    ikid_model_free(refiner);
    int refined_frames = 0;
    mismatches = 0;
    for (size_t i = 0; i < n; i++) {
        if (ikid_tracker_push(refined, frames + i * FRAME, FRAME, out, VALUES, &flags) != IKID_STATUS_OK) mismatches++;
        else if (!matches(out, &flags, expected_refined + i * EXPECTED_COLS)) mismatches++;
        refined_frames += flags.refined;
    }
    CHECK(mismatches == 0 && refined_frames > 0, "refined push vs Python: %d mismatches, %d refined frames", mismatches, refined_frames);
    CHECK(ikid_tracker_reset(refined) == IKID_STATUS_OK && run_in_blocks(refined, frames, expected_refined, n, 100) == 0, "refined run in blocks after reset vs Python");
    ikid_tracker_free(refined);

    free(rows);
    free(fl);
    ikid_tracker_free(tracker);
    ikid_tracker_free(NULL);
    free(frames);
    free(expected);
    free(expected_refined);
    free(noise_expected);

    printf("%d passed, %d failed\n", passed, failed);
    return failed != 0;
}
