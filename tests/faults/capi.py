"""C ABI probes: libikid (``target/release/libikid.so``, built by ``make capi``) through
ctypes, in a worker process (a crash fails the probe, not the suite).

Every exported function gets NULL for each pointer, buffers one short, lengths that do not
match the model, non-finite values and bad strings. The status must be the documented one
(NULL -> ``IKID_STATUS_NULL_PARAMETER``; otherwise an error status, never
``IKID_STATUS_PANIC``), ``ikid_last_error()`` must say why (naming the file for a file), and
nothing may be written to an output on failure (sentinels are checked), except where the
header says the contents are unspecified (``ikid_stream_push_many``, ``ikid_tracker_run``)."""

from __future__ import annotations

import ctypes as C
import math
import os
import re
from collections.abc import Callable
from functools import cache
from pathlib import Path

import numpy as np

from faults.corpus import Corpus
from faults.framework import ROOT, Api, Verdict

LIB = ROOT / "target" / "release" / "libikid.so"
OK, NULL, ARG, IO, MODEL_FILE, INPUT, PANIC = range(7)
SENTINEL = -12345.0
SIZE_MAX = 2**64 - 1

f32p, f64p = C.POINTER(C.c_float), C.POINTER(C.c_double)
vp, sz = C.c_void_p, C.c_size_t


HEADER = ROOT / "include" / "ikid.h"
C_TYPES = {
    "uint32_t": C.c_uint32,
    "int32_t": C.c_int32,
    "uint64_t": C.c_uint64,
    "bool": C.c_bool,
    "double": C.c_double,
    "float": C.c_float,
    "size_t": C.c_size_t,
}


def header_struct(name: str) -> type[C.Structure]:
    """A ctypes structure with the fields ``include/ikid.h`` gives ``name`` (the ABI grows
    fields; a stale copy here would let the library write past a buffer)."""
    text = HEADER.read_text(encoding="utf-8")
    body = text.split(f"typedef struct {name} {{", 1)[1].split(f"}} {name};", 1)[0]
    fields = []
    for line in body.splitlines():
        line = line.split("//")[0].strip()
        m = re.fullmatch(r"(\w+)\s+(\w+)(?:\[(\d+)\])?;", line)
        if m:
            ctype = C_TYPES[m.group(1)]
            fields.append((m.group(2), ctype * int(m.group(3)) if m.group(3) else ctype))
    return type(name, (C.Structure,), {"_fields_": fields})


Settings = header_struct("ikid_tracker_settings")
Flags = header_struct("ikid_tracker_flags")
Info = header_struct("ikid_model_info")


SIGNATURES = {
    "ikid_version": ([], C.c_char_p),
    "ikid_status_message": ([C.c_int], C.c_char_p),
    "ikid_last_error": ([], C.c_char_p),
    "ikid_model_load": ([C.c_char_p, C.POINTER(vp)], C.c_int),
    "ikid_model_load_bytes": ([C.c_char_p, sz, C.POINTER(vp)], C.c_int),
    "ikid_model_free": ([vp], None),
    "ikid_model_get_info": ([vp, C.POINTER(Info)], C.c_int),
    "ikid_model_describe": ([vp, C.c_uint32], C.c_char_p),
    "ikid_model_name": ([vp], C.c_char_p),
    "ikid_model_task": ([vp], C.c_char_p),
    "ikid_model_feature_set": ([vp], C.c_char_p),
    "ikid_model_output_name": ([vp, sz], C.c_char_p),
    "ikid_model_frame_name": ([vp, sz], C.c_char_p),
    "ikid_model_predict_rows": ([vp, sz], sz),
    "ikid_model_predict": ([vp, f32p, sz, sz, f32p, sz, C.POINTER(sz)], C.c_int),
    "ikid_stream_new": ([vp, C.POINTER(vp)], C.c_int),
    "ikid_stream_push": ([vp, f32p, sz, f32p, sz, C.POINTER(C.c_bool)], C.c_int),
    "ikid_stream_push_at": ([vp, C.c_double, f32p, sz, f32p, sz, C.POINTER(C.c_bool)], C.c_int),
    "ikid_stream_set_missing_markers": ([vp, C.c_uint32], C.c_int),
    "ikid_stream_set_calibration": ([vp, f64p, f64p], C.c_int),
    "ikid_stream_set_calibration_side": ([vp, f64p, f64p, C.c_char_p], C.c_int),
    "ikid_stream_set_calibration_shapes": ([vp, f64p, f64p, C.c_char_p, f64p], C.c_int),
    "ikid_stream_set_lab_up": ([vp, f64p], C.c_int),
    "ikid_stream_status": ([vp, C.POINTER(C.c_uint32)], C.c_int),
    "ikid_stream_filled_markers": ([vp, C.POINTER(C.c_uint32)], C.c_int),
    "ikid_stream_push_many": ([vp, f32p, sz, sz, f32p, sz, C.POINTER(sz)], C.c_int),
    "ikid_stream_reset": ([vp], C.c_int),
    "ikid_stream_free": ([vp], None),
    "ikid_tracker_settings_default": ([], Settings),
    "ikid_tracker_new": ([C.POINTER(Settings), vp, C.POINTER(vp)], C.c_int),
    "ikid_tracker_push": ([vp, f64p, sz, f64p, sz, C.POINTER(Flags)], C.c_int),
    "ikid_tracker_push_at": ([vp, C.c_double, f64p, sz, f64p, sz, C.POINTER(Flags)], C.c_int),
    "ikid_tracker_gap_restarts": ([vp, C.POINTER(sz)], C.c_int),
    "ikid_tracker_run": ([vp, f64p, sz, f64p, sz, C.POINTER(Flags), sz, C.POINTER(sz)], C.c_int),
    "ikid_tracker_reset": ([vp], C.c_int),
    "ikid_tracker_marker_noise": ([vp, f64p, sz], C.c_int),
    "ikid_tracker_free": ([vp], None),
    "ikid_tracker_set_calibration": ([vp, f64p, f64p, C.c_char_p], C.c_int),
    "ikid_tracker_set_calibration_shapes": ([vp, f64p, f64p, C.c_char_p, f64p], C.c_int),
}


