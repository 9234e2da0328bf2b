"""Collect the benchmark figures of one `make bench` run into docs/performance.md.

Side by side, in one run on one machine:
* criterion (`cargo bench -p ikid --bench inference`, run just before by `make bench`):
  `Stream::push` and per-sample `Model::predict` for the thesis' three network shapes;
* the per-push latency distribution from Rust (`examples/latency.rs`, p50/p99/max);
* the same models pushed from Python (`ikid.Stream.push`), so the Python overhead is a
  difference of two figures measured minutes apart on the same files.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import ikid

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from studies import common  # noqa: E402
from studies.common import frames_for, machine  # noqa: E402

MODELS = ROOT / "target" / "bench-models"
CRITERION = ROOT / "target" / "criterion"
PUSHES = 200_000


def rust_latency() -> dict[str, dict]:
    res = common.rust_latency("--pushes", str(PUSHES), "--save-dir", str(MODELS))
    if res.returncode != 0:
        raise SystemExit(f"examples/latency failed:\n{res.stderr}")
    rows = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    return {r["model"]: r for r in rows}


def python_push(model: ikid.Model, n: int) -> dict[str, float]:
    """Per-call latency of ``Stream.push`` from Python, and its overhead over the Rust push.

    The overhead is measured in one process, interleaved: rounds of 1000 frames pushed one
    by one from a Python loop against the same 1000 frames through ``Stream.push_many``
    (one call, the Rust loop). Median over rounds of the per-frame difference.
    """
    frames = frames_for(model, 1024)
    stream = model.stream()
    stream.push_many(frames)
    ns = np.empty(n, np.int64)
    clock = time.perf_counter_ns
    for i in range(n):
        f = frames[i % 1024]
        t = clock()
        stream.push(f)
        ns[i] = clock() - t
    diffs = []
    block = frames[:1000]
    for _ in range(60):
        t = clock()
        for f in block:
            stream.push(f)
        one_by_one = (clock() - t) / 1000
        t = clock()
        stream.push_many(block)
        in_rust = (clock() - t) / 1000
        diffs.append((one_by_one - in_rust) / 1000)
    return {
        "p50_us": float(np.median(ns)) / 1000,
        "p99_us": float(np.percentile(ns, 99)) / 1000,
        "overhead_us": float(np.median(diffs)),
    }


#: The shipped refiner, timed with `ikid_tracker_push` beside the stream (marker models only).
REFINER = ROOT / "python" / "ikid" / "models" / "wrist-track.safetensors"


def c_abi(label: str) -> dict[str, float]:
    """The C ABI's cost over the Rust push, and the tracker's push from C beside the stream's
    (benches/c/abi_overhead.c, built by `make c`)."""
    model = ikid.load(MODELS / f"{label}.safetensors")
    csv = MODELS / f"{label}.frames.csv"
    np.savetxt(csv, frames_for(model, 1000), fmt="%.9g", delimiter=",")
    refiner = [str(REFINER)] if model.frame_len == 18 else []
    bench = ROOT / "target" / "c" / "abi_overhead"
    out = subprocess.run(
        [str(bench), str(MODELS / f"{label}.safetensors"), str(csv), *refiner],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return json.loads(out)


def python_batch(model: ikid.Model, n: int = 10_000, repeat: int = 5) -> float:
    frames = frames_for(model, n)
    best = min(_timed(lambda: model.predict(frames)) for _ in range(repeat))
    return best / model.predict(frames).shape[0] * 1e6


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def soak(pushes: int = 10_000_000) -> list[str]:
    """The 10^7-push soak (crates/ikid/examples/soak.rs): allocations, memory, latency drift."""
    out = subprocess.run(
        ["cargo", "run", "--release", "-q", "-p", "ikid", "--example", "soak", "--", "--pushes", str(pushes)],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    r = json.loads(out.strip().splitlines()[-1])
    f, la = r["first_million_us"], r["last_million_us"]
    return [
        "## Soak (`cargo run --release -p ikid --example soak`)",
        "",
        f"{r['pushes']:,} pushes through one stream (150-128-128-3 on `angles` × 50, gap filling on; "
        f"{r['filled_frames']:,} frames had a marker missing and filled): **{r['allocations']} heap "
        f"allocations**, resident memory {r['rss_kib_before']:,} → {r['rss_kib_after']:,} KiB.",
        "",
        "| pushes | p50 | p99 | p99/p50 | max |",
        "|---|---|---|---|---|",
        f"| first 10⁶ | {f[0]:.2f} µs | {f[1]:.2f} µs | {f[1] / f[0]:.2f} | {f[2]:.0f} µs |",
        f"| last 10⁶ | {la[0]:.2f} µs | {la[1]:.2f} µs | {la[1] / la[0]:.2f} | {la[2]:.0f} µs |",
    ]


def criterion_ns(*parts: str) -> float | None:
    path = CRITERION.joinpath(*parts, "new", "estimates.json")
    if not path.exists():
        return None
    return json.loads(path.read_text())["median"]["point_estimate"]


def main() -> None:
    rust = rust_latency()
    lines = [
        "# Performance",
        "",
        f"Generated by `make bench` on {time.strftime('%Y-%m-%d %H:%M')} — {machine()}.",
        "Single thread; random weights of the thesis' shapes (cost does not depend on the values);",
        "window 5. Shared 2-core VM: figures move by ±20 % between runs, compare within one run.",
        "",
        "## `Stream::push` (one frame in, one prediction out)",
        "",
        "| network | MACs | criterion median | Rust p50 | Rust p99 | p99/p50 | Rust max | Python "
        "p50 | Python p99 | Python overhead |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    batch_rows = []
    for label, r in rust.items():
        model = ikid.load(MODELS / f"{label}.safetensors")
        py = python_push(model, PUSHES // 2)
        crit = criterion_ns("push", label)
        crit_s = f"{crit / 1000:.2f} µs" if crit else "n/a"
        lines.append(
            f"| {label} | {r['multiply_adds']:,} | {crit_s} | {r['p50_us']:.2f} µs | {r['p99_us']:.2f} µs | "
            f"{r['p99_us'] / r['p50_us']:.2f} | {r['max_us']:.0f} µs | {py['p50_us']:.2f} µs | "
            f"{py['p99_us']:.2f} µs | {py['overhead_us']:+.2f} µs |"
        )
        n_rows = model.predict(frames_for(model, 1000)).shape[0]
        per_sample = [criterion_ns("predict", f"{label}_threads{t}", "1000") for t in (1, 2)]
        per_sample = [ns / n_rows / 1000 if ns else None for ns in per_sample]
        batch_rows.append((label, *per_sample, python_batch(model)))
    lines += [
        "",
        "p50/p99/max: `cargo run --release -p ikid --example latency` (200k timed pushes after 10k warm-up;",
        "max includes the VM's scheduler hiccups). Python: the same model files, `ikid.Stream.push` timed",
        "with `time.perf_counter_ns` around each call (the timer pair adds ~0.1 µs). "
        "Python overhead: per frame,",
        "a Python loop of `push` minus one `push_many` call on the same 1000 frames, "
        "interleaved, median of 60",
        "rounds; it includes the Python loop itself and the cache lines the interpreter "
        "evicts between frames.",
        "",
        "## `Model::predict` (whole recordings)",
        "",
        "| network | Rust per sample, 1 thread | Rust per sample, 2 threads | Python `Model.predict` "
        "per sample (10k frames, all cores) |",
        "|---|---|---|---|",
    ]
    for label, one, two, py_ps in batch_rows:
        fmt = lambda v: f"{v:.2f} µs" if v else "n/a"  # noqa: E731
        lines.append(f"| {label} | {fmt(one)} | {fmt(two)} | {py_ps:.2f} µs |")
    lines += ["", "Rust: criterion, 1000 frames per call (996 predictions), `Model::predict_with_threads`."]
    lines += [
        "",
        "## C ABI (`libikid`)",
        "",
        "| network | `ikid_stream_push` p50 | p99 | per frame, one call each | per frame, "
        "one `push_many` call | ABI overhead |",
        "|---|---|---|---|---|---|",
    ]
    tracker_lines = []
    for label in rust:
        c = c_abi(label)
        lines.append(
            f"| {label} | {c['push_p50_us']:.2f} µs | {c['push_p99_us']:.2f} µs | "
            f"{c['push_per_frame_ns'] / 1000:.2f} µs | {c['push_many_per_frame_ns'] / 1000:.2f} µs "
            f"| {c['abi_overhead_ns']:+.0f} ns |"
        )
        if "tracker_push_p50_us" in c:
            tracker_lines.append(
                f"| `ikid_tracker_push` (same frames as {label}) | {c['tracker_push_p50_us']:.2f} µs | "
                f"{c['tracker_push_p99_us']:.2f} µs | {c['push_p50_us']:.2f} µs |"
            )
            tracker_lines.append(
                f"| `ikid_tracker_push` + `wrist-track` refiner | "
                f"{c['tracker_refined_push_p50_us']:.2f} µs | {c['tracker_refined_push_p99_us']:.2f} µs | "
                f"{c['push_p50_us']:.2f} µs |"
            )
    if tracker_lines:
        lines += [
            "",
            "| the Kalman tracker from C | p50 | p99 | `ikid_stream_push` p50, same run |",
            "|---|---|---|---|",
            *tracker_lines,
        ]
    lines += [
        "",
        "`target/c/abi_overhead` (benches/c/abi_overhead.c): 200 interleaved rounds "
        "of 1000 frames, median; the",
        "overhead is the per-frame difference between 1000 `ikid_stream_push` calls and "
        "one `ikid_stream_push_many`.",
        "",
        "Zero heap allocations per push: proved by `crates/ikid/tests/allocations.rs` (counting allocator).",
        "",
        *soak(),
        "",
        "## Simulator (`cargo run --release -p ikid-sim --example sim_speed`, one core)",
        "",
        "```",
        subprocess.run(
            ["cargo", "run", "--release", "-q", "-p", "ikid-sim", "--example", "sim_speed"],
            cwd=ROOT,
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip(),
        "```",
    ]
    out = ROOT / "docs" / "performance.md"
    # Keep the section `make bench-peers` writes.
    old = out.read_text() if out.exists() else ""
    peers = old[old.index("<!-- peers:start -->") :] if "<!-- peers:start -->" in old else ""
    out.write_text("\n".join(lines) + "\n" + ("\n" + peers if peers else ""))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
