"""Calibration to a subject's marker placement, measured once per session and saved as JSON.

    cal = ikid.calibrate(static_frames, {"ra_wr_e_f": flexion_frames, "ra_wr_s_p": pronation_frames})
    ikid.save_calibration(cal, "subject01.json")
    stream = model.stream(calibration=ikid.load_calibration("subject01.json"))

The measurement itself (static neutral trial + single-coordinate movements, functional axes,
Procrustes) is the core's: see :class:`ikid.Calibration` and ``crates/ikid/src/calibration.rs``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ikid._native import Calibration, InputError, fill_gaps
from ikid.io._atomic import write_text_atomic
from ikid.io.markers import FileFormatError, read_text

FORMAT = "ikid-calibration"
FORMAT_VERSION = 1


def calibrate(static_frames, movements: dict, *, fill: bool = True) -> Calibration:
    """Measure a :class:`Calibration` from a neutral static trial and single-coordinate
    movements ``{coordinate name: frames}`` (``(n, 18)`` metres each). With ``fill``, a
    single missing marker per segment is filled first (``ikid.fill_gaps``)."""

    def prepared(frames):
        frames = np.asarray(frames, np.float64)
        if fill and frames.ndim == 2 and not np.isfinite(frames).all():
            frames = fill_gaps(frames)[0]
        return frames

    return Calibration.from_trials(prepared(static_frames), {k: prepared(v) for k, v in movements.items()})


def save_calibration(calibration: Calibration, path: str | os.PathLike[str], **provenance) -> Path:
    """Write ``calibration`` (and its report, and any ``provenance`` given) as JSON, atomically."""
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "forearm": np.asarray(calibration.forearm).tolist(),
        "hand": np.asarray(calibration.hand).tolist(),
        "report": calibration.report,
        "provenance": provenance,
    }
    return write_text_atomic(path, json.dumps(doc, indent=1) + "\n")


def load_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read a calibration written by :func:`save_calibration`; the matrices are checked."""
    path = Path(path)
    try:
        doc = json.loads(read_text(path, "a calibration file is JSON text"))
    except (json.JSONDecodeError, FileFormatError) as e:
        raise InputError(f"{path}: not a calibration file ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f'{path}: not an ikid calibration (expected "format": "{FORMAT}")')
    if doc.get("format_version") != FORMAT_VERSION:
        raise InputError(
            f"{path}: calibration format_version {doc.get('format_version')!r}; "
            f"this ikid reads {FORMAT_VERSION}"
        )
    try:
        return Calibration.from_matrices(doc["forearm"], doc["hand"])
    except KeyError as e:
        raise InputError(f"{path}: no {e.args[0]!r} matrix") from None
    except InputError as e:
        raise InputError(f"{path}: {e}") from None
