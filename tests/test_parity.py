"""A torch MLP exported with the project's exporter gives torch's outputs in ikid (Rust core
through Python, batch and stream) and in ONNX, to 1e-5 relative on random windows."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import ikid

torch = pytest.importorskip("torch", reason="parity needs ikid-training (make wheel installs it)")
from torch import nn  # noqa: E402

from ikid_training.export import Affine, ModelSpec, WindowModel, export, export_onnx  # noqa: E402

#: Largest |ikid - torch| allowed, relative to the largest |torch output| of each column.
RTOL = 1e-5


def torch_reference(net: nn.Module, windows: np.ndarray, inp: Affine, out: Affine) -> np.ndarray:
    with torch.no_grad():
        x = torch.as_tensor(windows, dtype=torch.float32) * torch.as_tensor(inp.scale) + torch.as_tensor(
            inp.shift
        )
        y = net(x) * torch.as_tensor(out.scale) + torch.as_tensor(out.shift)
    return y.numpy()


def assert_close(got: np.ndarray, want: np.ndarray) -> None:
    scale = np.abs(want).max(axis=0)
    err = np.abs(got - want).max(axis=0)
    assert np.all(err <= RTOL * scale), f"max error {err} vs column scale {scale}"


def spread_frames(n: int, seed: int) -> np.ndarray:
    """Marker frames near the origin, each marker on its own random walk (~10 cm over 300
    frames; not rigid): every feature column varies and raw coordinates stay well
    conditioned in float32, so the comparison measures the kernels, not the cancellation in
    min-max scaling of coordinates half a metre from the origin."""
    rng = np.random.default_rng(seed)
    base = np.array(
        [
            [0, 0.01, 0.03],
            [-0.01, 0.01, -0.025],
            [-0.025, 0.18, 0],
            [-0.01, -0.08, 0.025],
            [-0.01, -0.075, -0.025],
            [-0.02, -0.03, 0],
        ]
    )
    frames = base[None] + 0.005 * np.cumsum(rng.normal(size=(n, 6, 3)), axis=0)
    return frames.reshape(n, 18).astype(np.float32)


def windows_of(features: np.ndarray, window: int) -> np.ndarray:
    n = len(features) - window + 1
    return np.stack([features[i : i + window].reshape(-1) for i in range(n)])


@pytest.mark.parametrize(
    ("feature_set", "hidden"),
    [("markers", (64, 64)), ("basis", (48, 48)), ("relative", (40, 30, 20))],
)
def test_exported_model_matches_torch(tmp_path, feature_set, hidden):
    torch.manual_seed(0)
    window = 5
    frames = spread_frames(300, seed=1)
    features = ikid.compute_features(frames, feature_set)
    n_in = window * features.shape[1]
    widths = [n_in, *hidden, 3]
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(itertools.pairwise(widths)):
        layers.append(nn.Linear(a, b))
        if i < len(hidden):
            layers.append(nn.ReLU())
    net = nn.Sequential(*layers).eval()
    windows = windows_of(features, window)
    inp = Affine.minmax(windows.min(axis=0), windows.max(axis=0))
    out = Affine.minmax(np.full(3, -1.4), np.full(3, 1.4)).inverse()
    spec = ModelSpec(name=f"parity-{feature_set}", task="ik", feature_set=feature_set, window=window)
    model = export(net, tmp_path / "m.safetensors", spec, inp, out)

    want = torch_reference(net, windows, inp, out)
    assert_close(model.predict(frames), want)
    stream = model.stream()
    streamed = np.stack([o for f in frames if (o := stream.push(f)) is not None])
    assert_close(streamed, want)

    ort = pytest.importorskip("onnxruntime")
    export_onnx(WindowModel(net, inp, out), tmp_path / "m.onnx")
    session = ort.InferenceSession(str(tmp_path / "m.onnx"), providers=["CPUExecutionProvider"])
    assert_close(session.run(None, {"window": windows.astype(np.float32)})[0], want)


def test_exporter_refuses_unsupported_modules(tmp_path):
    spec = ModelSpec(name="bad", task="ik", feature_set="markers")
    with pytest.raises(ValueError, match="Tanh"):
        export(nn.Sequential(nn.Linear(90, 8), nn.Tanh(), nn.Linear(8, 3)), tmp_path / "x.safetensors", spec)
    assert not (tmp_path / "x.safetensors").exists()
    with pytest.raises(ikid.ModelFileError, match="shape"):
        export(nn.Sequential(nn.Linear(91, 8), nn.ReLU(), nn.Linear(8, 3)), tmp_path / "y.safetensors", spec)
    assert not (tmp_path / "y.safetensors").exists()


def test_compiled_and_data_parallel_wrappers_are_unwrapped(tmp_path):
    net = nn.Sequential(nn.Linear(90, 8), nn.ReLU(), nn.Linear(8, 3))
    spec = ModelSpec(name="wrapped", task="ik", feature_set="markers")
    model = export(nn.DataParallel(net), tmp_path / "dp.safetensors", spec)
    assert model.layer_widths == [90, 8, 3]
