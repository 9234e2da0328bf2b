"""The command line's checked option types and option groups, shared by every command (imports no
command)."""

from __future__ import annotations

import argparse
import math

from ikid import _native
from ikid.sim import Trial


def _number(
    cast: type = float,
    *,
    gt: float | None = None,
    ge: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    name: str = "",
    unit: str = "",
):
    """An argparse ``type`` for a number: finite, within the bounds given; a bad value is
    refused by argparse as ``argument --OPTION: VALUE: ...`` (exit 2), never a traceback later.
    ``name`` is what the value is called in the API, for the message."""
    what = f"{name} " if name else ""
    bounds = [
        (gt, lambda v, b: v > b, "greater than"),
        (ge, lambda v, b: v >= b, "at least"),
        (le, lambda v, b: v <= b, "at most"),
        (lt, lambda v, b: v < b, "less than"),
    ]

    def parse(text: str):
        try:
            value = cast(text)
        except ValueError:
            kind = "an integer" if cast is int else "a number"
            raise argparse.ArgumentTypeError(f"{text!r}: {what}must be {kind}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r}: {what}must be a finite number")
        for bound, ok, words in bounds:
            if bound is not None and not ok(value, bound):
                raise argparse.ArgumentTypeError(f"{text}: {what}must be {words} {bound:g}{unit}")
        return value

    parse.__name__ = "integer" if cast is int else "number"
    return parse


POSITIVE = _number(gt=0)


POSITIVE_INT = _number(int, ge=1)


COUNT = _number(int, ge=0)


FINITE = _number()


SUBJECT_LENGTH = _number(
    ge=_native.LENGTH_SCALE_RANGE[0],
    le=_native.LENGTH_SCALE_RANGE[1],
    name="length_scale (the subject's segment lengths / the default's)",
)


SUBJECT_MASS = _number(
    ge=_native.MASS_SCALE_RANGE[0],
    le=_native.MASS_SCALE_RANGE[1],
    name="mass_scale (the subject's segment masses / the default's)",
)


SHOULDER_DEG = _number(ge=-180, le=180, unit=" degrees")


#: `ikid id --lowpass`: a cut-off in Hz, or 0 for none (its upper bound is the file's rate's half,
#: checked where the rate is known).
LOWPASS_HZ = _number(ge=0, unit=" Hz", name="the low-pass cut-off")


SEED = _number(int, ge=0, lt=2**32)


SIM_RATE = _number(gt=0, le=100_000, unit=" Hz")


PORT = _number(int, ge=0, le=65535)


def _widths(text: str) -> str:
    """``--hidden``: layer widths like ``128,128``, each a positive integer."""
    try:
        widths = [int(w) for w in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected widths like 128,128") from None
    if not widths or min(widths) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: every width must be a positive integer")
    return text


#: Noise kinds of ``--noise KIND:VALUE``, and the parameters each VALUE fills.
NOISE_KINDS = ("uniform", "gaussian", "drift", "occlusion")


#: Largest value of each noise kind: all of a marker's range (uniform, a fraction), 10 cm
#: (gaussian, drift), 100 occlusion bursts per second (one every 10 ms).
NOISE_MAX = {"uniform": 1.0, "gaussian": 0.1, "drift": 0.1, "occlusion": 100.0}


def _noise_spec(spec: str) -> str:
    """``--noise``: checked here (argparse type), parsed by :func:`_noise`."""
    kind, _, value = spec.partition(":")
    if kind not in NOISE_KINDS:
        raise argparse.ArgumentTypeError(f"{spec!r}: unknown kind {kind!r} ({', '.join(NOISE_KINDS)})")
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{spec!r}: expected KIND:NUMBER, e.g. uniform:0.01") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"{spec!r}: the value must be a finite number >= 0")
    if v > NOISE_MAX[kind]:
        raise argparse.ArgumentTypeError(f"{spec!r}: {kind} noise is at most {NOISE_MAX[kind]:g}")
    return spec


def _noise(spec: str) -> tuple[str, dict]:
    """``uniform:0.01``, ``gaussian:0.002`` (m), ``drift:0.005`` (m), ``occlusion:0.5`` (bursts/s)."""
    kind, _, value = _noise_spec(spec).partition(":")
    v = float(value)
    params = {
        "uniform": {"fraction": v},
        "gaussian": {"sigma": v},
        "drift": {"amplitude": v, "rate_hz": 0.0},
        "occlusion": {"bursts_per_second": v, "min_s": 0.05, "max_s": 0.3, "rate_hz": 0.0},
    }
    return kind, params[kind]


def _with_noise(trial: Trial, specs: list[str], seed: int) -> Trial:
    for k, spec in enumerate(specs):
        kind, params = _noise(spec)
        if "rate_hz" in params:
            params["rate_hz"] = trial.rate_hz
        trial = trial.with_noise(kind, seed * 1000 + k + 1, **params)
    return trial


#: How the command line opts in to a model file without a checksum (see :func:`ikid.load`).
UNCHECKED_FLAG = "--allow-unchecked-model"


def unchecked_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        UNCHECKED_FLAG,
        action="store_true",
        help="load a model file written before model files carried a checksum of their weights "
        "(refused otherwise: a corrupted copy cannot be told from a good one; a warning is printed). "
        "python -m ikid_training.export --restamp FILE adds the checksum for good",
    )
