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
  units) × clock);
* the whole causal step, markers → angles and torques: ikid's Tracker (bare, and refined by the
  shipped ``wrist-track``) beside biorbd's extended Kalman filter + inverse dynamics, on the same
  held-out frames: angle and torque RMS, per-frame latency (the machinery of
  ``studies/ekf_peer.py``, on a subset of its trials; ``make compare-ekf`` has the full study).

Results: a section of docs/performance.md between the `peers` markers, and target/peers.json.
"""

from __future__ import annotations

import argparse
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
from studies import ekf_peer as ekf  # noqa: E402  (needs biorbd: the eval extra)
from studies.common import frames_for, machine  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "target" / "bench-peers"
SINGLE = 20_000
BATCH = 4096
START, END = "<!-- peers:start -->", "<!-- peers:end -->"
JSON = ROOT / "target" / "peers.json"
# The tracker comparison: ekf_peer's random-family test trials of the default-size subject (one
# per shoulder pose), at these noise levels, complete or with ekf_peer's occlusion bursts.
TRACKER_CONDITIONS = [("0%", False), ("1%", False), ("5%", False), ("5%", True)]


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


def tracker_vs_ekf(workers: int = 2) -> dict:
    """ikid's Tracker (``ikid.DEFAULT_JERK_NOISE``; bare, and refined by ``wrist-track``) and
    biorbd's EKF (its default and the setting ekf_peer tunes on its validation trials) + biorbd's
    inverse dynamics on the same frames: angle and torque RMS over every frame after ekf_peer's
    ``SKIP`` of each trial, and per-frame latency (Python p50/p99/mean over rounds, the core's
    loop, the Rust example)."""
    every = ekf.trial_specs()
    # Each trial keeps its index in ekf_peer's list: the same noise and occlusion seeds, so the
    # very frames docs/ekf.md scores.
    picked = [i for i, s in enumerate(every) if s["family"] == "random" and s["length_scale"] == 1.0]
    specs, vspecs = [every[i] for i in picked], ekf.validation_specs()
    ekf.check_held_out(specs + vspecs)
    recs, val = ekf.simulate(specs), ekf.simulate(vspecs)
    tuning = ekf.tune_ekf(val, workers)
    settings = {"ekf_default": ekf.EKF_DEFAULT, "ekf_tuned": tuning["chosen"]}
    data = {
        (i, c): ekf.condition(rec, i, *c)
        for i, rec in zip(picked, recs, strict=True)
        for c in TRACKER_CONDITIONS
    }
    jobs = [{"key": key, "meta": r.meta, "markers": r.markers, "ekf": settings} for key, r in data.items()]
    refiner, jerk = ikid.load("wrist-track"), ikid.DEFAULT_JERK_NOISE
    squared: dict[str, dict[str, dict[str, list[np.ndarray]]]] = {}
    for res in ekf.pool_map(ekf.biorbd_job, jobs, workers):
        rec, (lvl, occluded) = data[res["key"]], res["key"][1]
        estimates = {
            **{m: res[m] for m in settings},
            "tracker": ekf.run_tracker(rec, jerk),
            "tracker_refined": ekf.run_tracker(rec, jerk, refiner),
        }
        scored = slice(ekf.SKIP, len(rec))
        cond = f"{lvl}{' occluded' if occluded else ''}"
        for method, est in estimates.items():
            cell = squared.setdefault(method, {}).setdefault(cond, {"q": [], "tau": []})
            for k in ("q", "tau"):
                err = est[k][scored] - getattr(rec, k)[scored]
                if not np.isfinite(err).all():
                    raise RuntimeError(f"{method} on {rec.name} ({cond}): non-finite {k} where scored")
                cell[k].append(err**2)
    rms = {
        method: {
            cond: {
                "angle_deg": float(np.degrees(np.sqrt(np.mean(np.concatenate(c["q"]))))),
                "torque_nm": float(np.sqrt(np.mean(np.concatenate(c["tau"])))),
            }
            for cond, c in conds.items()
        }
        for method, conds in squared.items()
    }
    ik, chain = ikid.load("wrist-ik"), ikid.load("wrist-chain")
    lat_rec = ekf.D.add_noise(recs[0], "uniform", 0.01, ekf.NOISE_SEED + 99)
    return {
        "trials": [r.name for r in recs],
        "frames": int(sum(len(r) for r in recs)),
        "skip": ekf.SKIP,
        "ekf": settings,
        "jerk_noise": jerk,
        "rms": rms,
        "latency": {
            "python": ekf.python_latency(lat_rec, ik, chain, refiner, jerk),
            "rust": ekf.rust_latency(("tracker", "tracker_refined")),
        },
    }


def tracker_table(t: dict) -> list[str]:
    conds = list(next(iter(t["rms"].values())))
    py, rs = t["latency"]["python"], t["latency"]["rust"]
    nf_t, ef_t = t["ekf"]["ekf_tuned"]
    rows = [
        ("ekf_default", "biorbd EKF (default) + ID", py["ekf_id"], None, None),
        ("ekf_tuned", f"biorbd EKF (tuned: {nf_t:g}/{ef_t:g}) + ID", py["ekf_id"], None, None),
        ("tracker", "ikid Tracker", py["tracker"], py["tracker_rust_loop"], rs["tracker"]),
        (
            "tracker_refined",
            "ikid Tracker + wrist-track",
            py["tracker_refined"],
            py["tracker_refined_rust_loop"],
            rs["tracker_refined"],
        ),
    ]
    lines = [
        "### Markers → angles and torques (one causal step): ikid's Tracker beside biorbd's EKF + ID",
        "",
        f"The same frames for every method: {len(t['trials'])} held-out simulated trials "
        "(`studies/ekf_peer.py`'s random multi-DoF family, default-size subject, shoulder at 0°, 45° "
        "and −20°; "
        f"{t['frames']} frames at 1 kHz), uniform noise of ±0/1/5 % of each marker coordinate's range, "
        "and 5 % with one marker occluded in bursts; RMS over every frame after the first "
        f"{t['skip']} of each trial. biorbd: `KalmanReconsMarkers` (its default, and the noise/error "
        "factors ekf_peer tunes on its validation trials) then `InverseDynamics`; ikid: `ikid.Tracker` at "
        f"`DEFAULT_JERK_NOISE` ({t['jerk_noise']:g}), bare and refined by the shipped `wrist-track`, one "
        f"`push` giving q, q̇, q̈ and τ. Latency per frame, one thread: Python p50 / p99 ({ekf.LATENCY_ROUNDS} "
        f"rounds of {ekf.LATENCY_FRAMES} frames of one trial at 1 % noise, median over rounds; both "
        "settings of the EKF cost the same), the core's loop (`Tracker.run`, mean) and the Rust example "
        f"(`latency.rs --tracker`, p50 / p99, median of {ekf.RUST_REPEATS} runs). These are docs/ekf.md's "
        "frames for these trials; `make compare-ekf` has the full study (all sizes, the networks, "
        "biorbd's least-squares IK, the criteria).",
        "",
        "| method | angle RMS ° "
        + " | ".join(conds)
        + " | torque RMS N·m "
        + " | ".join(conds)
        + " | Python µs p50 / p99 | Rust loop µs (mean) | Rust µs p50 / p99 | EKF + ID / this (Python p50) |",
        "|---|" + "---|" * (2 * len(conds) + 4),
    ]
    for key, label, p, loop, r in rows:
        cells = [f"{t['rms'][key][c]['angle_deg']:.3f}" for c in conds]
        cells += [f"{t['rms'][key][c]['torque_nm']:.4f}" for c in conds]
        cells.append(f"{p['p50_us']:.1f} / {p['p99_us']:.1f}")
        cells.append(f"{loop['mean_us']:.2f}" if loop else "")
        cells.append(f"{r['p50_us']:.2f} / {r['p99_us']:.2f}" if r else "")
        cells.append(f"{py['ekf_id']['p50_us'] / p['p50_us']:.1f}×" if key.startswith("tracker") else "")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    if "5%" in conds and "5% occluded" in conds:
        cost = {
            k: t["rms"][k]["5% occluded"]["torque_nm"] / t["rms"][k]["5%"]["torque_nm"]
            for k in ("ekf_default", "ekf_tuned", "tracker", "tracker_refined")
        }
        lines += [
            "",
            "One marker occluded in bursts at 5 % noise, torque RMS over complete markers': "
            f"biorbd EKF {cost['ekf_default']:.2f}× (default) / {cost['ekf_tuned']:.2f}× (tuned), ikid "
            f"Tracker {cost['tracker']:.2f}×, Tracker + wrist-track {cost['tracker_refined']:.2f}×.",
        ]
    return lines


def table(summary: dict) -> list[str]:
    results, ghz = summary["networks"], summary["clock_ghz"]
    cores = summary["cores"]
    peak_1 = 32 * ghz * 1e9  # f32 FLOP/s on one core: 2 FMA units x 8 lanes x 2
    lines = [
        f"Generated by `make bench-peers` on {summary['generated']} — {summary['machine']}; "
        f"clock {ghz:.2f} GHz.",
        ", ".join(f"{name} {version}" for name, version in summary["versions"].items()) + ".",
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
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--render", action="store_true", help=f"only rewrite the doc's section from {JSON} of an earlier run"
    )
    if parser.parse_args().render:
        summary = json.loads(JSON.read_text(encoding="utf-8"))
    else:
        summary = {
            "generated": time.strftime("%Y-%m-%d %H:%M"),
            "machine": machine(),
            "clock_ghz": clock_ghz(),
            "cores": os.cpu_count() or 1,
            "versions": {
                "onnxruntime": ort.__version__,
                "torch": torch.__version__,
                "numpy": np.__version__,
                "biorbd": ekf.biorbd.__version__,
                "ikid": ikid.__version__,
            },
            "networks": [measure(*n) for n in networks()],
            "tracker": tracker_vs_ekf(),
        }
        JSON.write_text(json.dumps(summary, indent=2), encoding="utf-8")
    lines = [*table(summary), "", *tracker_table(summary["tracker"])]
    doc = ROOT / "docs" / "performance.md"
    # UTF-8 whatever the locale (make may run under LANG=C): the page has µ, ², →.
    text = doc.read_text(encoding="utf-8") if doc.exists() else "# Performance\n"
    section = "\n".join([START, "## Peers (`make bench-peers`)", "", *lines, END])
    if START in text:
        text = re.sub(re.escape(START) + ".*?" + re.escape(END), lambda _: section, text, flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + section + "\n"
    doc.write_text(text, encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