@cache
def lib() -> C.CDLL:
    if not LIB.exists():
        raise FileNotFoundError(f"{LIB} is missing: run `make capi`")
    handle = C.CDLL(str(LIB))
    for name, (args, res) in SIGNATURES.items():
        fn = getattr(handle, name)
        fn.argtypes, fn.restype = args, res
    return handle


def last_error() -> str:
    return (lib().ikid_last_error() or b"").decode("utf-8", "replace")


def expect(v: Verdict, what: str, status: int, allowed: set[int], needle: str = "") -> bool:
    """``status`` one of ``allowed`` (an error needs a message); True if it failed as it should."""
    if status == PANIC:
        v.traceback(f"{what}: IKID_STATUS_PANIC ({last_error()})")
        return False
    if status not in allowed:
        if status == OK:
            v.silent(f"{what}: IKID_STATUS_OK, expected status {sorted(allowed)}")
        else:
            v.silent(f"{what}: status {status}, expected {sorted(allowed)} ({last_error()})")
        return False
    if status != OK:
        message = last_error()
        if not message:
            v.silent(f"{what}: status {status} but ikid_last_error() is empty")
        elif needle and needle not in message:
            v.silent(f"{what}: message does not name {needle!r}: {message}")
    return status != OK


class Handles:
    """A model (wrist-ik or wrist-track), a stream and a tracker for one probe, freed after it."""

    def __init__(self, corpus: Corpus) -> None:
        self.corpus = corpus
        self.models: list[vp] = []
        self.streams: list[vp] = []
        self.trackers: list[vp] = []

    def model(self, name: str = "wrist-ik") -> vp:
        h = vp()
        status = lib().ikid_model_load(os.fsencode(self.corpus.model(name)), C.byref(h))
        assert status == OK, last_error()
        self.models.append(h)
        return h

    def stream(self, model: vp | None = None) -> vp:
        h = vp()
        assert lib().ikid_stream_new(model or self.model(), C.byref(h)) == OK, last_error()
        self.streams.append(h)
        return h

    def tracker(self, refiner: vp | None = None) -> vp:
        h = vp()
        settings = lib().ikid_tracker_settings_default()
        settings.rate_hz = 1000.0
        assert lib().ikid_tracker_new(C.byref(settings), refiner, C.byref(h)) == OK, last_error()
        self.trackers.append(h)
        return h

    def close(self) -> None:
        for h in self.streams:
            lib().ikid_stream_free(h)
        for h in self.trackers:
            lib().ikid_tracker_free(h)
        for h in self.models:
            lib().ikid_model_free(h)


def frames32(corpus: Corpus, n: int) -> np.ndarray:
    return np.ascontiguousarray(corpus.long["markers"][:n], np.float32)


def frames64(corpus: Corpus, n: int) -> np.ndarray:
    return np.ascontiguousarray(corpus.long["markers"][:n], np.float64)


def ptr(a: np.ndarray | None, kind=f32p):
    return None if a is None else a.ctypes.data_as(kind)


def unchanged(v: Verdict, what: str, buf: np.ndarray) -> None:
    if not np.all(buf == SENTINEL):
        v.silent(f"{what}: output written although the call failed")


def probe(corpus: Corpus, name: str, body: Callable[[Verdict, Handles], None]) -> Api:
    def fn(v: Verdict) -> None:
        h = Handles(corpus)
        try:
            body(v, h)
        finally:
            h.close()

    return Api(f"capi/{name}", fn, timeout=30.0)


