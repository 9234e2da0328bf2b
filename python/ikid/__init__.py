"""ikid: real-time inverse kinematics and dynamics of the human wrist from mocap markers.

A small neural network over a short window of marker frames gives the wrist's three
angles (or torques), frame by frame, in microseconds::

    import ikid
    model = ikid.load("path/to/wrist-ik.safetensors")
    angles = model.predict(frames)          # (n, 18) markers -> (n - window + 1, 3) radians
    stream = model.stream()
    for frame in frames:
        out = stream.push(frame)            # None until the window is full

Everything runs in the Rust core (``ikid._native``); this package adds only name
resolution and re-exports. ``import ikid`` never imports torch.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

from ikid._native import (
    COORDINATES,
    DEFAULT_JERK_NOISE,
    FEATURE_SETS,
    FRAME_STATUS,
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
    TrackerEstimate,
    __version__,
    body_model,
    check_default_placement,
    check_marker_units,
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
    "FRAME_STATUS",
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
    "TrackerEstimate",
    "Trial",
    "WriteError",
    "__version__",
    "available_models",
    "body_model",
    "compute_features",
    "coordinate_names",
    "feature_set_info",
    "check_default_placement",
    "check_marker_units",
    "fill_gaps",
    "forward_markers",
    "is_model_name",
    "load",
    "marker_names",
    "reference_id",
    "reference_ik",
    "simulate",
]

from ikid.calibration import calibrate, load_calibration, save_calibration  # noqa: E402
from ikid.io._atomic import WriteError  # noqa: E402
from ikid.sim import Trial, simulate  # noqa: E402  (needs _native first)

_SHIPPED = Path(__file__).with_name("models")


def available_models() -> list[str]:
    """Names of the models shipped inside the package (usable with :func:`load`)."""
    return sorted(p.stem for p in _SHIPPED.glob("*.safetensors"))


#: How each surface opts in to a model file without a checksum (appended to the loader's
#: ``missing_checksum`` error by :func:`load`; the CLI swaps in its own flag).
UNCHECKED_OPT_IN = "or load it unchecked: ikid.load(path, allow_unchecked=True)"


def load(
    name_or_path: str | os.PathLike[str], *, rate_hz: float | None = None, allow_unchecked: bool = False
) -> Model:
    """Load a shipped model by name (see :func:`available_models`) or a model file.

    With ``rate_hz`` (the rate of the frames a stream will be fed), a shipped model's name
    stands for its family (``wrist-ik`` for ``wrist-ik``, ``wrist-ik-100hz``, ...): the member
    trained at that rate is loaded; a model with no member at that rate, or a file trained at
    another one, is an :class:`InputError` listing the rates there are (a live stream is never
    resampled: that would add latency). ``ikid.load("wrist-ik", rate_hz=100).stream()``.

    The rule, the same for every command that takes a model: a string with no path separator
    and no ``.safetensors`` suffix is a shipped model's name — ``"wrist-ik"`` is always the
    shipped model, even if a file or folder of that name is in the working directory; anything
    else (a string with a separator or the suffix, or a ``pathlib.Path``) is a file path:
    ``"./wrist-ik"``, ``"lab-ik.safetensors"``.

    A model file carries a checksum of its weights, verified here. A file written before
    checksums existed has none, so a corrupted copy cannot be told from a good one: it is
    refused (:class:`ModelFileError`, ``code == "missing_checksum"``) unless
    ``allow_unchecked=True``, which loads it with a warning (``python -m
    ikid_training.export --restamp FILE`` adds the checksum for good).

    Raises :class:`NotFoundError` (a ``FileNotFoundError``, listing the shipped names) for a
    name that is not shipped or a path that does not exist, and :class:`ModelFileError` if the
    file is not a valid ikid model.
    """
    if rate_hz is not None:
        from ikid.pipeline import model_at_rate

        return model_at_rate(name_or_path, rate_hz, allow_unchecked=allow_unchecked)
    if is_model_name(name_or_path):
        name = str(name_or_path)
        shipped = _SHIPPED / f"{name}.safetensors"
        if shipped.is_file():
            return Model.load(shipped)
        names = ", ".join(available_models()) or "none in this build"
        hint = (
            f"; a file of that name is here: give it as a path, ./{name}"
            if os.path.lexists(name)
            else "; a model file is given by a path (with a folder or the .safetensors suffix)"
        )
        raise NotFoundError(
            f"no model file {name!r} and no shipped model of that name (shipped: {names}){hint}"
        )
    path = Path(name_or_path)
    if not os.path.lexists(path):
        raise NotFoundError(f"no model file {str(name_or_path)!r}: {path} does not exist")
    try:
        model = Model.load(path, allow_unchecked=allow_unchecked)
    except ModelFileError as e:
        if e.code == "missing_checksum":
            e.args = (f"{e}, {UNCHECKED_OPT_IN}",)  # the same error (kind, code), its opt-in named
        raise
    if not model.has_checksum:
        warnings.warn(
            f"{path}: loaded without a checksum (allow_unchecked): written before model files carried "
            "one, so a corrupted file cannot be told from a good one; add one with "
            "python -m ikid_training.export --restamp FILE (from ikid-training)",
            stacklevel=2,
        )
    return model


def is_model_name(name_or_path: str | os.PathLike[str]) -> bool:
    """True if :func:`load` reads ``name_or_path`` as a shipped model's name, not a path: a
    string with no path separator and no ``.safetensors`` suffix."""
    if not isinstance(name_or_path, str):
        return False
    separators = {"/", os.sep, *([os.altsep] if os.altsep else [])}
    return not any(s in name_or_path for s in separators) and not name_or_path.endswith(".safetensors")


def coordinate_names() -> list[str]:
    """The wrist coordinates in canonical order ``(s_p, e_f, ad_ab)``."""
    return [c[0] for c in COORDINATES]


def marker_names() -> list[str]:
    """The six marker labels in frame order (three forearm, then three hand)."""
    return [m[0] for m in MARKERS]
