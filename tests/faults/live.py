"""Live-path probes: frames into a ``Stream`` and into the ``Tracker`` (garbage, bursts,
dropouts, a frame 1 km off, swapped labels, bad time stamps), bad settings, whole-recording
``predict`` on bad frames, and models whose weights were corrupted (one flipped sign bit).

The disturbed recording is the corpus' 4 s trial with the fault at frame 1500. Every output
more than 5° from the clean run's at the same frame must be flagged (refused, filled, or
marked missing); and one second after the fault ends the outputs must be back: the stream
with under 5 % of frames refused and within 2° of the clean run, the tracker within 2°."""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Callable
from functools import cache
from pathlib import Path

import numpy as np

from faults.corpus import SHIPPED, Corpus
from faults.framework import Api, Verdict, call, judge_error

K0 = 1500
SILENT_DEG = 5.0
RECOVERED_DEG = 2.0


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(seed)


# Each fault: (frames, times) of the clean trial -> (frames, times, index of each frame in the
# clean trial, the frame after the fault's end). Times None: pushed without time stamps.
Fault = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray | None, np.ndarray, int]]


def _at(change: Callable[[np.ndarray], None], length: int = 1, stamped: bool = True) -> Fault:
    def fault(frames, times):
        f = frames.copy()
        change(f[K0 : K0 + length])
        return f, times if stamped else None, np.arange(len(f)), K0 + length

    return fault


def _drop(n: int, stamped: bool) -> Fault:
    def fault(frames, times):
        keep = np.r_[0:K0, K0 + n : len(frames)]
        return frames[keep], times[keep] if stamped else None, keep, K0 + n

    return fault


def _swap(frames_from: int, length: int | None, a: int = 3, b: int = 4) -> Fault:
    """Markers ``a`` and ``b`` (MC2 and MC5 by default) under each other's labels from
    ``frames_from`` on, for ``length`` frames (None: to the end)."""

    def fault(frames, times):
        f = frames.copy()
        end = len(f) if length is None else frames_from + length
        ca, cb = slice(3 * a, 3 * a + 3), slice(3 * b, 3 * b + 3)
        f[frames_from:end, ca], f[frames_from:end, cb] = (
            frames[frames_from:end, cb],
            frames[frames_from:end, ca],
        )
        return f, times, np.arange(len(f)), end if length is not None else len(f) + 10**6

    return fault


def _time_edit(edit: Callable[[np.ndarray], None]) -> Fault:
    def fault(frames, times):
        t = times.copy()
        edit(t)
        return frames, t, np.arange(len(frames)), K0 + 2

    return fault


def _set(values) -> Callable[[np.ndarray], None]:
    def change(block):
        block[:] = values if not callable(values) else values(block)

    return change


def _shift_marker(j: int, metres: float) -> Callable[[np.ndarray], None]:
    def change(block):
        block[:, 3 * j : 3 * j + 3] += metres

    return change


FAULTS: dict[str, Fault] = {
    "frame-shifted-1km": _at(_set(lambda b: b + 1000.0)),
    "marker-MC5-shifted-1km": _at(_shift_marker(4, 1000.0)),
    "marker-MC5-shifted-1m": _at(_shift_marker(4, 1.0)),
    "marker-MC5-shifted-5cm": _at(_shift_marker(4, 0.05)),
    "marker-FAP-shifted-5cm": _at(_shift_marker(2, 0.05)),
    "garbage-frame": _at(_set(lambda b: _rng(1).uniform(-2, 2, b.shape))),
    "zeros-frame": _at(_set(0.0)),
    "nan-frame": _at(_set(np.nan)),
    "huge-value-1e30": _at(_set(lambda b: np.where(np.arange(b.shape[1]) == 13, 1e30, b))),
    "burst-50-garbage-frames": _at(_set(lambda b: _rng(2).uniform(-2, 2, b.shape)), 50),
    "burst-50-frames-1km-off": _at(_set(lambda b: b + 1000.0), 50),
    "dropout-100-nan-frames": _at(_set(np.nan), 100),
    "dropout-MC5-nan-200-frames": _at(_shift_marker(4, np.nan), 200),
    "lost-100-frames-stamped": _drop(100, True),
    "lost-100-frames-unstamped": _drop(100, False),
    "lost-500-frames-unstamped": _drop(500, False),
    "labels-MC2-MC5-swapped-from-1500": _swap(K0, None),
    "labels-MC2-MC5-swapped-one-frame": _swap(K0, 1),
    "labels-MC2-MC5-swapped-throughout": _swap(0, None),
    # The other pairs from the first frame: the styloids keep the forearm's shape as the
    # metacarpal heads keep the hand's; the others break it (read as a hand turned over).
    "labels-RSP-USP-swapped-throughout": _swap(0, None, 0, 1),
    "labels-MC2-MCB-swapped-throughout": _swap(0, None, 3, 5),
    "labels-USP-FAP-swapped-throughout": _swap(0, None, 1, 2),
}
TIME_FAULTS: dict[str, Fault] = {
    "time-backwards": _time_edit(lambda t: t.__setitem__(K0, t[K0 - 2])),
    "time-duplicated": _time_edit(lambda t: t.__setitem__(K0, t[K0 - 1])),
    "time-nan": _time_edit(lambda t: t.__setitem__(K0, np.nan)),
    "time-inf": _time_edit(lambda t: t.__setitem__(K0, np.inf)),
    # A source's clock glitch: one stamp far ahead (issue #30: it used to lock the stream out).
    "time-600s-ahead": _time_edit(lambda t: t.__setitem__(K0, t[K0] + 600.0)),
    "time-1e300": _time_edit(lambda t: t.__setitem__(K0, 1e300)),
}