# --- the probes ----------------------------------------------------------------------------------


def load_probes(corpus: Corpus) -> list[Api]:
    out = []
    files = {
        "missing-file": (corpus.root / "no-such.safetensors", {IO}),
        "directory": (corpus.mut / "safetensors" / "special-directory.safetensors", {IO}),
        "fifo": (corpus.mut / "safetensors" / "special-fifo.safetensors", {IO}),
        "dev-zero": (Path("/dev/zero"), {IO}),
        "sparse-4gb": (corpus.mut / "safetensors" / "special-sparse4g.safetensors", {IO}),
        "empty-file": (corpus.mut / "safetensors" / "empty.safetensors", {MODEL_FILE}),
        "truncated": (corpus.mut / "safetensors" / "junk-prepend.safetensors", {MODEL_FILE}),
    }
    for name, (path, allowed) in files.items():

        def body(v, h, path=path, allowed=allowed, name=name):
            out_h = vp(12345)
            status = lib().ikid_model_load(os.fsencode(path), C.byref(out_h))
            if expect(v, f"ikid_model_load({name})", status, allowed, str(path)) and out_h.value != 12345:
                v.silent("ikid_model_load wrote *out although it failed")
            if status == OK:
                lib().ikid_model_free(out_h)

        out.append(probe(corpus, f"ikid_model_load/{name}", body))
    for cut in sorted({*(p for p in corpus.mutations("safetensors") if p.name.startswith("trunc-"))}):

        def body(v, h, cut=cut):
            data = cut.read_bytes()
            out_h = vp()
            status = lib().ikid_model_load_bytes(data, len(data), C.byref(out_h))
            expect(v, f"ikid_model_load_bytes({len(data)} bytes)", status, {MODEL_FILE})
            if status == OK:
                lib().ikid_model_free(out_h)

        out.append(probe(corpus, f"ikid_model_load_bytes/{cut.stem}", body))

    def simple(name: str, call: Callable[[], int], allowed: set[int], needle: str = "") -> Api:
        return probe(corpus, name, lambda v, h: expect(v, name, call(), allowed, needle))

    good = os.fsencode(corpus.model("wrist-ik"))
    out += [
        simple("ikid_model_load/NULL-path", lambda: lib().ikid_model_load(None, C.byref(vp())), {NULL}),
        simple("ikid_model_load/NULL-out", lambda: lib().ikid_model_load(good, None), {NULL}),
        simple("ikid_model_load/empty-path", lambda: lib().ikid_model_load(b"", C.byref(vp())), {IO, ARG}),
        simple(
            "ikid_model_load/non-utf8-path",
            lambda: lib().ikid_model_load(b"/tmp/\xff\xfe.safetensors", C.byref(vp())),
            {IO, ARG},
        ),
        simple(
            "ikid_model_load_bytes/NULL-data",
            lambda: lib().ikid_model_load_bytes(None, 100, C.byref(vp())),
            {NULL},
        ),
        simple(
            "ikid_model_load_bytes/NULL-out", lambda: lib().ikid_model_load_bytes(b"abc", 3, None), {NULL}
        ),
        simple(
            "ikid_model_load_bytes/zero-length",
            lambda: lib().ikid_model_load_bytes(b"", 0, C.byref(vp())),
            {MODEL_FILE, ARG},
        ),
    ]
    return out


