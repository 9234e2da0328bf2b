"""`make live`: latency from a live source's send to ikid's output, on the loopback, at 1 kHz
with 6 markers (plus one the source sends that ikid ignores).

Each source peer stamps a frame with this machine's monotonic clock as it sends it (LSL's
local_clock; the fake QTM server's µs time stamp); `ikid stream --flush` writes the frame's
line with that stamp; this process reads the line and takes the clock again. So a latency
here is send -> ikid's CSV line read back through a pipe: ikid's sink output plus the pipe.
Runs each source REPEATS times and reports the medians of the per-run p50 and p99; then one
LSL run whose source restarts midway (reconnected). Ends with one line:

    live: lsl_p50_us=… lsl_p99_us=… qtm_p50_us=… qtm_p99_us=… frames=… lost=… reconnected=… sigma_coverage=…
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from live_peers import lsl_config, map_toml  # noqa: E402

PEERS = [sys.executable, str(ROOT / "tests" / "live_peers.py")]
IKID = [sys.executable, "-m", "ikid"]
FRAMES = 10_000
REPEATS = 3


def _read_latencies(proc: subprocess.Popen) -> list[float]:
    """Latency (µs) of each output line as it is read, by its time column."""
    lat: list[float] = []
    assert proc.stdout is not None
    proc.stdout.readline()  # header
    for line in proc.stdout:
        now = time.monotonic()
        stamp = line.split(",", 2)[1]
        if stamp:
            lat.append((now - float(stamp)) * 1e6)
    return lat


def _run(source_cmd: list[str], stream_args: list[str], env, count: int, port_file: Path | None = None):
    peer = subprocess.Popen(source_cmd, env=env, stdout=subprocess.DEVNULL)
    try:
        if port_file is not None:
            deadline = time.monotonic() + 30
            while not (port_file.exists() and port_file.read_text()) and time.monotonic() < deadline:
                time.sleep(0.01)
            stream_args = [a.replace("PORT", port_file.read_text()) for a in stream_args]
        proc = subprocess.Popen(
            [*IKID, "stream", *stream_args, "--count", str(count), "--idle", "10", "--flush"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
        )  # fmt: skip
        err: list[str] = []
        t = threading.Thread(target=lambda: err.append(proc.stderr.read()), daemon=True)  # type: ignore[union-attr]
        t.start()
        lat = _read_latencies(proc)
        proc.wait(timeout=120)
        t.join(10)
        peer.wait(timeout=60)
    finally:
        peer.kill()
    summary = err[0] if err else ""
    lost = sum(int(m) for m in re.findall(r"(\d+) lost", summary))
    skipped = sum(int(m) for m in re.findall(r"(\d+) skipped", summary))
    reconnected = sum(int(m) for m in re.findall(r"(\d+) reconnected", summary))
    if not lat:
        sys.exit(f"make live: no output from ikid stream:\n{summary}")
    return np.array(lat), lost + skipped, reconnected, summary


def main() -> None:
    d = Path(tempfile.mkdtemp(prefix="ikid-live-"))
    (d / "lab.toml").write_text(map_toml())
    mapping = ["--map", str(d / "lab.toml")]
    results: dict[str, list[tuple[float, float]]] = {"lsl": [], "qtm": []}
    frames = lost = reconnected = 0
    for r in range(REPEATS):
        env = lsl_config(d)
        name = f"bench-{r}"
        lat, dropped, _, summary = _run(
            [*PEERS, "lsl-outlet", name, "--frames", str(FRAMES)],
            ["--source", f"lsl:{name}", *mapping],
            env,
            FRAMES,
        )
        results["lsl"].append((float(np.percentile(lat, 50)), float(np.percentile(lat, 99))))
        frames, lost = frames + len(lat), lost + dropped
        print(
            f"lsl run {r}: p50 {results['lsl'][-1][0]:.0f} µs, p99 {results['lsl'][-1][1]:.0f} µs; "
            + summary.strip(),
            flush=True,
        )
        port_file = d / f"qtm-port-{r}"
        lat, dropped, _, summary = _run(
            [*PEERS, "qtm-server", "--frames", str(FRAMES), "--port-file", str(port_file)],
            ["--source", "qtm:127.0.0.1:PORT", *mapping], env, FRAMES, port_file,
        )  # fmt: skip
        results["qtm"].append((float(np.percentile(lat, 50)), float(np.percentile(lat, 99))))
        frames, lost = frames + len(lat), lost + dropped
        print(
            f"qtm run {r}: p50 {results['qtm'][-1][0]:.0f} µs, p99 {results['qtm'][-1][1]:.0f} µs; "
            + summary.strip(),
            flush=True,
        )
    # A source that stops and comes back.
    env = lsl_config(d)
    lat, _, reconnected, summary = _run(
        [*PEERS, "lsl-outlet", "bench-restart", "--frames", "2000", "--restart-at", "1000", "--pause", "0.5"],
        ["--source", "lsl:bench-restart", *mapping], env, 2000,
    )  # fmt: skip
    print(f"lsl restart run: {summary.strip()}", flush=True)
    floor = harness_floor(d)
    print(
        f"harness alone (fake QTM server -> ikid's QTM client in this process; no model, no CSV, no pipe): "
        f"p50 {np.percentile(floor, 50):.0f} µs, p99 {np.percentile(floor, 99):.0f} µs",
        flush=True,
    )
    med = {k: np.median(np.array(v), axis=0) for k, v in results.items()}
    coverage = sigma_coverage()
    print(
        f"live: lsl_p50_us={med['lsl'][0]:.0f} lsl_p99_us={med['lsl'][1]:.0f} qtm_p50_us={med['qtm'][0]:.0f} "
        f"qtm_p99_us={med['qtm'][1]:.0f} frames={frames} lost={lost} reconnected={reconnected} "
        f"sigma_coverage={coverage}"
    )


def harness_floor(d: Path) -> np.ndarray:
    """Latency (µs) of the path without ikid's work: the same fake QTM server process read by
    ikid's QTM client here, each frame timed as it arrives. On a loaded machine the source's
    pacer itself sends late (stamps are capture times): that tail is not ikid's."""
    from ikid.io.mapping import MarkerMap
    from ikid.live import QtmSource

    port_file = d / "qtm-port-floor"
    peer = subprocess.Popen([*PEERS, "qtm-server", "--frames", str(FRAMES), "--port-file", str(port_file)])
    try:
        deadline = time.monotonic() + 30
        while not (port_file.exists() and port_file.read_text()) and time.monotonic() < deadline:
            time.sleep(0.01)
        source = QtmSource("127.0.0.1", int(port_file.read_text()), MarkerMap.load(d / "lab.toml"), 10)
        lat: list[float] = []
        end = time.monotonic() + 60
        while len(lat) < FRAMES - 10 and time.monotonic() < end:
            lat.extend((time.monotonic() - f.time) * 1e6 for f in source.read(0.5) if f.time is not None)
        source.close()
    finally:
        peer.kill()
    return np.array(lat)


def sigma_coverage() -> str:
    """Share of held-out frames whose true angle lies within ±1 σ of the Tracker's σ, with 1 mm
    noise on every marker (studies/sigma_coverage.py; it also prints the torques' figure and
    the other noise conditions)."""
    from studies.sigma_coverage import HEADLINE, coverage, describe

    c = coverage()
    print(describe(c), flush=True)
    return f"{c[f'{HEADLINE}/angles']:.3f}"


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main()
