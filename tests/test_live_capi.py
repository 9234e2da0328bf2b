"""libikid's ``ikid_stream_push_at`` with a source whose clock misbehaves (through ctypes on
the library `make c` builds): one bad stamp is refused alone and the frames after it give
what they give without it; a clock that restarts is taken after three frames."""

from __future__ import annotations

import ctypes as C
import os

import numpy as np
import pytest

import ikid
from live_peers import trial_frames

N, K0 = 3000, 1000


@pytest.fixture(scope="module")
def capi(tmp_path_factory):
    from faults.capi import LIB, last_error, lib

    if not LIB.exists():
        pytest.fail(f"{LIB} is missing: run `make c` (make check does)")
    path = tmp_path_factory.mktemp("capi-live") / "wrist-ik.safetensors"
    ikid.load("wrist-ik").save(path)
    model = C.c_void_p()
    assert lib().ikid_model_load(os.fsencode(path), C.byref(model)) == 0, last_error()
    yield lib(), model, last_error
    lib().ikid_model_free(model)


def _push_all(capi, frames: np.ndarray, times: np.ndarray) -> list:
    """Per frame: None if refused (with the error), else the output (or [] while filling)."""
    from faults.capi import f32p

    lib, model, last_error = capi
    stream = C.c_void_p()
    assert lib.ikid_stream_new(model, C.byref(stream)) == 0, last_error()
    out = np.zeros(3, np.float32)
    ready = C.c_bool(False)
    results = []
    try:
        for f, t in zip(frames, times, strict=True):
            f32 = np.ascontiguousarray(f, np.float32)
            status = lib.ikid_stream_push_at(
                stream, float(t), f32.ctypes.data_as(f32p), 18, out.ctypes.data_as(f32p), 3, C.byref(ready)
            )
            results.append((None, last_error()) if status != 0 else (out.copy() if ready.value else [], None))
    finally:
        lib.ikid_stream_free(stream)
    return results


@pytest.mark.parametrize("bad", [600.0, 1e300, -5.0, "repeat"])
def test_push_at_refuses_one_bad_stamp_alone(capi, bad):
    frames = trial_frames(N)
    times = np.arange(N) * 1e-3
    glitched = times.copy()
    glitched[K0] = times[K0 - 1] if bad == "repeat" else times[K0] + bad
    got = _push_all(capi, frames, glitched)
    refused = [k for k, (o, _) in enumerate(got) if o is None]
    assert refused == [K0], (bad, refused[:10])
    assert "glitch of the source's clock" in got[K0][1]
    # The oracle: the same stream never sent frame K0 (frames lost, not a bad clock).
    keep = np.arange(N) != K0
    without = _push_all(capi, frames[keep], times[keep])
    for (a, _), (b, _) in zip(got[K0 + 1 :], without[K0:], strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    share = len(refused) / (N - K0)
    assert share < 0.05


def test_push_at_takes_a_restarted_clock_after_three_frames(capi):
    frames = trial_frames(N)
    times = np.where(np.arange(N) < K0, np.arange(N), np.arange(N) - K0) * 1e-3
    got = _push_all(capi, frames, times)
    assert [k for k, (o, _) in enumerate(got) if o is None] == [K0, K0 + 1]
    assert all(o is not None for o, _ in got[K0 + 2 :])