def model_probes(corpus: Corpus) -> list[Api]:
    out = []

    def info_null(v, h):
        expect(v, "ikid_model_get_info(NULL model)", lib().ikid_model_get_info(None, C.byref(Info())), {NULL})
        expect(v, "ikid_model_get_info(NULL out)", lib().ikid_model_get_info(h.model(), None), {NULL})

    out.append(probe(corpus, "ikid_model_get_info/NULL", info_null))

    def strings(v, h):
        m = h.model()
        checks = {
            "ikid_model_describe(NULL, 0)": lib().ikid_model_describe(None, 0),
            "ikid_model_name(NULL)": lib().ikid_model_name(None),
            "ikid_model_task(NULL)": lib().ikid_model_task(None),
            "ikid_model_feature_set(NULL)": lib().ikid_model_feature_set(None),
            "ikid_model_describe(model, 3)": lib().ikid_model_describe(m, 3),
            "ikid_model_describe(model, 2^32-1)": lib().ikid_model_describe(m, 2**32 - 1),
            "ikid_model_output_name(NULL, 0)": lib().ikid_model_output_name(None, 0),
            "ikid_model_output_name(model, 3)": lib().ikid_model_output_name(m, 3),
            "ikid_model_output_name(model, SIZE_MAX)": lib().ikid_model_output_name(m, SIZE_MAX),
            "ikid_model_frame_name(NULL, 0)": lib().ikid_model_frame_name(None, 0),
            "ikid_model_frame_name(model, 18)": lib().ikid_model_frame_name(m, 18),
            "ikid_model_frame_name(model, SIZE_MAX)": lib().ikid_model_frame_name(m, SIZE_MAX),
        }
        for what, got in checks.items():
            if got is not None:
                v.silent(f"{what} gave {got!r}, expected NULL")
        for status in (-1, 7, 999, 2**31 - 1):
            if not lib().ikid_status_message(status):
                v.silent(f"ikid_status_message({status}) gave NULL")
        if not lib().ikid_version():
            v.silent("ikid_version() gave NULL")

    out.append(probe(corpus, "strings/out-of-range-and-NULL", strings))

    def rows(v, h):
        m = h.model()
        info = Info()
        lib().ikid_model_get_info(m, C.byref(info))
        for n, want in (
            (0, 0),
            (info.window - 1, 0),
            (info.window, 1),
            (info.window + 99, 100),
        ):
            got = lib().ikid_model_predict_rows(m, n)
            if got != want:
                v.silent(f"ikid_predict_rows({n}) = {got}, expected {want}")
        if lib().ikid_model_predict_rows(None, 100) != 0:
            v.silent("ikid_predict_rows(NULL, 100) is not 0")

    out.append(probe(corpus, "ikid_predict_rows/edges", rows))

    def predict_case(
        name: str, n: int, frame_len: int, out_len: int | None, allowed: set[int], nulls=(), change=None
    ):
        def body(v, h):
            m = h.model()
            held = min(n, 200)
            frames = frames32(corpus, held)
            if change is not None:
                change(frames)
            frames = np.ascontiguousarray(np.resize(frames, held * 18 + 18), np.float32)
            buf = np.full(3 * held + 3 if out_len is None else max(out_len, 1), SENTINEL, np.float32)
            rows = sz(777)
            args = {
                "model": m,
                "frames": ptr(frames),
                "n": n,
                "frame_len": frame_len,
                "out": ptr(buf),
                "out_len": len(buf) if out_len is None else out_len,
                "rows": C.byref(rows),
            }
            for k in nulls:
                args[k] = None
            status = lib().ikid_model_predict(*args.values())
            if expect(v, f"ikid_predict({name})", status, allowed):
                unchanged(v, "ikid_predict", buf)
                if rows.value != 777:
                    v.silent("ikid_predict wrote *rows although it failed")

        return probe(corpus, f"ikid_predict/{name}", body)

    def nan_at(k):
        def change(f):
            f[k] = np.nan

        return change

    def shift_at(k):
        def change(f):
            f[k] += 1000.0

        return change

    out += [
        predict_case("NULL-model", 200, 18, None, {NULL}, nulls=("model",)),
        predict_case("NULL-frames", 200, 18, None, {NULL}, nulls=("frames",)),
        predict_case("NULL-out", 200, 18, None, {NULL}, nulls=("out",)),
        predict_case("NULL-rows", 200, 18, None, {NULL}, nulls=("rows",)),
        predict_case("frame_len-17", 200, 17, None, {ARG, INPUT}),
        predict_case("frame_len-19", 200, 19, None, {ARG, INPUT}),
        predict_case("frame_len-0", 200, 0, None, {ARG, INPUT}),
        predict_case("out-len-0", 200, 18, 0, {ARG}),
        predict_case("n_frames-times-frame_len-overflows", SIZE_MAX // 9, 18, None, {ARG, INPUT}),
        predict_case("nan-frame", 200, 18, None, {INPUT}, change=nan_at(100)),
        predict_case("frame-1km-off", 200, 18, None, {INPUT}, change=shift_at(100)),
    ]
    out.append(predict_short(corpus))
    return out


def predict_short(corpus: Corpus) -> Api:
    def body(v, h):
        m = h.model()
        frames = frames32(corpus, 200)
        rows_needed = lib().ikid_model_predict_rows(m, 200)
        buf = np.full(rows_needed * 3 - 1, SENTINEL, np.float32)
        rows = sz(777)
        status = lib().ikid_model_predict(m, ptr(frames), 200, 18, ptr(buf), len(buf), C.byref(rows))
        if expect(v, "ikid_predict(out one float short)", status, {ARG}):
            unchanged(v, "ikid_predict", buf)

    return probe(corpus, "ikid_predict/out-one-short", body)


def stream_probes(corpus: Corpus) -> list[Api]:
    out = []

    def push_case(name: str, frame_len: int, out_len: int, allowed: set[int], nulls=(), change=None, at=None):
        def body(v, h):
            s = h.stream()
            f = frames32(corpus, 1)[0]
            if change is not None:
                change(f)
            frame = np.ascontiguousarray(np.resize(f, max(frame_len, 1)), np.float32)
            buf = np.full(max(out_len, 1), SENTINEL, np.float32)
            ready = C.c_bool(True)
            args = {
                "stream": s,
                "frame": ptr(frame),
                "frame_len": frame_len,
                "out": ptr(buf),
                "out_len": out_len,
                "ready": C.byref(ready),
            }
            for k in nulls:
                args[k] = None
            values = list(args.values())
            if at is None:
                fn, what = lib().ikid_stream_push, f"ikid_stream_push({name})"
            else:
                fn, what = lib().ikid_stream_push_at, f"ikid_stream_push_at({name})"
                values.insert(1, at)
            status = fn(*values)
            if expect(v, what, status, allowed):
                unchanged(v, what, buf)
                if not ready.value:
                    v.silent(f"{what}: *ready written although the call failed")

        return probe(corpus, f"ikid_stream_push{'_at' if at is not None else ''}/{name}", body)

    def set_nan(f):
        f[:] = np.nan

    def set_inf(f):
        f[4] = np.inf

    for at in (None, 0.0):
        out += [
            push_case("NULL-stream", 18, 3, {NULL}, nulls=("stream",), at=at),
            push_case("NULL-frame", 18, 3, {NULL}, nulls=("frame",), at=at),
            push_case("NULL-out", 18, 3, {NULL}, nulls=("out",), at=at),
            push_case("NULL-ready", 18, 3, {NULL}, nulls=("ready",), at=at),
            push_case("frame_len-17", 17, 3, {ARG, INPUT}, at=at),
            push_case("frame_len-19", 19, 3, {ARG, INPUT}, at=at),
            push_case("frame_len-0", 0, 3, {ARG, INPUT}, at=at),
            push_case("out_len-2", 18, 2, {ARG}, at=at),
            push_case("out_len-0", 18, 0, {ARG}, at=at),
            push_case("all-nan-frame", 18, 3, {INPUT}, change=set_nan, at=at),
            push_case("inf-value", 18, 3, {INPUT}, change=set_inf, at=at),
        ]
    out += [
        push_case("time-nan", 18, 3, {ARG, INPUT}, at=math.nan),
        push_case("time-inf", 18, 3, {ARG, INPUT}, at=math.inf),
        push_case("time-minus-inf", 18, 3, {ARG, INPUT}, at=-math.inf),
    ]

    def backwards(v, h):
        s = h.stream()
        fr = frames32(corpus, 2)
        buf = np.full(3, SENTINEL, np.float32)
        ready = C.c_bool(False)
        assert lib().ikid_stream_push_at(s, 1.0, ptr(fr[0]), 18, ptr(buf), 3, C.byref(ready)) == OK
        for t, what in ((0.5, "earlier"), (1.0, "equal")):
            status = lib().ikid_stream_push_at(s, t, ptr(fr[1]), 18, ptr(buf), 3, C.byref(ready))
            expect(v, f"ikid_stream_push_at(time {what})", status, {INPUT, ARG})

    out.append(probe(corpus, "ikid_stream_push_at/time-not-increasing", backwards))

    def lab_up(v, h):
        # A lab's up that is no direction is refused by name; NULLs are NULL errors.
        s = h.stream(h.model("wrist-chain"))
        for name, up in (
            ("zero", (0.0, 0.0, 0.0)),
            ("NaN", (math.nan, 1.0, 0.0)),
            ("inf", (0.0, math.inf, 0.0)),
        ):
            vec = np.ascontiguousarray(up, np.float64)
            expect(
                v,
                f"ikid_stream_set_lab_up({name})",
                lib().ikid_stream_set_lab_up(s, ptr(vec, f64p)),
                {ARG},
                "up",
            )
        vec = np.ascontiguousarray((0.0, 0.0, 1.0), np.float64)
        expect(
            v,
            "ikid_stream_set_lab_up(NULL stream)",
            lib().ikid_stream_set_lab_up(None, ptr(vec, f64p)),
            {NULL},
        )
        expect(v, "ikid_stream_set_lab_up(NULL up)", lib().ikid_stream_set_lab_up(s, None), {NULL})

    out.append(probe(corpus, "ikid_stream_set_lab_up/not-a-direction", lab_up))

    def policy(name: str, value: int, allowed: set[int], null_stream: bool = False):
        def body(v, h):
            s = None if null_stream else h.stream()
            expect(
                v,
                f"ikid_stream_set_missing_markers({name})",
                lib().ikid_stream_set_missing_markers(s, value),
                allowed,
            )

        return probe(corpus, f"ikid_stream_set_missing_markers/{name}", body)

    out += [
        policy("NULL-stream", 1, {NULL}, True),
        policy("refuse", 0, {OK}),
        policy("fill", 1, {OK}),
        policy("2", 2, {ARG}),
        policy("u32-max", 2**32 - 1, {ARG}),
    ]

    def calibration(name: str, forearm, hand, allowed: set[int], null_stream: bool = False):
        def body(v, h):
            s = None if null_stream else h.stream()
            a = None if forearm is None else np.ascontiguousarray(forearm, np.float64)
            b = None if hand is None else np.ascontiguousarray(hand, np.float64)
            status = lib().ikid_stream_set_calibration(s, ptr(a, f64p), ptr(b, f64p))
            expect(v, f"ikid_stream_set_calibration({name})", status, allowed)

        return probe(corpus, f"ikid_stream_set_calibration/{name}", body)

    eye = np.eye(3)
    out += [
        calibration("NULL-stream", eye, eye, {NULL}, True),
        calibration("forearm-NULL-hand-not", None, eye, {NULL, ARG}),
        calibration("hand-NULL-forearm-not", eye, None, {NULL, ARG}),
        calibration("not-a-rotation", eye * 2, eye, {ARG}),
        calibration("reflection", np.diag([1.0, 1.0, -1.0]), eye, {ARG}),
        calibration("nan", np.full((3, 3), np.nan), eye, {ARG}),
        calibration("inf", eye + np.inf, eye, {ARG}),
        calibration("zeros", np.zeros((3, 3)), eye, {ARG}),
    ]

    def filled_null(v, h):
        expect(
            v,
            "ikid_stream_filled_markers(NULL stream)",
            lib().ikid_stream_filled_markers(None, C.byref(C.c_uint32())),
            {NULL},
        )
        expect(
            v,
            "ikid_stream_filled_markers(NULL mask)",
            lib().ikid_stream_filled_markers(h.stream(), None),
            {NULL},
        )
        expect(v, "ikid_stream_reset(NULL)", lib().ikid_stream_reset(None), {NULL})
        lib().ikid_stream_free(None)
        lib().ikid_model_free(None)
        lib().ikid_tracker_free(None)

    out.append(probe(corpus, "stream-misc/NULLs-and-frees", filled_null))

    def many_case(
        name: str, n: int, frame_len: int, out_len: int | None, allowed: set[int], nulls=(), change=None
    ):
        def body(v, h):
            s = h.stream()
            held = min(n, 200)
            frames = frames32(corpus, held)
            if change is not None:
                change(frames)
            frames = np.ascontiguousarray(np.resize(frames, held * 18 + 18), np.float32)
            buf = np.full(3 * held + 3 if out_len is None else max(out_len, 1), SENTINEL, np.float32)
            rows = sz(777)
            args = [
                s,
                ptr(frames),
                n,
                frame_len,
                ptr(buf),
                len(buf) if out_len is None else out_len,
                C.byref(rows),
            ]
            for k in nulls:
                args[k] = None
            status = lib().ikid_stream_push_many(*args)
            if expect(v, f"ikid_stream_push_many({name})", status, allowed) and rows.value != 777:
                v.silent("ikid_stream_push_many wrote *rows although it failed")
            if status == INPUT and "frame" not in last_error():
                v.silent(f"ikid_stream_push_many: the error names no frame: {last_error()}")

        return probe(corpus, f"ikid_stream_push_many/{name}", body)

    def nan_at(f):
        f[150] = np.nan

    def inf_at(f):
        f[150, 3] = np.inf

    out += [
        many_case("NULL-stream", 200, 18, None, {NULL}, nulls=(0,)),
        many_case("NULL-frames", 200, 18, None, {NULL}, nulls=(1,)),
        many_case("NULL-out", 200, 18, None, {NULL}, nulls=(4,)),
        many_case("NULL-rows", 200, 18, None, {NULL}, nulls=(6,)),
        many_case("frame_len-17", 200, 17, None, {ARG, INPUT}),
        many_case("frame_len-0", 200, 0, None, {ARG, INPUT}),
        many_case("out-too-short", 200, 18, 10, {ARG}),
        many_case("out_len-0", 200, 18, 0, {ARG}),
        many_case("n_frames-times-frame_len-overflows", SIZE_MAX // 9, 18, None, {ARG, INPUT}),
        many_case("nan-frame-150", 200, 18, None, {INPUT}, change=nan_at),
        many_case("inf-value-frame-150", 200, 18, None, {INPUT}, change=inf_at),
    ]
    return out


def tracker_probes(corpus: Corpus) -> list[Api]:
    out = []
    # The numeric fields (a bool, e.g. relative_hand, has no bad value to give).
    fields = [f[0] for f in Settings._fields_ if f[1] is C.c_double]
    for field in fields:
        for value in (0.0, -1.0, math.nan, math.inf, 1e308):

            def body(v, h, field=field, value=value):
                settings = lib().ikid_tracker_settings_default()
                settings.rate_hz = 1000.0
                setattr(settings, field, value)
                t = vp(4321)
                status = lib().ikid_tracker_new(C.byref(settings), None, C.byref(t))
                if status == OK:
                    h.trackers.append(t)
                if expect(v, f"ikid_tracker_new({field}={value})", status, {ARG}, field) and t.value != 4321:
                    v.silent("ikid_tracker_new wrote *out although it failed")

            out.append(probe(corpus, f"ikid_tracker_new/{field}={value}", body))

    def new_nulls(v, h):
        settings = lib().ikid_tracker_settings_default()
        settings.rate_hz = 1000.0
        expect(
            v, "ikid_tracker_new(NULL settings)", lib().ikid_tracker_new(None, None, C.byref(vp())), {NULL}
        )
        expect(v, "ikid_tracker_new(NULL out)", lib().ikid_tracker_new(C.byref(settings), None, None), {NULL})
        t = vp()
        status = lib().ikid_tracker_new(C.byref(settings), h.model("wrist-ik"), C.byref(t))
        if status == OK:
            h.trackers.append(t)
        expect(v, "ikid_tracker_new(refiner = wrist-ik, not a refiner)", status, {ARG})

    out.append(probe(corpus, "ikid_tracker_new/NULLs-and-wrong-refiner", new_nulls))

    def push_case(name: str, frame_len: int, out_len: int, allowed: set[int], nulls=(), change=None):
        def body(v, h):
            t = h.tracker()
            f = frames64(corpus, 1)[0].copy()
            if change is not None:
                change(f)
            frame = np.ascontiguousarray(np.resize(f, max(frame_len, 1)), np.float64)
            buf = np.full(max(out_len, 1), SENTINEL, np.float64)
            flags = Flags(missing=999)
            args = [t, ptr(frame, f64p), frame_len, ptr(buf, f64p), out_len, C.byref(flags)]
            for k in nulls:
                args[k] = None
            status = lib().ikid_tracker_push(*args)
            if expect(v, f"ikid_tracker_push({name})", status, allowed):
                unchanged(v, "ikid_tracker_push", buf)
                if flags.missing != 999:
                    v.silent("ikid_tracker_push wrote *flags although it failed")

        return probe(corpus, f"ikid_tracker_push/{name}", body)

    def inf(f):
        f[7] = np.inf

    def huge(f):
        f[7] = 1e300

    out += [
        push_case("NULL-tracker", 18, 12, {NULL}, nulls=(0,)),
        push_case("NULL-frame", 18, 12, {NULL}, nulls=(1,)),
        push_case("NULL-out", 18, 12, {NULL}, nulls=(3,)),
        push_case("NULL-flags", 18, 12, {NULL}, nulls=(5,)),
        push_case("frame_len-17", 17, 12, {INPUT, ARG}),
        push_case("frame_len-19", 19, 12, {INPUT, ARG}),
        push_case("frame_len-0", 0, 12, {INPUT, ARG}),
        push_case("out_len-11", 18, 11, {ARG}),
        push_case("out_len-0", 18, 0, {ARG}),
        push_case("inf-value", 18, 12, {INPUT}, change=inf),
        push_case("value-1e300", 18, 12, {INPUT, OK}, change=huge),
    ]

    def stamped(v, h):
        # Stamps that cannot be a frame at the tracker's rate are refused, write nothing and
        # restart nothing.
        t = h.tracker()
        fr = frames64(corpus, 2)
        buf = np.full(12, SENTINEL, np.float64)
        flags = Flags(missing=999)
        assert (
            lib().ikid_tracker_push_at(t, 1.0, ptr(fr[0], f64p), 18, ptr(buf, f64p), 12, C.byref(flags)) == OK
        )
        buf[:] = SENTINEL
        flags.missing = 999
        for when, what in ((1.0002, "too soon"), (math.nan, "NaN"), (math.inf, "inf"), (-math.inf, "-inf")):
            status = lib().ikid_tracker_push_at(
                t, when, ptr(fr[1], f64p), 18, ptr(buf, f64p), 12, C.byref(flags)
            )
            if expect(v, f"ikid_tracker_push_at(time {what})", status, {ARG}, "time"):
                unchanged(v, "ikid_tracker_push_at", buf)
                if flags.missing != 999:
                    v.silent("ikid_tracker_push_at wrote *flags although it failed")
        restarts = sz(7)
        expect(v, "ikid_tracker_gap_restarts(NULL)", lib().ikid_tracker_gap_restarts(t, None), {NULL})
        if lib().ikid_tracker_gap_restarts(t, C.byref(restarts)) != OK or restarts.value != 0:
            v.silent(f"refused stamps restarted the filter ({restarts.value} restarts)")

    out.append(probe(corpus, "ikid_tracker_push_at/bad-stamps", stamped))

    def run_case(
        name: str,
        n_values: int,
        out_len: int | None,
        flags_len: int | None,
        allowed: set[int],
        nulls=(),
        change=None,
    ):
        def body(v, h):
            t = h.tracker()
            n = min(max(n_values // 18, 1), 100) + 1
            frames = frames64(corpus, n).ravel().copy()
            if change is not None:
                change(frames)
            buf = np.full(12 * n if out_len is None else max(out_len, 1), SENTINEL, np.float64)
            flags = (Flags * max(n if flags_len is None else flags_len, 1))()
            start = sz(777)
            args = [
                t,
                ptr(frames, f64p),
                n_values,
                ptr(buf, f64p),
                len(buf) if out_len is None else out_len,
                flags,
                len(flags) if flags_len is None else flags_len,
                C.byref(start),
            ]
            for k in nulls:
                args[k] = None
            status = lib().ikid_tracker_run(*args)
            if expect(v, f"ikid_tracker_run({name})", status, allowed) and start.value != 777:
                v.silent("ikid_tracker_run wrote *start although it failed")
            if status == INPUT and not any(w in last_error() for w in ("frame", "index")):
                v.silent(f"ikid_tracker_run: the error names no frame: {last_error()}")

        return probe(corpus, f"ikid_tracker_run/{name}", body)

    def inf_at(f):
        f[18 * 50 + 4] = np.inf

    out += [
        run_case("NULL-tracker", 1800, None, None, {NULL}, nulls=(0,)),
        run_case("NULL-frames", 1800, None, None, {NULL}, nulls=(1,)),
        run_case("NULL-out", 1800, None, None, {NULL}, nulls=(3,)),
        run_case("NULL-flags", 1800, None, None, {NULL}, nulls=(5,)),
        run_case("NULL-start", 1800, None, None, {NULL}, nulls=(7,)),
        run_case("n_values-not-whole-frames", 1801, None, None, {ARG}),
        run_case("out-too-short", 1800, 12 * 100 - 1, None, {ARG}),
        run_case("flags-too-short", 1800, None, 99, {ARG}),
        run_case("n_values-huge", SIZE_MAX - SIZE_MAX % 18, None, None, {ARG}),
        run_case("inf-value-frame-50", 1800, None, None, {INPUT}, change=inf_at),
    ]

    def noise(v, h):
        t = h.tracker()
        buf = np.full(9, SENTINEL, np.float64)
        expect(
            v,
            "ikid_tracker_marker_noise(NULL tracker)",
            lib().ikid_tracker_marker_noise(None, ptr(buf, f64p), 9),
            {NULL},
        )
        expect(v, "ikid_tracker_marker_noise(NULL out)", lib().ikid_tracker_marker_noise(t, None, 9), {NULL})
        if expect(
            v,
            "ikid_tracker_marker_noise(out_len 8)",
            lib().ikid_tracker_marker_noise(t, ptr(buf, f64p), 8),
            {ARG},
        ):
            unchanged(v, "ikid_tracker_marker_noise", buf)
        expect(v, "ikid_tracker_reset(NULL)", lib().ikid_tracker_reset(None), {NULL})

    out.append(probe(corpus, "ikid_tracker_marker_noise/NULLs-and-short", noise))

    def diverge(v, h):
        """The issue's case 1 through C: a frame 1 km off, then 1 s of clean frames."""
        t = h.tracker(h.model("wrist-track"))
        frames = frames64(corpus, 3000).copy()
        frames[1500] += 1000.0
        n = len(frames)
        buf = np.zeros(12 * n)
        flags = (Flags * n)()
        start = sz()
        status = lib().ikid_tracker_run(
            t, ptr(frames.ravel(), f64p), 18 * n, ptr(buf, f64p), 12 * n, flags, n, C.byref(start)
        )
        if status != OK:
            expect(v, "ikid_tracker_run(frame 1500 1 km off)", status, {INPUT}, "1500")
            return
        clean_t = h.tracker(h.model("wrist-track"))
        ok = frames64(corpus, 3000)
        ref = np.zeros(12 * n)
        lib().ikid_tracker_run(
            clean_t, ptr(ok.ravel(), f64p), 18 * n, ptr(ref, f64p), 12 * n, (Flags * n)(), n, C.byref(sz())
        )
        q, q_ref = buf.reshape(n, 12)[:, :3], ref.reshape(n, 12)[:, :3]
        late = np.degrees(np.abs(q[2500:] - q_ref[2500:])).max()
        if not late <= 2.0:
            v.silent(f"ikid_tracker_run: 1 s after a frame 1 km off, still {late:.3g}° from the clean run")
        if flags[1500].missing == 0 and getattr(flags[1500], "status", 0) == 0:
            v.silent("ikid_tracker_run: the frame 1 km off is not flagged")

    out.append(probe(corpus, "ikid_tracker_run/frame-1km-off-recovers", diverge))
    return out


def probes(corpus: Corpus) -> list[Api]:
    return load_probes(corpus) + model_probes(corpus) + stream_probes(corpus) + tracker_probes(corpus)
