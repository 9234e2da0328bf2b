"""Reader probes: every mutated file of the corpus through its reader, and what a reader
gives through to the output a lab would get.

A probe passes when the reader (and what follows it) raises ikid's error naming the file
(and the line or frame, for a mutation of one row), or reads something whose outputs are
plausible: for a marker file, ``wrist-ik`` on its frames agrees with the clean trial within
5° on every frame it does not flag (refused or filled); for a model file, the same
predictions as the file it was copied from (a changed weight must be refused: checksums).
Non-regular files (a directory, a FIFO, /dev/zero, a 4 GB sparse file) must be refused within
a second."""

from __future__ import annotations

import re
import time
from functools import cache
from pathlib import Path

import numpy as np

from faults.corpus import MARKER_KINDS, Corpus
from faults.framework import Api, Verdict, call, judge_error

#: An angle further than this from the clean trial's, on a frame not flagged, is silent.
ANGLE_TOLERANCE_DEG = 5.0
#: Mutations of one row (or a block of rows): the error must say where.
POSITIONAL = ("time-backwards", "time-duplicated", "value-literal", "value-not-a-number", "value-huge")


def names_position(message: str, path: Path) -> bool:
    """Whether an error message says where: ``FILE:LINE``, or a frame, row or line number."""
    return bool(
        re.search(re.escape(str(path)) + r":\d+", message)
        or re.search(r"\b(frame|row|line)s?\s*#?\d+", message, re.IGNORECASE)
    )


def reader(kind: str):
    import ikid

    return {
        "c3d": ikid.io.read_c3d,
        "trc": ikid.io.read_trc,
        "csv": ikid.io.read_csv_markers,
        "mot": ikid.io.read_mot,
        "sto": ikid.io.read_sto,
        "toml": ikid.io.MarkerMap.load,
        "json": ikid.load_calibration,
        "safetensors": ikid.load,
    }[kind]


@cache
def wrist_ik():
    import ikid

    return ikid.load("wrist-ik")


@cache
def clean_run(corpus_root: str):
    """wrist-ik over the clean trial's frames: {time (µs): angles}."""
    import ikid
    from ikid.pipeline import run_model

    data = ikid.io.read_trc(Path(corpus_root) / "base" / "trial.trc")
    run = run_model(wrist_ik(), data.frames(), data.time, rate_hz=data.rate_hz)
    return {int(round(t * 1e6)): q for t, q in zip(run.time, run.values, strict=True)}


def compare_angles(v: Verdict, clean: dict, times, values, flagged, what: str) -> None:
    """Silent if an unflagged output is more than the tolerance off the clean one."""
    worst, count, at = 0.0, 0, None
    for t, q, flag in zip(times, values, flagged, strict=True):
        ref = clean.get(int(round(t * 1e6)))
        if ref is None or flag:
            continue
        d = float(np.degrees(np.max(np.abs(np.asarray(q) - ref))))
        if not np.isfinite(d) or d > ANGLE_TOLERANCE_DEG:
            count += 1
            if not np.isfinite(d) or d > worst:
                worst, at = d, t
    if count:
        v.silent(
            f"{what}: {count} unflagged outputs more than {ANGLE_TOLERANCE_DEG:g}° from the clean trial's "
            f"(worst {worst:.3g}° at t={at:.3f} s)"
        )


def through_pipeline(v: Verdict, corpus: Corpus, path: Path, data) -> None:
    """A marker file that was read: frames -> wrist-ik, as `ikid ik` does."""
    from ikid.pipeline import run_model

    frames, e = call(data.frames)
    if e is not None:
        judge_error(v, e, [str(path)], "MarkerData.frames: ")
        return
    run, e = call(run_model, wrist_ik(), frames, data.time, rate_hz=data.rate_hz, source=str(path))
    if e is not None:
        judge_error(v, e, [str(path)], "run_model: ")
        return
    # Flagged: any status bit (a filled marker, inputs outside the training range, ...).
    compare_angles(
        v, clean_run(str(corpus.root)), run.time, run.values, run.status != 0, "wrist-ik on what was read"
    )


@cache
def clean_model_outputs(corpus_root: str) -> tuple[dict, np.ndarray]:
    import ikid

    frames = ikid.io.read_trc(Path(corpus_root) / "base" / "trial.trc").frames()[:300]
    return ikid.load("wrist-ik").card, ikid.load("wrist-ik").predict(frames)


def check_model(v: Verdict, corpus: Corpus, path: Path, model) -> None:
    import ikid

    card, expected = clean_model_outputs(str(corpus.root))
    frames = ikid.io.read_trc(corpus.path("trc")).frames()[:300]
    got, e = call(model.predict, frames)
    if e is not None:
        judge_error(v, e, [], "predict on the loaded model: ")
        return
    if got.shape != expected.shape or not np.array_equal(got, expected, equal_nan=True):
        diff = float(np.nanmax(np.abs(got - expected))) if got.shape == expected.shape else float("nan")
        v.silent(f"a corrupted model file loaded without complaint; outputs differ by up to {diff:.3g}")
    for key in ("task", "feature_set", "window", "frame_rate_hz", "outputs"):
        if model.card.get(key) != card.get(key):
            v.silent(f"loaded with card field {key} = {model.card.get(key)!r} (was {card.get(key)!r})")


def probe(corpus: Corpus, kind: str, path: Path) -> Api:
    mutation = path.name[: -len(path.suffix)] if path.suffix else path.name

    def fn(v: Verdict) -> None:
        t0 = time.monotonic()
        value, e = call(reader(kind), path)
        seconds = time.monotonic() - t0
        if mutation.startswith("special-"):
            if e is None:
                v.silent(f"{mutation}: read without error")
            else:
                judge_error(v, e, [str(path)])
            if seconds > 1.0:
                v.silent(f"{mutation}: took {seconds:.1f} s to refuse (unbounded read?)")
            return
        if e is not None:
            if judge_error(v, e, [str(path)]) and mutation.startswith(POSITIONAL):
                if kind != "c3d" and not names_position(str(e), path):
                    v.silent(f"error names no line or frame: {e}")
            return
        if kind in MARKER_KINDS:
            through_pipeline(v, corpus, path, value)
        elif kind in ("mot", "sto"):
            t, x = value
            if x.shape != (len(t), 3) or not np.isfinite(x).all():
                v.silent(f"read {x.shape} values, non-finite or not 3 columns")
        elif kind == "safetensors":
            check_model(v, corpus, path, value)

    return Api(f"read/{kind}/{mutation}", fn, timeout=60.0 if kind == "c3d" else 30.0)


def probes(corpus: Corpus) -> list[Api]:
    from faults.corpus import KINDS

    return [probe(corpus, kind, path) for kind in KINDS for path in corpus.mutations(kind)]
