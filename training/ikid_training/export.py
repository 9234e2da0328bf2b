"""Export a torch MLP to ikid's ``.safetensors`` model format (and to ONNX for interop).

The file is written by the Rust core (``ikid._native.build_model`` + ``Model.save``), so the
format has exactly one writer and every exported file has passed the loader's validation.

The network must be a chain of ``nn.Linear`` layers with ``nn.ReLU`` between them (an
``nn.Sequential``, optionally wrapped by ``torch.compile`` or ``DataParallel``); scaling is
given separately as per-element affine maps ``x * scale + shift``:

    net_input = window_features * input_scale + input_shift
    prediction = net(net_input) * output_scale + output_shift [+ newest frame's features]

The bracket is the card's ``output_offset = "newest_features"`` (``ModelSpec.output_offset``):
the network learns a correction to the newest frame's own estimate (e.g. per-frame angles).
:class:`WindowModel` is that whole function in torch (ONNX export, parity, peers).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

import ikid
from ikid import _native

#: Units of each task's outputs (SI, as everywhere inside ikid).
TASK_UNITS = {"ik": "rad", "id": "N*m", "chain": "N*m", "refine": "rad"}


@dataclass
class Affine:
    """Element-wise ``x * scale + shift``."""

    scale: np.ndarray
    shift: np.ndarray

    @staticmethod
    def identity(n: int) -> Affine:
        return Affine(np.ones(n, np.float32), np.zeros(n, np.float32))

    @staticmethod
    def minmax(lo: np.ndarray, hi: np.ndarray, target: tuple[float, float] = (-1.0, 1.0)) -> Affine:
        """Maps ``[lo, hi]`` onto ``target`` (sklearn's MinMaxScaler); constant columns map to the
        midpoint."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        span = np.where(hi > lo, hi - lo, 1.0)
        scale = (target[1] - target[0]) / span
        shift = target[0] - lo * scale
        shift = np.where(hi > lo, shift, 0.5 * (target[0] + target[1]) - lo * scale)
        return Affine(scale.astype(np.float32), shift.astype(np.float32))

    def inverse(self) -> Affine:
        """The map undoing this one (for output scaling: network units -> SI)."""
        scale = 1.0 / self.scale.astype(np.float64)
        return Affine(scale.astype(np.float32), (-self.shift * scale).astype(np.float32))


@dataclass
class ModelSpec:
    """Everything the model card says besides the weights."""

    name: str
    task: str
    feature_set: str
    window: int = 5
    frame_rate_hz: float = 1000.0
    missing_markers: str = "refuse"  # or "fill": streams fill one missing marker (ikid.fill_gaps)
    output_names: Sequence[str] = field(default_factory=ikid.coordinate_names)
    output_units: Sequence[str] | None = None
    scaling: Mapping[str, str] = field(default_factory=dict)
    provenance: Mapping[str, Any] = field(default_factory=dict)
    metrics: Mapping[str, Any] = field(default_factory=dict)
    output_offset: str | None = None  # "newest_features": outputs add the newest frame's features
    #: The training data's ranges (see :func:`envelope_of`): frames outside it are flagged.
    envelope: Mapping[str, Any] | None = None


def linear_layers(net: nn.Module) -> list[tuple[nn.Linear, str]]:
    """The ``(Linear, activation)`` chain of ``net``; refuses anything else by name."""
    net = getattr(net, "_orig_mod", net)  # torch.compile
    net = getattr(net, "module", net)  # DataParallel / DistributedDataParallel
    chain: list[tuple[nn.Linear, str]] = []
    for name, module in net.named_children():
        if isinstance(module, nn.Linear):
            chain.append((module, "identity"))
        elif isinstance(module, nn.ReLU):
            if not chain or chain[-1][1] != "identity":
                raise ValueError(f"module {name!r}: ReLU must follow a Linear layer")
            chain[-1] = (chain[-1][0], "relu")
        elif isinstance(module, (nn.Identity, nn.Dropout)):
            continue
        else:
            raise ValueError(
                f"module {name!r} ({type(module).__name__}) is not supported: use Linear and ReLU only"
            )
    if not chain:
        raise ValueError("the network has no Linear layers")
    return chain


def card_for(spec: ModelSpec, activations: Sequence[str]) -> dict[str, Any]:
    """The model card (see crates/ikid/src/model/card.rs for the schema, which checks it)."""
    info = ikid.feature_set_info(spec.feature_set)
    units = spec.output_units or [TASK_UNITS[spec.task]] * len(spec.output_names)
    return {
        "format": "ikid-model",
        "format_version": 1,
        "name": spec.name,
        "task": spec.task,
        "feature_set": spec.feature_set,
        "feature_names": info["feature_names"],
        "window": spec.window,
        "predicted_frame": "newest",
        "frame_rate_hz": spec.frame_rate_hz,
        "outputs": [{"name": n, "unit": u} for n, u in zip(spec.output_names, units, strict=True)],
        "missing_markers": spec.missing_markers,
        "activations": list(activations),
        "scaling": dict(spec.scaling),
        "provenance": dict(spec.provenance),
        "metrics": dict(spec.metrics),
        **({"output_offset": spec.output_offset} if spec.output_offset else {}),
        **({"envelope": dict(spec.envelope)} if spec.envelope else {}),
    }


def envelope_of(
    windows: np.ndarray, feature_len: int, outputs: np.ndarray, seen: Sequence[np.ndarray] = ()
) -> dict[str, Any]:
    """The card's ``envelope``: each per-frame feature's range over every frame of the
    training ``windows`` ``(n, window × feature_len)``, and each output's over ``outputs``
    ``(n, n_outputs)`` (SI, what the model gives); ``window_change`` (:func:`window_change`) over
    ``windows`` and the windows in ``seen`` (e.g. the noisy ones the network trained on) pooled."""
    per_frame = np.asarray(windows, np.float64).reshape(-1, feature_len)
    outputs = np.asarray(outputs, np.float64)

    def bounds(a: np.ndarray) -> dict[str, list[float]]:
        return {"min": a.min(0).tolist(), "max": a.max(0).tolist()}

    change = window_change([windows, *seen], feature_len)
    return {"inputs": bounds(per_frame), "outputs": bounds(outputs), "window_change": change.tolist()}


#: The share of its training windows a correcting model corrects at their speed: the card's
#: ``window_change`` is this quantile of the training windows' changes, not their largest. The
#: fastest few teach the network little (wrist-ik on a held-out simulated session, clean: 0.1°
#: RMS per coordinate below 300°/s, 0.6-1.1° over 2000°/s), and the largest is set by one burst:
#: sessions with 40 ms bursts made wrist-ik's 4x the random protocol's.
WINDOW_CHANGE_QUANTILE = 0.999


def window_changes(windows: np.ndarray, feature_len: int) -> np.ndarray:
    """Each window's change of each feature's mean from its older half to its newer half
    (``window // 2`` frames each), ``(n, feature_len)``: how fast it moves, noise averaged out
    (the core's ``NewestFeatures`` measures a live window the same way)."""
    w = np.asarray(windows, np.float64).reshape(len(windows), -1, feature_len)
    half = max(w.shape[1] // 2, 1)
    return np.abs(w[:, w.shape[1] - half :].mean(axis=1) - w[:, :half].mean(axis=1))


def window_change(window_sets: Sequence[np.ndarray], feature_len: int) -> np.ndarray:
    """The card's ``window_change``: per feature, the :data:`WINDOW_CHANGE_QUANTILE` quantile of
    :func:`window_changes` over every window of ``window_sets`` pooled (e.g. the clean and the
    noisy windows the network trained on)."""
    changes = np.concatenate([window_changes(w, feature_len) for w in window_sets])
    return np.quantile(changes, WINDOW_CHANGE_QUANTILE, axis=0)


def envelope_from_scaling(card: Mapping[str, Any], tensors: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """The envelope of a model whose scaling tensors were min-max fitted to ``[-1, 1]`` on its
    training data (its card's ``scaling`` says so): the training ranges are those tensors'
    inverse images, exactly. For models written before cards carried envelopes."""
    scaling = card.get("scaling", {})
    if not all(str(scaling.get(k, "")).startswith("minmax(-1,1)") for k in ("input", "output")):
        raise ValueError(f"model {card['name']!r}: scaling {scaling} is not min-max on both sides")
    feature_len = len(card["feature_names"])

    def image(scale: np.ndarray, shift: np.ndarray, inverse: bool) -> tuple[np.ndarray, np.ndarray]:
        scale, shift = scale.astype(np.float64), shift.astype(np.float64)
        # inputs: x*scale + shift spans [-1, 1]; outputs: SI = h*scale + shift for h in [-1, 1].
        ends = (
            ((np.array([-1.0, 1.0])[:, None] - shift) / scale)
            if inverse
            else (np.array([-1.0, 1.0])[:, None] * scale + shift)
        )
        return ends.min(0), ends.max(0)

    lo, hi = image(tensors["input.scale"], tensors["input.shift"], inverse=True)
    lo, hi = lo.reshape(-1, feature_len).min(0), hi.reshape(-1, feature_len).max(0)
    out_lo, out_hi = image(tensors["output.scale"], tensors["output.shift"], inverse=False)
    if card.get("output_offset"):
        # Outputs add the newest frame's same-named feature: ranges add.
        n = len(out_lo)
        out_lo, out_hi = out_lo + lo[:n], out_hi + hi[:n]
    return {
        "inputs": {"min": lo.tolist(), "max": hi.tolist()},
        "outputs": {"min": out_lo.tolist(), "max": out_hi.tolist()},
    }


def restamp(
    path: str | Path, envelope: Mapping[str, Any] | None, metrics: Mapping[str, Any] | None = None
) -> ikid.Model:
    """Rewrite model file ``path`` through the one writer: same tensors, the card given an
    ``envelope`` and ``metrics`` (each if not None) and a tensor checksum. A file written
    before checksums is read unchecked (that is what restamping is for); one with a checksum
    must match it. Atomic; returns the model read back (checked)."""
    from safetensors.numpy import load_file

    path = Path(path)
    # Checked (a checksum it has, verified) first.
    card = dict(_native.Model.load(path, allow_unchecked=True).card)
    tensors = load_file(str(path))
    card.pop("tensor_sha256", None)
    if envelope is not None:
        card["envelope"] = dict(envelope)
    if metrics is not None:
        card["metrics"] = dict(metrics)
    n_layers = len(card["activations"])
    weights: list[npt.ArrayLike] = [tensors[f"layers.{k}.weight"] for k in range(n_layers)]
    biases: list[npt.ArrayLike] = [tensors[f"layers.{k}.bias"] for k in range(n_layers)]
    model = _native.build_model(
        json.dumps(card),
        weights,
        biases,
        tensors["input.scale"],
        tensors["input.shift"],
        tensors["output.scale"],
        tensors["output.shift"],
    )
    model.save(path)
    return ikid.load(path)


def export(
    net: nn.Module,
    path: str | Path,
    spec: ModelSpec,
    input_scaling: Affine | None = None,
    output_scaling: Affine | None = None,
) -> ikid.Model:
    """Write ``net`` as an ikid model file at ``path`` and return it loaded from there."""
    chain = linear_layers(net)
    # Typed as what build_model takes (its stub's list[ArrayLike]; a list is invariant).
    weights: list[npt.ArrayLike] = [lin.weight.detach().cpu().float().numpy() for lin, _ in chain]
    biases: list[npt.ArrayLike] = [
        (
            lin.bias.detach().cpu().float().numpy()
            if lin.bias is not None
            else np.zeros(lin.out_features, np.float32)
        )
        for lin, _ in chain
    ]
    n_in, n_out = chain[0][0].in_features, chain[-1][0].out_features
    inp = input_scaling or Affine.identity(n_in)
    out = output_scaling or Affine.identity(n_out)
    card = card_for(spec, [act for _, act in chain])
    model = _native.build_model(json.dumps(card), weights, biases, inp.scale, inp.shift, out.scale, out.shift)
    model.save(Path(path))
    return ikid.load(Path(path))


class WindowModel(nn.Module):
    """A model file's whole function in torch: raw feature window ``[batch, window × F]`` ->
    SI outputs, i.e. ``net`` with its scaling and, with ``offset_features = F``, the newest
    frame's first outputs-many features added (the card's ``output_offset``)."""

    # Buffers (register_buffer): typed here, as nn.Module's __getattr__ cannot tell them from submodules.
    in_scale: torch.Tensor
    in_shift: torch.Tensor
    out_scale: torch.Tensor
    out_shift: torch.Tensor

    def __init__(self, net: nn.Module, inp: Affine, out: Affine, offset_features: int = 0):
        super().__init__()
        self.net = net
        self.offset_features = offset_features
        self.n_out = linear_layers(net)[-1][0].out_features
        for name, arr in [
            ("in_scale", inp.scale),
            ("in_shift", inp.shift),
            ("out_scale", out.scale),
            ("out_shift", out.shift),
        ]:
            self.register_buffer(name, torch.as_tensor(np.asarray(arr, np.float32)))

    @property
    def n_inputs(self) -> int:
        return linear_layers(self.net)[0][0].in_features

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.net(x * self.in_scale + self.in_shift) * self.out_scale + self.out_shift
        if self.offset_features:
            start = x.shape[1] - self.offset_features
            y = y + x[:, start : start + self.n_out]
        return y


def export_onnx(model: WindowModel, path: str | Path) -> None:
    """Write ``model`` as ONNX: input ``window`` ``[batch, n_inputs]`` -> ``output`` (SI). The graph
    is the network with its scaling and offset; ikid's runtime policies on top of it (status
    bits, and a correcting model left uncorrected beyond its training envelope) are not in it."""
    example = torch.zeros(1, model.n_inputs)
    torch.onnx.export(
        model.eval(),
        (example,),
        str(path),
        input_names=["window"],
        output_names=["output"],
        dynamic_axes={"window": {0: "batch"}, "output": {0: "batch"}},
        dynamo=False,
    )


def load_torch(path: str | Path) -> WindowModel:
    """The model in an ikid model file as a torch :class:`WindowModel`, read with the
    ``safetensors`` library (not ikid): the inverse of :func:`export`, so parity tests and
    peer benchmarks compare ikid against an independent reading of the same file."""
    from safetensors import safe_open

    with safe_open(str(path), framework="numpy") as f:
        t = {k: f.get_tensor(k) for k in f.keys()}
        card = json.loads(f.metadata()["ikid"])
    layers: list[nn.Module] = []
    for k, act in enumerate(card["activations"]):
        w, b = t[f"layers.{k}.weight"], t[f"layers.{k}.bias"]
        lin = nn.Linear(w.shape[1], w.shape[0])
        lin.weight.data, lin.bias.data = torch.as_tensor(w), torch.as_tensor(b)
        layers += [lin, nn.ReLU()] if act == "relu" else [lin]
    if card.get("output_offset") not in (None, "newest_features"):
        raise ValueError(f"{path}: output_offset {card['output_offset']!r} is not known to this exporter")
    offset = len(card["feature_names"]) if card.get("output_offset") else 0
    net = nn.Sequential(*layers).eval()
    return WindowModel(
        net, Affine(t["input.scale"], t["input.shift"]), Affine(t["output.scale"], t["output.shift"]), offset
    ).eval()


if __name__ == "__main__":  # `python -m ikid_training.export --restamp FILE`: see ikid_training.restamp
    from ikid_training.restamp import main

    raise SystemExit(main())
