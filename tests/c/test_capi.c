/* Tests of libikid's C ABI: results equal the Python API's, every error path returns its
 * status and a readable message, a model is shared by threads. Run under valgrind by
 * tests/test_capi.py, which writes the fixtures:
 *   test_capi MODEL FRAMES.csv EXPECTED.csv CORRUPT_MODEL
 * FRAMES.csv: one frame per line (frame_len floats); EXPECTED.csv: predictions of frames
 * window-1.. (n_outputs floats per line), from ikid.Model.predict. Prints "N passed, N failed". */
#include "ikid.h"

#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"

static float *read_csv(const char *path, size_t cols, size_t *rows) {
    FILE *f = fopen(path, "r");
    if (!f) { perror(path); exit(2); }
    size_t cap = 1024, n = 0;
    float *v = malloc(cap * sizeof *v);
    double x;
    while (fscanf(f, "%lf%*[, \n]", &x) == 1) {
        if (n == cap) { cap *= 2; v = realloc(v, cap * sizeof *v); }
        v[n++] = (float)x;
    }
    fclose(f);
    *rows = n / cols;
    return v;
}

static unsigned char *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) { perror(path); exit(2); }
    fseek(f, 0, SEEK_END);
    *len = (size_t)ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *buf = malloc(*len);
    if (fread(buf, 1, *len, f) != *len) { perror(path); exit(2); }
    fclose(f);
    return buf;
}

static int contains(const char *haystack, const char *needle) { return strstr(haystack, needle) != NULL; }

struct shared {
    const ikid_model *model;
    const float *frames, *expected;
    size_t n_frames, frame_len, n_out, window;
    int mismatches;
};

static void *stream_all(void *arg) {
    struct shared *s = arg;
    ikid_stream *stream = NULL;
    if (ikid_stream_new(s->model, &stream) != IKID_STATUS_OK) { s->mismatches = -1; return NULL; }
    float out[16];
    for (size_t i = 0; i < s->n_frames; i++) {
        bool ready = false;
        if (ikid_stream_push(stream, s->frames + i * s->frame_len, s->frame_len, out, 16, &ready) != IKID_STATUS_OK) s->mismatches++;
        if (ready && memcmp(out, s->expected + (i - s->window + 1) * s->n_out, s->n_out * sizeof(float)) != 0) s->mismatches++;
    }
    ikid_stream_free(stream);
    return NULL;
}

