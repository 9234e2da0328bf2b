"""`make bench-peers`: the same networks run by ikid and by its peers, in one process, one run.

For each network (the thesis' three shapes with random weights, and the three shipped models)
the one torch module is exported to ikid's file and to ONNX, then timed:
* single frame, p50/p99 over timed calls: ikid `Stream.push` from Python (the whole job:
  features, window, network), ikid's Rust push (`examples/latency.rs`) and C ABI push
  (`benches/c/abi_overhead.c`) on the same file; onnxruntime `run()` and `run_with_iobinding`,
  torch eager, TorchScript and NumPy on one ready-made input window (the network alone: the
  peers get the feature computation for free);
* batch throughput (per sample, 4096 windows) with 1 and 2 threads: ikid `Model.predict`,
  onnxruntime, torch; NumPy with its BLAS's default threads;
* the compute floor: 2 × multiply-adds / (cores × 32 f32 FLOPs per cycle (2 AVX2 FMA
  units) × clock).

Results: a section of docs/performance.md between the `peers` markers, and target/peers.json.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch
from torch import nn

import ikid

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ikid_training.export import Affine, ModelSpec, WindowModel, export, export_onnx, load_torch  # noqa: E402
from studies import common  # noqa: E402
from studies.common import frames_for, machine  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "target" / "bench-peers"
SINGLE = 20_000
BATCH = 4096
START, END = "<!-- peers:start -->", "<!-- peers:end -->"


def thesis_nets() -> list[tuple[str, str, list[int]]]:
    return [
        ("ik_markers_90-300-300-3", "markers", [300, 300]),
        ("ik_basis_120-240-240-3", "basis", [240, 240]),
        ("id_45-330-60-165-3", "joint_state", [330, 60, 165]),
    ]


def networks() -> list[tuple[str, ikid.Model, nn.Sequential, Path]]:
    """(label, ikid model, torch net with scaling folded in, ONNX path) for every network."""
    OUT.mkdir(parents=True, exist_ok=True)
    nets = []
    torch.manual_seed(0)
    for label, fs, hidden in thesis_nets():
        n_in = 5 * ikid.feature_set_info(fs)["feature_len"]
        widths = [n_in, *hidden, 3]
        seq: list[nn.Module] = []
        for a, b in itertools.pairwise(widths):
            seq += [nn.Linear(a, b), nn.ReLU()]
        net = nn.Sequential(*seq[:-1]).eval()
        task = "id" if ikid.feature_set_info(fs)["frame_kind"] == "joint_state" else "ik"
        model = export(
            net,
            OUT / f"{label}.safetensors",
            ModelSpec(name=label, task=task, feature_set=fs, window=5),
            Affine.identity(n_in),
            Affine.identity(3),
        )
        nets.append((label, model, net, WindowModel(net, Affine.identity(n_in), Affine.identity(3))))
    for name in ikid.available_models():
        model = ikid.load(name)
        path = OUT / f"{name}.safetensors"
        model.save(path)
        reference = load_torch(path)
        nets.append((name, model, reference.net, reference))
    result = []
    for label, model, _net, whole in nets:
        onnx_path = OUT / f"{label}.onnx"
        export_onnx(whole, onnx_path)
        result.append((label, model, whole.eval(), onnx_path))
    return result


def timed_calls(fn, n: int = SINGLE) -> dict[str, float]:
    for _ in range(min(n // 10, 2000)):
        fn()
    ns = np.empty(n, np.int64)
    clock = time.perf_counter_ns
    for i in range(n):
        t = clock()
        fn()
        ns[i] = clock() - t
    return {"p50_us": float(np.median(ns)) / 1e3, "p99_us": float(np.percentile(ns, 99)) / 1e3}


def per_sample_us(fn, samples: int, repeat: int = 5) -> float:
    fn()
    best = min(_seconds(fn) for _ in range(repeat))
    return best / samples * 1e6


def _seconds(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def numpy_forward(model: WindowModel):
    """The model as NumPy float32 matmuls (scaling and output offset included), for the NumPy column."""
    s_in, b_in = model.in_scale.numpy(), model.in_shift.numpy()
    s_out, b_out = model.out_scale.numpy(), model.out_shift.numpy()
    layers = [
        (m.weight.detach().numpy().T.copy(), m.bias.detach().numpy())
        for m in model.net
        if isinstance(m, nn.Linear)
    ]
    offset, n_out = model.offset_features, model.n_out

    def forward(x: np.ndarray) -> np.ndarray:
        h = x * s_in + b_in
        for k, (w, b) in enumerate(layers):
            h = h @ w + b
            if k + 1 < len(layers):
                np.maximum(h, 0, out=h)
        y = h * s_out + b_out
        if offset:
            start = x.shape[1] - offset
            y += x[:, start : start + n_out]
        return y

    return forward


def ort_session(path: Path, threads: int) -> ort.InferenceSession:
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])


def rust_push(path: Path) -> dict[str, float]:
    res = common.rust_latency("--pushes", "200000", "--model", str(path))
    if res.returncode != 0:
        raise RuntimeError(f"examples/latency --model {path} failed:\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def clock_ghz() -> float:
    mhz = re.findall(r"cpu MHz\s*:\s*([\d.]+)", Path("/proc/cpuinfo").read_text())
    return max(float(m) for m in mhz) / 1e3 if mhz else 2.5


def measure(label: str, model: ikid.Model, net: nn.Sequential, onnx_path: Path) -> dict:
    frames = frames_for(model, 1024)
    n_in = model.layer_widths[0]
    windows = ikid.compute_features(frames, model.feature_set)
    x1 = np.ascontiguousarray(
        np.lib.stride_tricks.sliding_window_view(windows, (model.window, windows.shape[1]))[:, 0]
        .reshape(-1, n_in)[:1]
        .astype(np.float32)
    )
    r: dict = {
        "network": label,
        "widths": model.layer_widths,
        "macs": int(sum(a * b for a, b in itertools.pairwise(model.layer_widths))),
    }

    stream = model.stream()
    stream.push_many(frames)
    i = [0]

    def push() -> None:
        stream.push(frames[i[0] & 1023])
        i[0] += 1

    r["ikid_python_push"] = timed_calls(push)
    rust = rust_push(OUT / f"{label}.safetensors")
    r["ikid_rust_push"] = {"p50_us": rust["p50_us"], "p99_us": rust["p99_us"], "max_us": rust["max_us"]}
    np.savetxt(OUT / f"{label}.frames.csv", frames_for(model, 1000), fmt="%.9g", delimiter=",")
    capi = subprocess.run(
        [
            str(ROOT / "target" / "c" / "abi_overhead"),
            str(OUT / f"{label}.safetensors"),
            str(OUT / f"{label}.frames.csv"),
        ],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    c = json.loads(capi)
    r["ikid_c_push"] = {
        "p50_us": c.get("push_p50_us", float("nan")),
        "p99_us": c.get("push_p99_us", float("nan")),
    }

    sess = ort_session(onnx_path, 1)
    name = sess.get_inputs()[0].name
    r["ort_run"] = timed_calls(lambda: sess.run(None, {name: x1}))
    binding = sess.io_binding()
    x_ort = ort.OrtValue.ortvalue_from_numpy(x1)
    binding.bind_ortvalue_input(name, x_ort)
    y_ort = ort.OrtValue.ortvalue_from_shape_and_type([1, model.n_outputs], np.float32)
    binding.bind_ortvalue_output(sess.get_outputs()[0].name, y_ort)
    r["ort_iobinding"] = timed_calls(lambda: sess.run_with_iobinding(binding))

    torch.set_num_threads(1)
    xt = torch.as_tensor(x1)
    with torch.inference_mode():
        r["torch_eager"] = timed_calls(lambda: net(xt))
        scripted = torch.jit.optimize_for_inference(torch.jit.trace(net, xt))
        r["torchscript"] = timed_calls(lambda: scripted(xt))
    fwd = numpy_forward(net)
    r["numpy"] = timed_calls(lambda: fwd(x1))

    # Batch: BATCH windows (ikid gets the BATCH + window - 1 frames they come from).
    many_frames = frames_for(model, BATCH + model.window - 1)
    feats = ikid.compute_features(many_frames, model.feature_set)
    xb = np.ascontiguousarray(
        np.lib.stride_tricks.sliding_window_view(feats, (model.window, feats.shape[1]))[:, 0].reshape(
            -1, n_in
        )
    )
    xbt = torch.as_tensor(xb)
    # The features alone (one thread), which ikid's predict includes and the peers get for free.
    r["batch_ikid_features_1t"] = (
        per_sample_us(lambda: ikid.compute_features(many_frames, model.feature_set), len(many_frames))
        if model.frame_kind == "markers"
        else 0.0
    )
    for threads in (1, 2):
        r[f"batch_ikid_{threads}t"] = per_sample_us(
            lambda: model.predict(many_frames, threads=threads),  # noqa: B023 (called before the loop moves on)
            BATCH,
        )
        s = ort_session(onnx_path, threads)
        r[f"batch_ort_{threads}t"] = per_sample_us(
            lambda: s.run(None, {name: xb}),  # noqa: B023 (called before the loop moves on)
            BATCH,
        )
        torch.set_num_threads(threads)
        with torch.inference_mode():
            r[f"batch_torch_{threads}t"] = per_sample_us(lambda: net(xbt), BATCH)
    torch.set_num_threads(1)
    r["batch_numpy"] = per_sample_us(lambda: fwd(xb), BATCH)
    # Agreement, so the table compares the same function.
    want = net(torch.as_tensor(xb[:64])).detach().numpy()
    got = model.predict(many_frames[: 64 + model.window - 1])
    r["max_rel_diff_ikid_vs_torch"] = float(np.max(np.abs(got - want)) / max(np.abs(want).max(), 1e-12))
    return r


def table(results: list[dict], ghz: float) -> list[str]:
    cores = os.cpu_count() or 1
    peak_1 = 32 * ghz * 1e9  # f32 FLOP/s on one core: 2 FMA units x 8 lanes x 2
    lines = [
        f"Generated by `make bench-peers` on {time.strftime('%Y-%m-%d %H:%M')} — {machine()}; "
        f"clock {ghz:.2f} GHz.",
        f"onnxruntime {ort.__version__}, torch {torch.__version__}, numpy {np.__version__}, "
        f"ikid {ikid.__version__}.",
        "",
        "### Single frame (p50 / p99, µs; one thread)",
        "",
        "ikid columns do the whole job (features, window, network); the peers run the network alone on one",
        "ready-made window. Ratio = peer p50 / ikid Python push p50 (> 1: ikid faster). Floor = 2·MACs at",
        f"one core's peak ({peak_1 / 1e9:.0f} GFLOP/s at the clock /proc/cpuinfo reports; "
        "a boost clock lowers it, so",
        "a figure near or under the floor means the core ran faster than reported).",
        "",
        "| network | floor | ikid Rust | ikid C ABI | ikid Python | ORT run() | ORT IOBinding | "
        "torch eager | TorchScript | NumPy |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        floor = 2 * r["macs"] / peak_1 * 1e6
        base = r["ikid_python_push"]["p50_us"]

        def cell(k: str, ratio: bool = True, r: dict = r, base: float = base) -> str:
            v = r[k]
            s = f"{v['p50_us']:.2f} / {v['p99_us']:.1f}"
            return s + (f" ({v['p50_us'] / base:.1f}×)" if ratio else "")

        lines.append(
            f"| {r['network']} | {floor:.2f} | {cell('ikid_rust_push', False)} | "
            f"{cell('ikid_c_push', False)} | {cell('ikid_python_push', False)} | {cell('ort_run')} | "
            f"{cell('ort_iobinding')} | {cell('torch_eager')} | {cell('torchscript')} | {cell('numpy')} |"
        )
    lines += [
        "",
        f"### Batch ({BATCH} windows; µs per sample, 1 thread / 2 threads; {cores} cores)",
        "",
        "ikid `predict` does the whole job from marker frames (features, windows, "
        "network); the peers run the",
        "network on ready-made windows. *ikid features* is the feature computation alone (per frame, one",
        "thread), included in ikid's figure. Ratio = ikid / ORT (< 1: ikid cheaper).",
        "",
        "| network | floor (1 t) | ikid `predict` | ikid features | ORT | ikid / ORT | torch | NumPy "
        "(BLAS default) | ikid vs torch (max rel. diff) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        floor = 2 * r["macs"] / peak_1 * 1e6
        ratio = f"{r['batch_ikid_1t'] / r['batch_ort_1t']:.2f} / {r['batch_ikid_2t'] / r['batch_ort_2t']:.2f}"
        lines.append(
            f"| {r['network']} | {floor:.3f} | {r['batch_ikid_1t']:.3f} / {r['batch_ikid_2t']:.3f} | "
            f"{r['batch_ikid_features_1t']:.3f} | {r['batch_ort_1t']:.3f} / {r['batch_ort_2t']:.3f} | "
            f"{ratio} | {r['batch_torch_1t']:.3f} / {r['batch_torch_2t']:.3f} | {r['batch_numpy']:.3f} | "
            f"{r['max_rel_diff_ikid_vs_torch']:.1e} |"
        )
    return lines


def main() -> None:
    results = [measure(*n) for n in networks()]
    (ROOT / "target" / "peers.json").write_text(json.dumps(results, indent=2))
    lines = table(results, clock_ghz())
    doc = ROOT / "docs" / "performance.md"
    text = doc.read_text() if doc.exists() else "# Performance\n"
    section = "\n".join([START, "## Peers (`make bench-peers`)", "", *lines, END])
    if START in text:
        text = re.sub(re.escape(START) + ".*?" + re.escape(END), lambda _: section, text, flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + section + "\n"
    doc.write_text(text)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
