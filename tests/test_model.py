"""The Python surface of Model and Stream: shapes, dtypes, layouts, errors."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import ikid
from conftest import make_model, marker_frames


def test_predict_shape_and_alignment(model, frames):
    out = model.predict(frames)
    assert out.shape == (len(frames) - model.window + 1, 3) and out.dtype == np.float32
    # Row i is the prediction for frame i + window - 1, identical to the stream's.
    stream = model.stream()
    streamed = [stream.push(f) for f in frames]
    assert all(s is None for s in streamed[: model.window - 1])
    np.testing.assert_array_equal(np.stack(streamed[model.window - 1 :]), out)


def test_short_recordings_give_no_rows(model, frames):
    assert model.predict(frames[:3]).shape == (0, 3)


def test_float64_lists_and_strided_inputs_agree(model, frames):
    want = model.predict(frames)
    np.testing.assert_array_equal(model.predict(frames.astype(np.float64)), want)
    np.testing.assert_array_equal(model.predict(frames.tolist()), want)
    wide = np.zeros((len(frames), 36), np.float32)
    wide[:, ::2] = frames  # non-contiguous view
    np.testing.assert_array_equal(model.predict(wide[:, ::2]), want)
    np.testing.assert_array_equal(model.predict(np.asfortranarray(frames)), want)
    stream = model.stream()
    for f in wide[:, ::2][: model.window - 1]:
        assert stream.push(f) is None
    np.testing.assert_array_equal(stream.push(frames[model.window - 1].astype(np.float64)), want[0])


def test_wrong_dtype_is_refused(model, frames):
    with pytest.raises(ikid.InputError, match="dtype int64"):
        model.predict(frames.astype(np.int64))
    with pytest.raises(ikid.InputError, match="dtype complex"):
        model.stream().push(frames[0].astype(np.complex64))
    with pytest.raises(ikid.InputError, match="frame"):
        model.stream().push("not numbers")


def test_wrong_shapes_are_refused(model, frames):
    with pytest.raises(ikid.InputError, match="17 columns.*18"):
        model.predict(frames[:, :17])
    with pytest.raises(ikid.InputError, match="2-D"):
        model.predict(frames[0])
    with pytest.raises(ikid.InputError, match="17 values, expected 18: a marker frame"):
        model.stream().push(frames[0, :17])


def test_nan_is_an_error_naming_the_marker_never_a_silent_output(model, frames):
    bad = frames.copy()
    bad[7, 13] = np.nan  # MC5.y
    with pytest.raises(ikid.InputError, match=r"frame 7: value MC5\.y is NaN"):
        model.predict(bad)
    stream = model.stream()
    for f in frames[:6]:
        stream.push(f)
    with pytest.raises(ikid.InputError, match="MC5.y"):
        stream.push(bad[7])
    # The refused frame did not enter the window.
    ref = model.stream()
    for f in frames[:6]:
        ref.push(f)
    np.testing.assert_array_equal(stream.push(frames[6]), ref.push(frames[6]))


def test_a_fill_stream_fills_one_missing_marker_and_flags_it(model):
    trial = ikid.simulate(seed=21, duration=4.0)
    frames = trial.markers.astype(np.float32)
    gone = frames.copy()
    gone[3000:3100, 15:18] = np.nan  # MCB hidden for 0.1 s after 3 s of motion
    with pytest.raises(ikid.InputError, match="MCB"):
        model.stream().push_many(gone)  # the card says "refuse"
    stream = model.stream(missing_markers="fill")
    assert stream.missing_markers == "fill" and model.missing_markers == "refuse"
    out = stream.push_many(gone[:3000])
    assert stream.filled_markers == []
    row = stream.push(gone[3000])
    assert stream.filled_markers == ["MCB"]
    # Clean markers: the filled frame gives (nearly) what the complete frame gives.
    ref = model.stream()
    ref.push_many(frames[:3000])
    np.testing.assert_allclose(row, ref.push(frames[3000]), atol=1e-3 * np.abs(out).max())
    filled, mask = ikid.fill_gaps(gone)
    assert mask[3000:3100].tolist() == [32] * 100 and not mask[:3000].any() and not mask[3100:].any()
    assert np.abs(filled - frames).max() < 1e-4
    # What cannot be filled (two markers of a segment) raises, or with "keep" stays missing.
    two = gone.copy()
    two[3200, 9:15] = np.nan
    with pytest.raises(
        ikid.InputError, match=r"frame 3200: missing marker\(s\) MC2, MC5 not filled: only one"
    ):
        ikid.fill_gaps(two)
    kept, mask = ikid.fill_gaps(two, unfillable="keep")
    assert np.isnan(kept[3200, 9:15]).all() and mask[3200] == 0 and mask[3050] == 32
    with pytest.raises(ikid.InputError, match="guess"):
        model.stream(missing_markers="guess")
    with pytest.raises(ikid.InputError, match="raise.*keep"):
        ikid.fill_gaps(two, unfillable="skip")
    with pytest.raises(ikid.InputError, match="joint_state"):
        make_model("joint_state").stream(missing_markers="fill")


def test_reset_and_filled(model, frames):
    stream = model.stream()
    for f in frames[:3]:
        stream.push(f)
    assert stream.filled == 3
    stream.reset()
    assert stream.filled == 0 and stream.push(frames[0]) is None
    assert stream.model.name == model.name


def test_card_properties(model):
    assert model.task == "ik" and model.feature_set == "markers" and model.window == 5
    assert model.frame_len == 18 and model.n_outputs == 3
    assert model.output_names == ikid.coordinate_names() and model.output_units == ["rad"] * 3
    assert model.layer_widths == [90, 32, 32, 3]
    assert model.frame_names[:3] == ["RSP.x", "RSP.y", "RSP.z"]
    card = model.card
    assert card["format_version"] == 1 and card["frame_rate_hz"] == 1000.0
    assert "Model(name=" in repr(model)


def test_save_load_round_trip(tmp_path, model, frames):
    path = tmp_path / "m.safetensors"
    model.save(path)
    again = ikid.load(path)
    np.testing.assert_array_equal(again.predict(frames), model.predict(frames))
    assert ikid.load(str(path)).card == model.card
    assert ikid.Model.from_bytes(model.to_bytes()).card == model.card


def test_bad_files_raise_model_file_error(tmp_path, model):
    data = model.to_bytes()
    truncated = tmp_path / "truncated.safetensors"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ikid.ModelFileError, match="not a valid safetensors"):
        ikid.load(truncated)
    with pytest.raises(FileNotFoundError, match="no model file 'nope'"):
        ikid.load("nope")
    with pytest.raises(FileNotFoundError):
        ikid.Model.load(tmp_path / "missing.safetensors")


def test_threads_share_a_model_with_their_own_streams(frames):
    model = make_model(hidden=(64, 64))
    data = marker_frames(400, seed=3)
    want = model.predict(data)
    results: dict[int, np.ndarray] = {}

    def run(k: int) -> None:
        stream = model.stream()
        results[k] = np.stack([o for f in data if (o := stream.push(f)) is not None])

    threads = [threading.Thread(target=run, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    assert sorted(results) == [0, 1, 2, 3]
    for out in results.values():
        np.testing.assert_array_equal(out, want)


def test_push_many_in_packets_equals_push(model, frames):
    want = model.predict(frames)
    stream = model.stream()
    got = np.concatenate([stream.push_many(frames[i : i + 7]) for i in range(0, len(frames), 7)])
    np.testing.assert_array_equal(got, want)
    bad = frames[:6].copy()
    bad[3, 0] = np.nan
    with pytest.raises(ikid.InputError, match="frame 3: value RSP.x"):
        model.stream().push_many(bad)
    with pytest.raises(ikid.InputError, match="17 columns"):
        model.stream().push_many(frames[:, :17])


def test_review_regressions_inputs(model, frames):
    # float64 frames with zero rows work like float32 ones
    assert model.predict(np.zeros((0, 18))).shape == (0, 3)
    # bytes, strings and ints are refused, not reinterpreted
    for bad in (bytes(18), "x" * 18, np.arange(18)):
        with pytest.raises(ikid.InputError):
            model.stream().push(bad)
    # the float64 fast path equals float32
    s32, s64 = model.stream(), model.stream()
    for f in frames[:6]:
        a, b = s32.push(f), s64.push(f.astype(np.float64))
    np.testing.assert_array_equal(a, b)


def test_markers_far_outside_any_arm_are_an_error_not_nan(frames):
    import json

    from conftest import make_card
    from ikid import _native

    # A single linear layer summing 90 inputs: 90 x 1e37 overflows float32.
    card = make_card(activations=["identity"])
    m = _native.build_model(
        json.dumps(card),
        [np.ones((3, 90), np.float32)],
        [np.zeros(3, np.float32)],
        np.ones(90, np.float32),
        np.zeros(90, np.float32),
        np.ones(3, np.float32),
        np.zeros(3, np.float32),
    )
    # Markers 1e37 m from the origin: in float32 an arm's size vanishes beside that (they all
    # coincide), so they are refused as no arm's before the network could overflow on them
    # (the overflow itself is an error too: crates/ikid/tests/model_file.rs).
    huge = np.full((10, 18), 1e37, np.float32)
    with pytest.raises(ikid.InputError, match="frame 0: the markers spread over 0.000 m"):
        m.predict(huge)
    spread = np.tile(np.arange(18, dtype=np.float32), (10, 1)) * np.float32(1e36)
    with pytest.raises(ikid.InputError, match="are the units mm, read as metres"):
        m.predict(spread)


def test_push_many_refusing_a_frame_part_way_gives_the_rows_before_it_with_the_error():
    # The reviewer's case: RSP and USP lost at frame 300 of a block (no fill for two markers).
    # The 251 predictions of frames 49-299 were computed, and pushed: they come with the error,
    # equal to what frame-by-frame pushes give (the oracle).
    model = ikid.load("wrist-ik")
    frames = ikid.simulate("random", seed=61, duration=0.5).markers.astype(np.float32)
    frames[300, 0:6] = np.nan
    one_by_one = model.stream()
    want = [r for f in frames[:300] if (r := one_by_one.push(f)) is not None]
    with pytest.raises(ikid.InputError) as refused:
        model.stream().push_many(frames)
    assert refused.value.frame == 300 and refused.value.outputs.shape == (251, 3)
    np.testing.assert_array_equal(refused.value.outputs, np.array(want))
