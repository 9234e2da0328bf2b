"""ikid: real-time inverse kinematics and dynamics of the human wrist from mocap markers.

A small neural network over a short window of marker frames gives the wrist's three
angles (or torques), frame by frame, in microseconds::

    import ikid
    model = ikid.load("path/to/wrist-ik.safetensors")
    angles = model.predict(frames)          # (n, 18) markers -> (n - 4, 3) radians
    stream = model.stream()
    for frame in frames:
        out = stream.push(frame)            # None until the window is full

Everything runs in the Rust core (``ikid._native``); this package adds only name
resolution and re-exports. ``import ikid`` never imports torch.
"""

from __future__ import annotations

import os
from pathlib import Path

from ikid._native import (
    COORDINATES,
    DEFAULT_JERK_NOISE,
    FEATURE_SETS,
    MARKERS,
    REFINER_GATE_NOISE,
    REFINER_OUTPUTS,
    SIMULATOR,
    ArgumentError,
    Calibration,
    IkidError,
    InputError,
    Model,
    ModelFileError,
    NotFoundError,
    ReadError,
    Stream,
    Tracker,
    __version__,
    body_model,
    compute_features,
    feature_set_info,
    fill_gaps,
    forward_markers,
    reference_id,
    reference_ik,
)

__all__ = [
    "Calibration",
    "calibrate",
    "load_calibration",
    "save_calibration",
    "COORDINATES",
    "DEFAULT_JERK_NOISE",
    "FEATURE_SETS",
    "MARKERS",
    "REFINER_GATE_NOISE",
    "REFINER_OUTPUTS",
    "SIMULATOR",
    "ArgumentError",
    "IkidError",
    "InputError",
    "Model",
    "ModelFileError",
    "NotFoundError",
    "ReadError",
    "Stream",
    "Tracker",
    "Trial",
    "__version__",
    "available_models",
    "body_model",
    "compute_features",
    "coordinate_names",
    "feature_set_info",
    "fill_gaps",
    "forward_markers",
    "load",
    "marker_names",
    "reference_id",
    "reference_ik",
    "simulate",
]

from ikid.calibration import calibrate, load_calibration, save_calibration  # noqa: E402
from ikid.sim import Trial, simulate  # noqa: E402  (needs _native first)

_SHIPPED = Path(__file__).with_name("models")


def available_models() -> list[str]:
    """Names of the models shipped inside the package (usable with :func:`load`)."""
    return sorted(p.stem for p in _SHIPPED.glob("*.safetensors"))


def load(name_or_path: str | os.PathLike[str]) -> Model:
    """Load a model by shipped name (see :func:`available_models`) or from a file path.

    Raises ``FileNotFoundError`` (listing the shipped names) if neither exists, and
    :class:`ModelFileError` if the file is not a valid ikid model.
    """
    path = Path(name_or_path)
    if path.exists():
        return Model.load(path)
    shipped = _SHIPPED / f"{name_or_path}.safetensors"
    if isinstance(name_or_path, str) and os.sep not in name_or_path and shipped.exists():
        return Model.load(shipped)
    names = ", ".join(available_models()) or "none in this build"
    raise FileNotFoundError(
        f"no model file {str(name_or_path)!r} and no shipped model of that name (shipped: {names})"
    )


def coordinate_names() -> list[str]:
    """The wrist coordinates in canonical order ``(s_p, e_f, ad_ab)``."""
    return [c[0] for c in COORDINATES]


def marker_names() -> list[str]:
    """The six marker labels in frame order (three forearm, then three hand)."""
    return [m[0] for m in MARKERS]