@cache
def load(name_or_path: str):
    import ikid

    return ikid.load(name_or_path)


@cache
def clean(corpus_root: str, what: str):
    """Per-frame outputs of the clean 4 s trial: the stream's (NaN rows without one) or the
    tracker's q."""
    c = Corpus(Path(corpus_root))
    frames, times = c.long["markers"], c.long["time"]
    if what == "stream":
        s = load("wrist-ik").stream()
        out = np.full((len(frames), 3), np.nan)
        for i, (f, t) in enumerate(zip(frames, times, strict=True)):
            r = s.push(f, time=float(t))
            if r is not None:
                out[i] = r
        return out
    import ikid

    refiner = None if what == "tracker-bare" else load("wrist-track")
    return ikid.Tracker(rate_hz=1000.0, refiner=refiner).run(frames)["q"]


def stream_probe(corpus: Corpus, name: str, fault: Fault) -> Api:
    def fn(v: Verdict) -> None:
        import ikid

        frames, times, index, end = fault(corpus.long["markers"], corpus.long["time"])
        ref = clean(str(corpus.root), "stream")
        s = load("wrist-ik").stream()
        status = []  # per pushed frame: "ok", "filled", "filling", "refused"
        d = np.zeros(len(frames))
        for i, f in enumerate(frames):
            out, e = call(s.push, f, time=None if times is None else float(times[i]))
            if e is not None:
                if not isinstance(e, ikid.InputError):
                    judge_error(v, e, [], f"push of frame {i}: ")
                    return
                status.append("refused")
                continue
            if out is None:
                status.append("filling")
                continue
            status.append("filled" if s.filled_markers or getattr(s, "status", 0) else "ok")
            if np.isfinite(ref[index[i]]).all():
                d[i] = float(np.degrees(np.max(np.abs(out - ref[index[i]]))))
                d[i] = d[i] if math.isfinite(d[i]) else math.inf
        ok = np.array([st == "ok" for st in status])
        silent = ok & (d > SILENT_DEG)
        if silent.any():
            v.silent(
                f"{int(silent.sum())} unflagged outputs over {SILENT_DEG:g}° from the clean run's "
                f"(worst {d[silent].max():.3g}°, first at frame {int(np.argmax(silent))})"
            )
        after = index >= end
        if after.any():
            refused = sum(st == "refused" for st, a in zip(status, after, strict=True) if a)
            if refused > 0.05 * after.sum():
                v.silent(f"{refused} of the {int(after.sum())} frames after the fault refused (over 5 %)")
            late = (index >= end + 1000) & (d > RECOVERED_DEG)
            if late.any():
                v.silent(f"not recovered 1 s after the fault: still {d[late].max():.3g}° from the clean run")

    return Api(f"stream/{name}", fn)


def _tracker_with_skips(make: Callable, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, object]:
    """q and flags over ``frames``, frames the tracker refuses skipped (and flagged): a fresh
    tracker replays the run up to each refused frame, so no output is lost to an error. The
    last error is returned if it was not ikid's or named no frame."""
    import ikid

    skips: list[int] = []
    while True:
        tracker = make()
        q = np.full((len(frames), 3), np.nan)
        flagged = np.zeros(len(frames), bool)
        flagged[skips] = True
        bounds = [-1, *skips, len(frames)]
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if b - a <= 1:
                continue
            out, e = call(tracker.run, frames[a + 1 : b])
            if e is not None:
                frame = getattr(e, "frame", None)
                if not isinstance(e, ikid.InputError) or frame is None or a + 1 + frame in skips:
                    return q, flagged, e
                skips = sorted([*skips, a + 1 + int(frame)])
                break
            q[a + 1 : b] = out["q"]
            flagged[a + 1 : b] = (out["missing"] != 0) | ~np.isfinite(out["q"]).all(axis=1)
            if "status" in out:  # the tracker's per-frame status bits (rejected, held, restarted...)
                flagged[a + 1 : b] |= np.asarray(out["status"]) != 0
        else:
            return q, flagged, tracker


