"""What the comparison studies and `make bench`'s report share: the machine they ran on, the
frames they feed a model, and the one way to time ikid's Rust push (`examples/latency.rs`)."""

from __future__ import annotations

import platform
import subprocess
from pathlib import Path

import numpy as np

import ikid

ROOT = Path(__file__).resolve().parents[1]


def machine() -> str:
    """The CPU, as the generated pages state it (lscpu's model, counts, caches, AVX2/FMA)."""
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        wanted = ("Model name", "CPU(s):", "L2 cache", "L3 cache", "Flags")
        lines = [ln for ln in lscpu.splitlines() if ln.startswith(wanted)]
        lines = [
            ("Flags: avx2 fma" if "avx2" in ln and "fma" in ln else "Flags: no avx2/fma")
            if ln.startswith("Flags")
            else ln
            for ln in lines
        ]
        return "; ".join(" ".join(ln.split()) for ln in lines)
    except OSError:
        return platform.processor()


def frames_for(model: ikid.Model, n: int) -> np.ndarray:
    """``n`` input frames for ``model``: random postures within the joint ranges (markers of the
    default subject at 17° shoulder flexion), or uniform states in [-1, 1] for state models."""
    rng = np.random.default_rng(2)
    if model.frame_kind != "markers":  # joint or tracker states
        return rng.uniform(-1, 1, (n, model.frame_len)).astype(np.float32)
    q = np.stack([rng.uniform(lo, hi, n) for _, _, (lo, hi) in ikid.COORDINATES], axis=1)
    return ikid.forward_markers(q, 0.3).astype(np.float32)


def rust_latency(*args: str) -> subprocess.CompletedProcess:
    """Runs the Rust per-push latency example (release) with ``args`` (see
    `crates/ikid/examples/latency.rs`: `--model`, `--tracker`, `--pushes`, `--save-dir`, ...)."""
    cmd = ["cargo", "run", "--release", "-q", "-p", "ikid", "--example", "latency", "--", *args]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