int main(int argc, char **argv) {
    if (argc != 6) { fprintf(stderr, "usage: %s MODEL FRAMES.csv EXPECTED.csv CORRUPT_MODEL EXPECTED_CALIBRATED.csv\n", argv[0]); return 2; }
    const char *model_path = argv[1], *corrupt_path = argv[4], *expected_cal_path = argv[5];

    CHECK(strcmp(ikid_version(), "") != 0 && strchr(ikid_version(), '.'), "version %s", ikid_version());
    CHECK(contains(ikid_status_message(IKID_STATUS_INPUT), "frame"), "status message");
    CHECK(strcmp(ikid_status_message(99), "unknown status") == 0, "unknown status message");

    /* Loading: every failure has its status and a message naming the problem. */
    ikid_model *model = NULL;
    CHECK(ikid_model_load(NULL, &model) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "path is NULL"), "NULL path");
    CHECK(ikid_model_load(model_path, NULL) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "out is NULL"), "NULL out");
    CHECK(ikid_model_load("/nonexistent/m.safetensors", &model) == IKID_STATUS_IO && contains(ikid_last_error(), "/nonexistent/m.safetensors") && model == NULL, "missing file");
    CHECK(ikid_model_load(corrupt_path, &model) == IKID_STATUS_MODEL_FILE && contains(ikid_last_error(), "safetensors") && model == NULL, "corrupt file");
    size_t len = 0;
    unsigned char *bytes = read_file(model_path, &len);
    CHECK(ikid_model_load_bytes(bytes, len / 2, &model) == IKID_STATUS_MODEL_FILE && model == NULL, "truncated bytes");
    CHECK(ikid_model_load_bytes(bytes, len, &model) == IKID_STATUS_OK && model != NULL, "load from bytes");
    ikid_model_free(model);
    free(bytes);
    model = NULL;
    CHECK(ikid_model_load(model_path, &model) == IKID_STATUS_OK && model != NULL, "load");

    ikid_model_info info = {0};
    CHECK(ikid_model_get_info(NULL, &info) == IKID_STATUS_NULL_PARAMETER, "info NULL model");
    CHECK(ikid_model_get_info(model, &info) == IKID_STATUS_OK && info.frame_len == 18 && info.window == 5 && info.n_outputs == 3 && info.frame_rate_hz == 1000.0,
          "info %zu %zu %zu %g", info.frame_len, info.window, info.n_outputs, info.frame_rate_hz);
    CHECK(strcmp(ikid_model_output_name(model, 0), "ra_wr_s_p") == 0 && ikid_model_output_name(model, 3) == NULL, "output names");
    CHECK(strcmp(ikid_model_frame_name(model, 10), "MC2.y") == 0 && ikid_model_frame_name(model, 18) == NULL, "frame names");
    CHECK(strcmp(ikid_model_task(model), "ik") == 0 && strcmp(ikid_model_feature_set(model), "markers") == 0 && ikid_model_name(model) != NULL, "named getters");
    CHECK(ikid_model_name(NULL) == NULL && ikid_model_task(NULL) == NULL && ikid_model_feature_set(NULL) == NULL, "NULL-safe named getters");
    CHECK(ikid_model_output_name(NULL, 0) == NULL && ikid_model_predict_rows(NULL, 10) == 0 && ikid_model_predict_rows(model, 10) == 6 && ikid_model_predict_rows(model, 3) == 0, "NULL-safe getters");
    /* The old names stay for one release, deprecated, and give the same answers. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
    CHECK(ikid_model_describe(model, 1) == ikid_model_task(model) && ikid_model_describe(model, 2) == ikid_model_feature_set(model) && ikid_model_describe(model, 0) == ikid_model_name(model) && ikid_model_describe(model, 7) == NULL, "describe (deprecated)");
    CHECK(ikid_predict_rows(model, 10) == 6, "ikid_predict_rows (deprecated)");
#pragma GCC diagnostic pop

    size_t n_frames = 0, n_expected = 0;
    float *frames = read_csv(argv[2], info.frame_len, &n_frames);
    float *expected = read_csv(argv[3], info.n_outputs, &n_expected);
    CHECK(n_expected == n_frames - info.window + 1, "fixture sizes %zu %zu", n_frames, n_expected);

    /* Streaming equals the Python API's predictions, bit for bit. */
    ikid_stream *stream = NULL;
    CHECK(ikid_stream_new(NULL, &stream) == IKID_STATUS_NULL_PARAMETER, "stream NULL model");
    CHECK(ikid_stream_new(model, &stream) == IKID_STATUS_OK, "stream new");
    float out[3] = {0};
    bool ready = true;
    int mismatches = 0, early = 0;
    for (size_t i = 0; i < n_frames; i++) {
        if (ikid_stream_push(stream, frames + i * 18, 18, out, 3, &ready) != IKID_STATUS_OK) mismatches++;
        if (i + 1 < info.window) early += ready;
        else if (!ready || memcmp(out, expected + (i - info.window + 1) * 3, sizeof out) != 0) mismatches++;
    }
    CHECK(mismatches == 0 && early == 0, "stream vs Python: %d mismatches, %d early outputs", mismatches, early);

    /* Bad pushes: status, message, and nothing written. */
    float sentinel[3] = {7, 7, 7};
    ready = true;
    CHECK(ikid_stream_push(stream, frames, 17, sentinel, 3, &ready) == IKID_STATUS_INPUT && contains(ikid_last_error(), "17 values") && ready && sentinel[0] == 7, "short frame");
    float bad[18];
    memcpy(bad, frames, sizeof bad);
    bad[13] = NAN;
    CHECK(ikid_stream_push(stream, bad, 18, sentinel, 3, &ready) == IKID_STATUS_INPUT && contains(ikid_last_error(), "MC5.y") && sentinel[0] == 7, "NaN marker: %s", ikid_last_error());
    CHECK(ikid_stream_push(stream, frames, 18, sentinel, 2, &ready) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "room for 2"), "small out");
    CHECK(ikid_stream_push(NULL, frames, 18, out, 3, &ready) == IKID_STATUS_NULL_PARAMETER, "NULL stream");
    CHECK(ikid_stream_push(stream, NULL, 18, out, 3, &ready) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "frame is NULL"), "NULL frame");
    CHECK(ikid_stream_push(stream, frames, 18, out, 3, NULL) == IKID_STATUS_NULL_PARAMETER, "NULL ready");
    CHECK(ikid_stream_push(stream, (const float *)((const char *)frames + 1), 17, out, 3, &ready) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "aligned"), "misaligned frame");

    /* Reset empties the window. */
    CHECK(ikid_stream_reset(stream) == IKID_STATUS_OK && ikid_stream_reset(NULL) == IKID_STATUS_NULL_PARAMETER, "reset");
    CHECK(ikid_stream_push(stream, frames, 18, out, 3, &ready) == IKID_STATUS_OK && !ready, "after reset");
    double sd3[3];
    CHECK(ikid_stream_output_sd(stream, sd3, 3) == IKID_STATUS_OK && isnan(sd3[0]) && isnan(sd3[2]), "no sd without an output");
    CHECK(ikid_stream_output_sd(NULL, sd3, 3) == IKID_STATUS_NULL_PARAMETER && contains(ikid_last_error(), "stream is NULL"), "sd of NULL stream");
    CHECK(ikid_stream_output_sd(stream, NULL, 3) == IKID_STATUS_NULL_PARAMETER, "NULL sd buffer");

    /* push_many in packets of 7 equals the expected rows. */
    ikid_stream_reset(stream);
    float *rows_out = malloc(n_expected * 3 * sizeof(float));
    size_t got = 0;
    for (size_t i = 0; i < n_frames; i += 7) {
        size_t k = n_frames - i < 7 ? n_frames - i : 7, rows = 0;
        if (ikid_stream_push_many(stream, frames + i * 18, k, 18, rows_out + got * 3, 7 * 3, &rows) != IKID_STATUS_OK) break;
        got += rows;
    }
    CHECK(got == n_expected && memcmp(rows_out, expected, n_expected * 3 * sizeof(float)) == 0, "push_many: %zu rows", got);

    /* Whole-recording prediction. */
    size_t rows = 0;
    memset(rows_out, 0, n_expected * 3 * sizeof(float));
    CHECK(ikid_model_predict(model, frames, n_frames, 18, rows_out, n_expected * 3, &rows) == IKID_STATUS_OK && rows == n_expected
          && memcmp(rows_out, expected, n_expected * 3 * sizeof(float)) == 0, "predict");
    CHECK(ikid_model_predict(model, frames, n_frames, 18, rows_out, 5, &rows) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "room for 5"), "predict small out");
    CHECK(ikid_model_predict(model, frames, n_frames, 9, rows_out, n_expected * 3, &rows) == IKID_STATUS_INPUT && contains(ikid_last_error(), "frame_len is 9"), "predict frame_len");
    CHECK(ikid_model_predict(model, frames, n_frames, 18, rows_out, n_expected * 3, NULL) == IKID_STATUS_NULL_PARAMETER, "predict NULL rows");
    CHECK(ikid_model_predict(model, NULL, 0, 18, NULL, 0, &rows) == IKID_STATUS_OK && rows == 0, "predict nothing into nothing");
    CHECK(ikid_model_predict(model, frames, 3, 18, NULL, 0, &rows) == IKID_STATUS_OK && rows == 0, "short recording needs no out");
    free(rows_out);

    /* Threads share one model, each with its own stream. */
    enum { THREADS = 4 };
    pthread_t tid[THREADS];
    struct shared sh[THREADS];
    for (int t = 0; t < THREADS; t++) {
        sh[t] = (struct shared){model, frames, expected, n_frames, 18, 3, info.window, 0};
        pthread_create(&tid[t], NULL, stream_all, &sh[t]);
    }
    int thread_mismatches = 0;
    for (int t = 0; t < THREADS; t++) {
        pthread_join(tid[t], NULL);
        thread_mismatches += sh[t].mismatches;
    }
    CHECK(thread_mismatches == 0, "%d threads: %d mismatches", THREADS, thread_mismatches);

    /* Missing-marker policy, flags and timed pushes. */
    ikid_stream *timed = NULL;
    CHECK(ikid_stream_new(model, &timed) == IKID_STATUS_OK, "timed stream");
    CHECK(ikid_stream_set_missing_markers(timed, 7) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "policy is 7"), "bad policy: %s", ikid_last_error());
    CHECK(ikid_stream_set_missing_markers(NULL, IKID_MISSING_MARKERS_FILL) == IKID_STATUS_NULL_PARAMETER, "NULL stream");
    CHECK(ikid_stream_set_missing_markers(timed, IKID_MISSING_MARKERS_FILL) == IKID_STATUS_OK, "fill policy");
    uint32_t mask = 99;
    int timed_bad = 0;
    for (size_t i = 0; i < n_frames; i++) {
        /* 3 frames dropped after frame 9: the window restarts, outputs resume 5 frames later. */
        double t = (double)(i < 10 ? i : i + 3) * 1e-3;
        if (ikid_stream_push_at(timed, t, frames + i * 18, 18, out, 3, &ready) != IKID_STATUS_OK) timed_bad++;
        if ((i >= 4 && i < 10) || i >= 14 ? !ready : ready) timed_bad++;
    }
    CHECK(timed_bad == 0 && ikid_stream_filled_markers(timed, &mask) == IKID_STATUS_OK && mask == 0, "timed pushes: %d bad", timed_bad);
    CHECK(ikid_stream_push_at(timed, 0.0, frames, 18, out, 3, &ready) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "does not follow"), "time backwards");
    ikid_stream_free(timed);

    /* push_many refusing frame 20 part-way (RSP and USP lost: only one marker is filled): the
       16 rows of frames 4-19 stay in out, *rows says so, and they are the expected ones. */
    ikid_stream *part = NULL;
    float *holed = malloc(21 * 18 * sizeof(float));
    memcpy(holed, frames, 21 * 18 * sizeof(float));
    for (int k = 0; k < 6; k++) holed[20 * 18 + k] = NAN;
    size_t part_rows = 99;
    float part_out[21 * 3];
    CHECK(ikid_stream_new(model, &part) == IKID_STATUS_OK && ikid_stream_set_missing_markers(part, IKID_MISSING_MARKERS_FILL) == IKID_STATUS_OK, "part-way stream");
    CHECK(ikid_stream_push_many(part, holed, 21, 18, part_out, 21 * 3, &part_rows) == IKID_STATUS_INPUT && contains(ikid_last_error(), "frame 20") && part_rows == 99, "part-way refusal: %s", ikid_last_error());
    CHECK(ikid_stream_rows_before_refusal(part, &part_rows) == IKID_STATUS_OK && part_rows == 16 && memcmp(part_out, expected, 16 * 3 * sizeof(float)) == 0, "rows before the refusal: %zu", part_rows);
    CHECK(ikid_stream_push_many(part, holed, 21, 18, part_out, 2, &part_rows) == IKID_STATUS_INVALID_ARGUMENT, "out too short");
    CHECK(ikid_stream_rows_before_refusal(part, &part_rows) == IKID_STATUS_OK && part_rows == 0, "a block refused whole pushed no row");
    CHECK(ikid_stream_rows_before_refusal(NULL, &part_rows) == IKID_STATUS_NULL_PARAMETER && ikid_stream_rows_before_refusal(part, NULL) == IKID_STATUS_NULL_PARAMETER, "NULL arguments");
    ikid_stream_free(part);
    free(holed);

    /* Calibration: both matrices (row-major, as a calibration file holds them) -> the outputs
       Python computes with the same calibration; both NULL removes it. */
    ikid_stream *cal = NULL;
    size_t n_cal = 0;
    float *expected_cal = read_csv(expected_cal_path, 3, &n_cal);
    const double c = 0.984807753012208, s = 0.17364817766693033; /* 10 degrees about z */
    const double rz[9] = {c, -s, 0, s, c, 0, 0, 0, 1};
    const double not_rotation[9] = {1, 0, 0, 0, 2, 0, 0, 0, 1};
    CHECK(ikid_stream_new(model, &cal) == IKID_STATUS_OK && expected_cal && n_cal == n_expected, "calibrated stream fixture");
    CHECK(ikid_stream_set_calibration(cal, not_rotation, rz) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "forearm matrix is not a rotation"), "not a rotation: %s", ikid_last_error());
    CHECK(ikid_stream_set_calibration(cal, rz, NULL) == IKID_STATUS_INVALID_ARGUMENT && contains(ikid_last_error(), "both"), "one matrix");
    CHECK(ikid_stream_set_calibration(NULL, rz, rz) == IKID_STATUS_NULL_PARAMETER, "calibration NULL stream");
    CHECK(ikid_stream_set_calibration(cal, rz, rz) == IKID_STATUS_OK, "set calibration");
    int cal_mismatches = 0, uncal_mismatches = 0;
    for (size_t i = 0; i < n_frames; i++) {
        if (ikid_stream_push(cal, frames + i * 18, 18, out, 3, &ready) != IKID_STATUS_OK) cal_mismatches++;
        if (i + 1 >= info.window && (!ready || memcmp(out, expected_cal + (i + 1 - info.window) * 3, sizeof out) != 0)) cal_mismatches++;
    }
    CHECK(cal_mismatches == 0, "calibrated stream vs Python: %d mismatches", cal_mismatches);
    CHECK(ikid_stream_set_calibration(cal, NULL, NULL) == IKID_STATUS_OK && ikid_stream_reset(cal) == IKID_STATUS_OK, "remove calibration");
    for (size_t i = 0; i < n_frames; i++) {
        if (ikid_stream_push(cal, frames + i * 18, 18, out, 3, &ready) != IKID_STATUS_OK) uncal_mismatches++;
        if (i + 1 >= info.window && (!ready || memcmp(out, expected + (i + 1 - info.window) * 3, sizeof out) != 0)) uncal_mismatches++;
    }
    CHECK(uncal_mismatches == 0, "uncalibrated again: %d mismatches", uncal_mismatches);
    ikid_stream_free(cal);
    free(expected_cal);

    /* The stream outlives its model handle; freeing NULL is a no-op. */
    ikid_model_free(model);
    /* (the last frame again: the stream refuses markers that jump, e.g. back to frame 0) */
    CHECK(ikid_stream_push(stream, frames + (n_frames - 1) * 18, 18, out, 3, &ready) == IKID_STATUS_OK, "stream after model free");
    ikid_stream_free(stream);
    ikid_stream_free(NULL);
    ikid_model_free(NULL);
    free(frames);
    free(expected);

    printf("%d passed, %d failed\n", passed, failed);
    return failed != 0;
}