def tracker_probe(corpus: Corpus, name: str, fault: Fault, refined: bool) -> Api:
    def fn(v: Verdict) -> None:
        import ikid

        frames, _, index, end = fault(corpus.long["markers"], corpus.long["time"])
        ref = clean(str(corpus.root), "tracker" if refined else "tracker-bare")
        q, flagged, tracker = _tracker_with_skips(
            lambda: ikid.Tracker(rate_hz=1000.0, refiner=load("wrist-track") if refined else None), frames
        )
        if isinstance(tracker, BaseException):
            if judge_error(v, tracker, [], "Tracker.run: "):
                v.silent(f"the tracker's error names no frame: {tracker}")
            return
        d = np.degrees(np.max(np.abs(q - ref[index]), axis=1))
        d[~np.isfinite(d) & np.isfinite(ref[index]).all(axis=1)] = np.inf
        bad_rows = (d > SILENT_DEG) & ~flagged
        if bad_rows.any():
            v.silent(
                f"{int(bad_rows.sum())} unflagged frames over {SILENT_DEG:g}° from the clean run's "
                f"(worst {d[bad_rows].max():.3g}°, first at frame {int(np.argmax(bad_rows))}); "
                f"marker noise learned {np.max(tracker.marker_noise) * 1e3:.3g} mm"
            )
        late = (index >= end + 1000) & ~flagged
        if late.any() and d[late].max() > RECOVERED_DEG:
            v.silent(f"not recovered 1 s after the fault: still {d[late].max():.3g}° from the clean run")

    return Api(f"tracker/{'refined' if refined else 'bare'}/{name}", fn)


def stream_time_probe(corpus: Corpus, name: str, fault: Fault) -> Api:
    """A bad time stamp: that push is refused with an ikid error naming the time; the rest goes on."""

    def fn(v: Verdict) -> None:
        import ikid

        frames, times, _, _ = fault(corpus.long["markers"], corpus.long["time"])
        s = load("wrist-ik").stream()
        refused = []
        for i, (f, t) in enumerate(zip(frames[: K0 + 200], times[: K0 + 200], strict=True)):
            _, e = call(s.push, f, time=float(t))
            if e is not None:
                if not isinstance(e, ikid.InputError):
                    judge_error(v, e, [], f"push at frame {i}: ")
                    return
                refused.append(i)
        if K0 not in refused:
            v.silent(f"the frame with the bad time stamp ({times[K0]}) was taken")
        if len(refused) > 5:
            v.silent(f"{len(refused)} frames refused after one bad time stamp (locked out?)")

    return Api(f"stream/{name}", fn)


def setting_probe(setting: str, value: float) -> Api:
    def fn(v: Verdict) -> None:
        import ikid

        t, e = call(ikid.Tracker, **{"rate_hz": 1000.0, setting: value})
        if e is None:
            v.silent(f"Tracker({setting}={value}) accepted")
        else:
            judge_error(v, e, [setting])

    return Api(f"tracker-settings/{setting}={value}", fn)


def predict_probe(corpus: Corpus, name: str, change: Callable[[np.ndarray], np.ndarray], **kw) -> Api:
    def fn(v: Verdict) -> None:
        frames = corpus.long["markers"][:2000].copy()
        model = load("wrist-ik")
        expected = model.predict(frames)
        bad = change(frames)
        out, e = call(model.predict, bad, **kw)
        if e is not None:
            if judge_error(v, e, []) and "frame" not in str(e) and "thread" not in str(e):
                v.silent(f"predict's error names no frame: {e}")
            return
        if out.shape != expected.shape:
            return
        d = np.degrees(np.max(np.abs(out - expected), axis=1))
        off = ~np.isfinite(d) | (d > SILENT_DEG)
        if hasattr(model, "frame_status"):  # rows flagged outside the envelope or implausible
            import ikid

            features, e = call(ikid.compute_features, bad, model.feature_set)
            if e is None:
                flags, e = call(model.frame_status, out, features[model.window - 1 :])
            if e is None:
                off &= np.asarray(flags) == 0
        if off.any():
            v.silent(f"predict gave {int(off.sum())} rows over {SILENT_DEG:g}° off, nothing flagged")

    return Api(f"predict/{name}", fn)


