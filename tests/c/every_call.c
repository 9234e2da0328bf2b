/* Calls every ikid_* function of include/ikid.h once (tests/test_capi.py checks that the list
 * here is the header's), so that valgrind run with its default leak flags
 * (`valgrind --error-exitcode=1 --leak-check=full`) sees every path a host takes, the
 * thread-pooled ikid_model_predict included, and must exit 0.
 *   every_call IK_MODEL REFINER FRAMES.csv
 * IK_MODEL: a marker model (e.g. the shipped wrist-ik); REFINER: a refine model (wrist-track);
 * FRAMES.csv: marker frames at the model's rate, 18 values a line, at least 2000 lines (enough
 * for ikid_model_predict to use more than one thread). Prints "N passed, N failed". */
#include "ikid.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"

static double *read_csv(const char *path, size_t *n_values) {
    FILE *f = fopen(path, "r");
    if (!f) { perror(path); exit(2); }
    size_t cap = 1 << 16, n = 0;
    double *v = malloc(cap * sizeof *v), x;
    while (fscanf(f, "%lf%*[, \n]", &x) == 1) {
        if (n == cap) { cap *= 2; v = realloc(v, cap * sizeof *v); }
        v[n++] = x;
    }
    fclose(f);
    *n_values = n;
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

int main(int argc, char **argv) {
    if (argc != 4) { fprintf(stderr, "usage: %s IK_MODEL REFINER FRAMES.csv\n", argv[0]); return 2; }
    size_t n_values = 0;
    double *frames64 = read_csv(argv[3], &n_values);
    size_t n_frames = n_values / 18;
    if (n_frames < 2000) { fprintf(stderr, "%s: need at least 2000 frames, got %zu\n", argv[3], n_frames); return 2; }
    float *frames = malloc(n_values * sizeof *frames);
    for (size_t i = 0; i < n_values; i++) frames[i] = (float)frames64[i];

    CHECK(strchr(ikid_version(), '.') != NULL, "ikid_version");
    CHECK(strlen(ikid_status_message(IKID_STATUS_IO)) > 0, "ikid_status_message");

    /* Models: from a path and from bytes. */
    ikid_model *model = NULL, *refiner = NULL;
    CHECK(ikid_model_load(argv[1], &model) == IKID_STATUS_OK, "ikid_model_load");
    CHECK(ikid_last_error() != NULL, "ikid_last_error");
    size_t len = 0;
    unsigned char *bytes = read_file(argv[2], &len);
    CHECK(ikid_model_load_bytes(bytes, len, &refiner) == IKID_STATUS_OK, "ikid_model_load_bytes");
    free(bytes);
    if (model == NULL || refiner == NULL) return 1;

    ikid_model_info info;
    CHECK(ikid_model_get_info(model, &info) == IKID_STATUS_OK && info.frame_len == 18, "ikid_model_get_info");
    CHECK(strcmp(ikid_model_task(model), "ik") == 0, "ikid_model_task");
    CHECK(ikid_model_name(model) != NULL && ikid_model_feature_set(model) != NULL, "name, feature set");
    CHECK(ikid_model_output_name(model, 0) != NULL && ikid_model_frame_name(model, 0) != NULL, "names");
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
    CHECK(ikid_model_describe(model, 0) == ikid_model_name(model), "ikid_model_describe");
    CHECK(ikid_predict_rows(model, n_frames) == ikid_model_predict_rows(model, n_frames), "ikid_predict_rows");
#pragma GCC diagnostic pop

    /* A whole recording: long enough for several threads. */
    size_t rows = ikid_model_predict_rows(model, n_frames), out_len = rows * info.n_outputs, got = 0;
    float *out = malloc(out_len * sizeof *out);
    CHECK(ikid_model_predict(model, frames, n_frames, 18, out, out_len, &got) == IKID_STATUS_OK && got == rows, "ikid_model_predict");
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
    CHECK(ikid_predict(model, frames, n_frames, 18, out, out_len, &got) == IKID_STATUS_OK && got == rows, "ikid_predict");
#pragma GCC diagnostic pop

    /* A stream: the same recording, frame by frame, then timed, in packets, calibrated. */
    ikid_stream *stream = NULL;
    CHECK(ikid_stream_new(model, &stream) == IKID_STATUS_OK, "ikid_stream_new");
    CHECK(ikid_stream_set_missing_markers(stream, IKID_MISSING_MARKERS_FILL) == IKID_STATUS_OK, "set_missing_markers");
    float row[16];
    bool ready = false;
    for (size_t i = 0; i < info.window; i++)
        CHECK(ikid_stream_push(stream, frames + i * 18, 18, row, 16, &ready) == IKID_STATUS_OK, "ikid_stream_push");
    CHECK(ready && memcmp(row, out, info.n_outputs * sizeof *row) == 0, "stream equals predict");
    double row_sd[16];
    CHECK(ikid_stream_output_sd(stream, row_sd, 16) == IKID_STATUS_OK && row_sd[0] > 0 && isfinite(row_sd[2]), "ikid_stream_output_sd");
    CHECK(ikid_stream_output_sd(stream, row_sd, 2) == IKID_STATUS_INVALID_ARGUMENT && strstr(ikid_last_error(), "room for 2") != NULL, "short sd buffer");
    uint32_t bits = 99;
    CHECK(ikid_stream_status(stream, &bits) == IKID_STATUS_OK && bits != 99, "ikid_stream_status");
    CHECK(ikid_stream_filled_markers(stream, &bits) == IKID_STATUS_OK && bits == 0, "ikid_stream_filled_markers");
    CHECK(ikid_stream_reset(stream) == IKID_STATUS_OK, "ikid_stream_reset");
    double period = 1.0 / info.frame_rate_hz;
    CHECK(ikid_stream_push_at(stream, 0.0, frames, 18, row, 16, &ready) == IKID_STATUS_OK && !ready, "ikid_stream_push_at");
    CHECK(ikid_stream_push_at(stream, period, frames + 18, 18, row, 16, &ready) == IKID_STATUS_OK, "push_at again");
    const double identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    CHECK(ikid_stream_set_calibration(stream, identity, identity) == IKID_STATUS_OK, "ikid_stream_set_calibration");
    CHECK(ikid_stream_set_calibration_side(stream, identity, identity, "left") == IKID_STATUS_OK, "..._side");
    CHECK(ikid_stream_set_calibration_side(stream, NULL, NULL, NULL) == IKID_STATUS_OK, "calibration removed");
    double shapes[18];
    for (int k = 0; k < 18; k++) shapes[k] = 0.01 * (k % 7) - 0.03;
    CHECK(ikid_stream_set_calibration_shapes(stream, identity, identity, "right", shapes) == IKID_STATUS_OK, "ikid_stream_set_calibration_shapes");
    CHECK(ikid_stream_set_calibration_shapes(stream, NULL, NULL, NULL, shapes) == IKID_STATUS_INVALID_ARGUMENT && strstr(ikid_last_error(), "shapes") != NULL, "shapes without a calibration");
    shapes[4] = NAN;
    CHECK(ikid_stream_set_calibration_shapes(stream, identity, identity, NULL, shapes) == IKID_STATUS_INVALID_ARGUMENT && strstr(ikid_last_error(), "not finite") != NULL, "shapes not finite");
    CHECK(ikid_stream_set_calibration_shapes(stream, NULL, NULL, NULL, NULL) == IKID_STATUS_OK, "calibration and shapes removed");
    const double z_up[3] = {0, 0, 1}, y_up[3] = {0, 1, 0}, no_up[3] = {0, 0, 0};
    CHECK(ikid_stream_set_lab_up(stream, z_up) == IKID_STATUS_OK, "ikid_stream_set_lab_up");
    CHECK(ikid_stream_set_lab_up(stream, no_up) == IKID_STATUS_INVALID_ARGUMENT && strstr(ikid_last_error(), "up") != NULL, "a zero up");
    CHECK(ikid_stream_set_lab_up(stream, y_up) == IKID_STATUS_OK, "back to +Y");
    CHECK(ikid_stream_reset(stream) == IKID_STATUS_OK, "reset again");
    size_t packet = 64, packet_rows = 0;
    CHECK(ikid_stream_push_many(stream, frames, packet, 18, out, out_len, &packet_rows) == IKID_STATUS_OK && packet_rows == packet - info.window + 1, "ikid_stream_push_many");
    size_t before_refusal = 99;
    CHECK(ikid_stream_rows_before_refusal(stream, &before_refusal) == IKID_STATUS_OK && before_refusal == 0, "ikid_stream_rows_before_refusal");
    ikid_stream_free(stream);
    ikid_model_free(model);

    /* A refined tracker: frame by frame, then a block, calibrated. */
    ikid_tracker_settings settings = ikid_tracker_settings_default();
    settings.rate_hz = info.frame_rate_hz;
    ikid_tracker *tracker = NULL;
    CHECK(ikid_tracker_new(&settings, refiner, &tracker) == IKID_STATUS_OK, "ikid_tracker_new");
    ikid_model_free(refiner); /* the tracker holds its own reference */
    if (tracker == NULL) return 1;
    double estimate[12];
    ikid_tracker_flags flags;
    CHECK(ikid_tracker_push(tracker, frames64, 18, estimate, 12, &flags) == IKID_STATUS_OK && flags.ready && isfinite(estimate[0]), "ikid_tracker_push");
    double noise[9];
    CHECK(ikid_tracker_marker_noise(tracker, noise, 9) == IKID_STATUS_OK && noise[0] > 0, "ikid_tracker_marker_noise");
    double sd[6];
    CHECK(ikid_tracker_output_sd(tracker, sd, 6) == IKID_STATUS_OK && sd[0] > 0 && sd[5] > 0, "ikid_tracker_output_sd");
    CHECK(ikid_tracker_reset(tracker) == IKID_STATUS_OK, "ikid_tracker_reset");
    size_t block = 200, start = 99;
    double *block_out = malloc(block * 12 * sizeof *block_out);
    ikid_tracker_flags *block_flags = malloc(block * sizeof *block_flags);
    CHECK(ikid_tracker_run(tracker, frames64, block * 18, block_out, block * 12, block_flags, block, &start) == IKID_STATUS_OK && start == 0, "ikid_tracker_run");
    CHECK(ikid_tracker_set_calibration(tracker, identity, identity, "right") == IKID_STATUS_OK, "ikid_tracker_set_calibration");
    shapes[4] = 0.0;
    CHECK(ikid_tracker_set_calibration_shapes(tracker, identity, identity, "right", shapes) == IKID_STATUS_OK, "ikid_tracker_set_calibration_shapes");
    CHECK(ikid_tracker_set_calibration_shapes(tracker, NULL, NULL, NULL, shapes) == IKID_STATUS_INVALID_ARGUMENT, "tracker shapes without a calibration");
    CHECK(ikid_tracker_set_calibration(tracker, identity, identity, "right") == IKID_STATUS_OK, "calibration without shapes again");
    /* Stamped frames: fifty periods apart is a gap longer than the tracker carries itself
       through (30 ms), which restarts the filter. */
    size_t gap_restarts = 99;
    CHECK(ikid_tracker_push_at(tracker, 0.0, frames64, 18, estimate, 12, &flags) == IKID_STATUS_OK, "ikid_tracker_push_at");
    CHECK(ikid_tracker_push_at(tracker, 50.0 * period, frames64 + 18, 18, estimate, 12, &flags) == IKID_STATUS_OK, "push_at after a gap");
    CHECK(ikid_tracker_gap_restarts(tracker, &gap_restarts) == IKID_STATUS_OK && gap_restarts == 1, "ikid_tracker_gap_restarts");
    /* Two periods lost after it: carried through as two frames without markers, no restart. */
    size_t bridged = 99;
    CHECK(ikid_tracker_push_at(tracker, 53.0 * period, frames64 + 18, 18, estimate, 12, &flags) == IKID_STATUS_OK, "push_at after two lost frames");
    CHECK(ikid_tracker_bridged_frames(tracker, &bridged) == IKID_STATUS_OK && bridged == 2, "ikid_tracker_bridged_frames");
    CHECK(ikid_tracker_gap_restarts(tracker, &gap_restarts) == IKID_STATUS_OK && gap_restarts == 1, "no restart for two lost frames");
    CHECK(ikid_tracker_bridged_frames(tracker, NULL) == IKID_STATUS_NULL_PARAMETER, "bridged_frames into NULL");
    CHECK(ikid_tracker_push_at(tracker, 53.1 * period, frames64 + 36, 18, estimate, 12, &flags) == IKID_STATUS_INVALID_ARGUMENT, "a stamp too soon");
    ikid_tracker_free(tracker);

    /* The NULL-safe frees and a failure's message. */
    ikid_stream_free(NULL);
    ikid_tracker_free(NULL);
    ikid_model_free(NULL);
    CHECK(ikid_model_load("/nonexistent.safetensors", &model) == IKID_STATUS_IO && strstr(ikid_last_error(), "nonexistent") != NULL, "a failure");

    free(block_out);
    free(block_flags);
    free(out);
    free(frames);
    free(frames64);
    printf("%d passed, %d failed\n", passed, failed);
    return failed != 0;
}