def stream_option_probe(name: str, make: Callable, needle: str) -> Api:
    def fn(v: Verdict) -> None:
        _, e = call(make, load("wrist-ik"))
        if e is None:
            v.silent(f"{name}: accepted")
        else:
            judge_error(v, e, [needle])

    return Api(f"stream-options/{name}", fn)


# --- corrupted weights ---------------------------------------------------------------------------


def tensors(data: bytes) -> dict:
    n = struct.unpack("<Q", data[:8])[0]
    header = json.loads(data[8 : 8 + n])
    header.pop("__metadata__", None)
    return {k: (8 + n + v["data_offsets"][0], v) for k, v in header.items()}


def flip_sign(src: Path, dst: Path, tensor: str, element: int) -> None:
    data = bytearray(src.read_bytes())
    start, info = tensors(bytes(data))[tensor]
    size = {"F32": 4, "F64": 8, "F16": 2, "BF16": 2}[info["dtype"]]
    count = (info["data_offsets"][1] - info["data_offsets"][0]) // size
    k = min(element, count - 1)
    data[start + size * k + size - 1] ^= 0x80
    dst.write_bytes(bytes(data))


def weight_targets(path: Path) -> list[tuple[str, int]]:
    names = sorted(tensors(path.read_bytes()))
    weights = [n for n in names if n.endswith(".weight")]
    scaling = [n for n in names if n.startswith(("input.", "output."))]
    picks = [weights[0], weights[-1], *scaling[:2]]
    return [(t, e) for t in dict.fromkeys(picks) for e in (0, 7)]


def corrupt_weight_probe(corpus: Corpus, model: str, tensor: str, element: int) -> Api:
    def fn(v: Verdict) -> None:
        import ikid

        dst = corpus.root / "api-tmp" / f"{model}-{tensor}-{element}.safetensors"
        dst.parent.mkdir(exist_ok=True)
        flip_sign(corpus.model(model), dst, tensor, element)
        m, e = call(ikid.load, dst)
        if e is None:
            v.silent(f"a weight with a flipped sign bit ({tensor}[{element}]) loaded without complaint")
        elif not isinstance(e, ikid.ModelFileError):
            judge_error(v, e, [str(dst)])
            v.silent(f"not a ModelFileError: {type(e).__name__}: {e}")
        else:
            judge_error(v, e, [str(dst)])

    return Api(f"weights/{model}/{tensor}[{element}]-sign-flipped", fn)


def probes(corpus: Corpus) -> list[Api]:
    out: list[Api] = []
    for name, fault in FAULTS.items():
        out.append(stream_probe(corpus, name, fault))
        if name.endswith("-stamped"):
            continue  # the tracker takes no time stamps: the same as unstamped
        out.append(tracker_probe(corpus, name, fault, True))
        out.append(tracker_probe(corpus, name, fault, False))
    for name, fault in TIME_FAULTS.items():
        out.append(stream_time_probe(corpus, name, fault))
    for setting in ("length_scale", "mass_scale", "rate_hz", "jerk_noise"):
        for value in (0.0, -1.0, math.nan, math.inf, 1e308):
            out.append(setting_probe(setting, value))

    def shifted(f):
        f[1000] += 1000.0
        return f

    def nan_frame(f):
        f[1000] = np.nan
        return f

    def inf_value(f):
        f[1000, 4] = np.inf
        return f

    def garbage(f):
        return _rng(4).uniform(-5, 5, f.shape)

    out += [
        predict_probe(corpus, "frame-shifted-1km", shifted),
        predict_probe(corpus, "nan-frame", nan_frame),
        predict_probe(corpus, "inf-value", inf_value),
        predict_probe(corpus, "all-garbage", garbage),
        predict_probe(corpus, "17-columns", lambda f: f[:, :17]),
        predict_probe(corpus, "3-frames", lambda f: f[:3]),
        predict_probe(corpus, "0-frames", lambda f: f[:0]),
        predict_probe(corpus, "threads-0", lambda f: f, threads=0),
        predict_probe(corpus, "threads-huge", lambda f: f, threads=10**6),
    ]
    out += [
        stream_option_probe("missing_markers=bogus", lambda m: m.stream(missing_markers="bogus"), "bogus"),
        stream_option_probe("missing_markers=empty", lambda m: m.stream(missing_markers=""), "missing"),
    ]
    for model in SHIPPED:
        for tensor, element in weight_targets(corpus.model(model)):
            out.append(corrupt_weight_probe(corpus, model, tensor, element))
    return out
