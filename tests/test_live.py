"""`ikid stream` from live sources: an LSL outlet and a fake Qualisys QTM server on the
loopback, the LSL sink, bad time stamps and frame numbers, bounded reads.

Every LSL peer (the source's outlet, the reader of ikid's sink) and `ikid stream` itself run
as processes with a liblsl config of their own test (``live_peers.lsl_config``): discovery
scoped to this machine, 127.0.0.1, no IPv6, a session id no other test shares. The test
process itself never calls liblsl. Every process is bounded in time; every frame count is
fixed."""

from __future__ import annotations

import io
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import ikid
from live_peers import LAB_LABELS, FakeQtm, lsl_config, map_toml, trial_frames

pytest.importorskip("pylsl", reason="the live extra (pip install 'ikid[live]'); the test extra pulls it in")

PEERS = [sys.executable, str(Path(__file__).with_name("live_peers.py"))]
IKID = [sys.executable, "-m", "ikid"]


def _header_and_rows(out: str):
    lines = out.strip().splitlines()
    if not lines:
        return [], []
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    return header, rows


def _summary(err: str) -> str:
    return "\n".join(line for line in err.splitlines() if line.startswith("ikid stream:"))


def _count(summary: str, what: str) -> int:
    """The number before ``what`` in the summary (0 when absent)."""
    import re

    m = re.search(r"(\d+) " + re.escape(what), summary)
    return int(m.group(1)) if m else 0


@pytest.fixture
def lab(tmp_path):
    """A folder with the lab's marker map and an LSL environment of this test's own."""
    (tmp_path / "lab.toml").write_text(map_toml())
    return tmp_path, lsl_config(tmp_path)


def _as_sent_in_mm(frames_m: np.ndarray) -> np.ndarray:
    """Frames as a source sends them in float32 millimetres and ikid reads them back in metres."""
    return (frames_m * 1000.0).astype(np.float32).astype(np.float64) * 1e-3


def _offline(frames_m: np.ndarray, times: np.ndarray, model: str = "wrist-ik") -> list:
    """The oracle: the same frames pushed into ikid.Stream in the test process."""
    s = ikid.load(model).stream()
    out = []
    for f, t in zip(frames_m, times, strict=True):
        try:
            r = s.push(f.astype(np.float32), time=float(t))
        except ikid.InputError:
            r = None
        out.append(None if r is None else np.asarray(r, np.float64))
    return out


def _lsl_pipeline(d, env, n: int, name: str, sink: str, outlet_args: list[str], stream_args: list[str]):
    """Runs an LSL outlet of ``n`` frames named ``name``, ``ikid stream`` from it to the sink
    ``sink`` and an inlet reading the sink, all bounded in time; returns ``ikid stream``'s exit
    code, stdout and stderr and the inlet's stdout and stderr."""
    ready = d / "sink-ready"
    outlet = subprocess.Popen(
        [*PEERS, "lsl-outlet", name, "--frames", str(n), *outlet_args, "--ready", str(ready)],
        env=env, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    stream = subprocess.Popen(
        [*IKID, "stream", "--source", f"lsl:{name}", "--map", str(d / "lab.toml"), "--sink", f"lsl:{sink}",
         "--count", str(n), "--idle", "10", *stream_args],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    reader = subprocess.Popen(
        [*PEERS, "lsl-inlet", sink, "--samples", str(n), "--ready", str(ready), "--timeout", "5"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        out, err = stream.communicate(timeout=60)
        got, reader_err = reader.communicate(timeout=30)
        outlet.wait(timeout=30)
    finally:
        for p in (outlet, stream, reader):
            p.kill()
    return stream.returncode, out, err, got, reader_err


def test_lsl_source_in_and_lsl_sink_out(lab):
    """600 frames at 1 kHz in mm with the lab's labels and an extra marker; MC5 hidden for
    20 frames. Outputs equal ikid.Stream's on the same frames and times; the sink's stream
    has labels, units and the source's stamps."""
    d, env = lab
    n, name, sink = 600, f"qualisys-{os.getpid()}-a", f"ikid-{os.getpid()}-a"
    code, out, err, got, reader_err = _lsl_pipeline(d, env, n, name, sink, ["--hide", "300:320:4"], [])
    # MC5 hidden: a gap, filled or refused by name as in files (refused frames: exit 3).
    assert code in (0, 3), err
    header, rows = _header_and_rows(out)
    assert header[:3] == ["frame", "time", "status"] and header[3:] == ikid.load("wrist-ik").output_names
    assert len(rows) == n
    times = np.array([float(r[1]) for r in rows])
    assert np.all(np.diff(times) > 0)
    # The oracle: the trial's frames (metres, ikid order), MC5 hidden on 300-319.
    frames = _as_sent_in_mm(trial_frames(n + 50)[:n])
    frames[300:320, 12:15] = np.nan
    expected = _offline(frames, times)
    filled = [k for k, r in enumerate(rows) if r[2].startswith("filled")]
    assert set(filled) <= set(range(300, 320))
    assert all(rows[k][2] == "filled:MC5" or "MC5" in rows[k][2] for k in range(300, 320)), rows[300]
    assert (code == 3) == any(r[2].startswith("refused") for r in rows)
    for k, r in enumerate(rows):
        if expected[k] is None:
            assert r[3] == "", (k, r)
        else:
            np.testing.assert_allclose([float(v) for v in r[3:]], expected[k], rtol=2e-6, atol=1e-6)
    summary = _summary(err)
    assert "0 lost (by time)" in summary and "0 skipped" in summary and "0 reconnected" in summary
    # The sink: metadata, then one sample per output frame, stamped with the source's time.
    import json

    lines = got.strip().splitlines()
    meta = json.loads(lines[0])
    labels = [c["label"] for c in meta["channels"]]
    assert meta["type"] == "Kinematics" and labels == [*ikid.load("wrist-ik").output_names, "status"]
    assert [c["unit"] for c in meta["channels"]] == ["rad", "rad", "rad", "bits"]
    samples = [json.loads(line) for line in lines[1:]]
    with_output = [k for k in range(n) if expected[k] is not None]
    assert len(samples) == len(with_output), reader_err
    stamps = np.array([s[1] for s in samples])
    np.testing.assert_allclose(stamps, times[with_output], atol=2e-6)
    values = np.array([s[2:5] for s in samples])
    np.testing.assert_array_equal(values, np.array([expected[k] for k in with_output]))  # float32 -> double
    status = np.array([s[5] for s in samples])
    assert np.all(status[np.isin(with_output, filled)].astype(int) & ikid._native.FRAME_STATUS["filled"])


def _lsl_run(lab, n: int, *outlet_args: str, idle: float = 5.0):
    d, env = lab
    name = f"qualisys-{os.getpid()}-{time.monotonic_ns()}"
    outlet = subprocess.Popen([*PEERS, "lsl-outlet", name, "--frames", str(n), *outlet_args], env=env)
    try:
        r = subprocess.run(
            [*IKID, "stream", "--source", f"lsl:{name}", "--map", str(d / "lab.toml"), "--idle", str(idle),
             "--count", str(n)],
            env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        if r.returncode != 2:  # refused before reading: the outlet would wait for it in vain
            outlet.wait(timeout=30)
    finally:
        outlet.kill()
    return r, _header_and_rows(r.stdout)[1]


def test_an_lsl_source_that_restarts_is_reconnected(lab):
    """The outlet goes away after 300 frames and a new one of the same name comes back 0.5 s
    later: ikid reconnects, restarts its window, and takes the 300 frames that follow."""
    r, rows = _lsl_run(lab, 600, "--restart-at", "300", "--pause", "0.5")
    summary = _summary(r.stderr)
    assert _count(summary, "reconnected") == 1, r.stderr
    assert len(rows) == 600 and not any(row[2].startswith("refused") for row in rows), summary
    # The window refills after the reconnection, then outputs.
    window = ikid.load("wrist-ik").window
    assert [row[2] for row in rows[300 : 300 + window]] == ["filling"] * (window - 1) + ["ok"]


def test_an_lsl_stamp_600_s_ahead_is_refused_alone(lab):
    r, rows = _lsl_run(lab, 800, "--glitch", "400:600")
    refused = [k for k, row in enumerate(rows) if row[2].startswith("refused")]
    assert refused == [400], r.stderr
    assert "time stamp jumped" in r.stderr and r.returncode == 3
    assert _count(_summary(r.stderr), "lost (by time)") == 0


def test_lsl_source_without_the_labels_is_refused_by_name(lab):
    d, env = lab
    (d / "lab.toml").write_text(map_toml().replace("R_MCP5", "R_MCP5_WRONG"))
    r, rows = _lsl_run(lab, 50, "--linger", "0")
    assert r.returncode == 2
    assert "R_MCP5_WRONG (MC5) not found" in r.stderr and "R_MCP2" in r.stderr, r.stderr


def _qtm_stream(server: FakeQtm, tmp_path, *extra: str, count: int) -> subprocess.CompletedProcess:
    (tmp_path / "lab.toml").write_text(map_toml())
    return subprocess.run(
        [*IKID, "stream", "--source", f"qtm:127.0.0.1:{server.port}", "--map", str(tmp_path / "lab.toml"),
         "--idle", "3", "--count", str(count), *extra],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip


def test_qtm_source_with_hidden_markers_dropped_frames_and_a_reconnection(tmp_path):
    n = 1000
    frames = trial_frames(n)
    drop = range(500, 505)
    server = FakeQtm(frames, drop=drop, disconnect_at=700, hide=(200, 215, 4))
    try:
        r = _qtm_stream(server, tmp_path, count=n - len(drop))
    finally:
        server.close()
    assert server.connections == 2
    header, rows = _header_and_rows(r.stdout)
    assert header[:3] == ["frame", "time", "status"]
    numbers = [int(row[0]) for row in rows]
    assert numbers == [k + 1 for k in range(n) if k not in drop]  # QTM's own frame numbers
    summary = _summary(r.stderr)
    assert _count(summary, "lost (by frame number)") == len(drop), summary
    assert _count(summary, "reconnected") == 1 and r.returncode == 3  # frames were lost
    status = {int(row[0]) - 1: row[2] for row in rows}
    # A hidden marker is a gap: filled or refused by name, as in files; nothing else is.
    assert all(status[k] == "filled:MC5" or "MC5" in status[k] for k in range(200, 215)), status[200]
    assert not any(s.startswith("filled") for k, s in status.items() if k not in range(200, 215))
    # Outputs equal ikid.Stream's on the same frames (mm -> m through float32, as QTM sends)
    # with QTM's stamps, the stream restarted at the reconnection as ikid does.
    sent = np.array([k for k in range(n) if k not in drop])
    as_sent = _as_sent_in_mm(frames)
    as_sent[200:215, 12:15] = np.nan
    times = np.array([float(row[1]) for row in rows])
    before = sent < 700
    expected = _offline(as_sent[sent[before]], times[before]) + _offline(
        as_sent[sent[~before]], times[~before]
    )
    for k, row in enumerate(rows):
        if expected[k] is None:
            assert row[3] == "", (k, row)
        else:
            np.testing.assert_allclose([float(v) for v in row[3:]], expected[k], rtol=2e-6, atol=1e-6)


def test_a_source_declaring_another_rate_than_it_sends_says_so_and_rate_overrides_it(tmp_path):
    # Review 4: an outlet declaring 250 Hz while sending at 100 Hz had every frame refused as
    # "bad argument", the summary said "give --rate 100", and --rate 100 was then refused as
    # "for a source that declares no rate": a dead end. The stamps name the source's rate and
    # --rate now overrides a declared one, said so.
    frames = trial_frames(2000)[::10]  # 200 frames, 100 Hz
    for extra in ((), ("--rate", "100")):
        server = FakeQtm(frames, rate=100.0, declared_rate=250.0)
        try:
            r = _qtm_stream(server, tmp_path, *extra, count=len(frames))
        finally:
            server.close()
        _, rows = _header_and_rows(r.stdout)
        status = [row[2].split(":")[0] for row in rows]
        summary = _summary(r.stderr)
        if not extra:
            assert r.returncode == 3, r.stderr
            assert (
                "the time stamps come 10 ms apart, a 100 Hz source read at 250 Hz: give --rate 100" in summary
            )
            refused = _count(summary, "time stamps at another rate than the stream's")
            assert refused == status.count("refused") > 100
        else:
            assert r.returncode == 0, r.stderr
            assert "--rate 100 Hz overrides the qtm source's declared 250 Hz" in r.stderr
            filling = ikid.load("wrist-ik-100hz").window - 1  # the 100 Hz member's window filling
            assert status == ["filling"] * filling + ["ok"] * (len(frames) - filling), summary


def test_a_source_declaring_a_rate_close_to_the_one_it_sends_is_stopped_by_its_stamps(tmp_path):
    # Review 6: a QTM declaring 100 Hz while it captures at 80 Hz: each stamp 1.25 periods on,
    # within the jitter a frame may take, so all were read as 100 Hz frames, every line "ok",
    # nothing said. The stamps' mean step refuses them once it is known (the core's
    # RATE_CHECK_STEPS), the summary says the source's rate and that no network runs at it.
    frames = trial_frames(2500)[::12][:200]
    server = FakeQtm(frames, rate=80.0, declared_rate=100.0)
    try:
        r = _qtm_stream(server, tmp_path, count=len(frames))
    finally:
        server.close()
    _, rows = _header_and_rows(r.stdout)
    status = [row[2] for row in rows]
    summary = _summary(r.stderr)
    assert r.returncode == 3, r.stderr
    first = status.index(next(s for s in status if s.startswith("refused")))
    assert first == 128 and all(s.startswith("refused:") for s in status[first:]), status[first]
    assert "the source runs at about 80 Hz; the model was trained at 100 Hz; no member" in status[first]
    assert _count(summary, "time stamps at another rate than the stream's") == len(frames) - first
    assert "a 80 Hz source read at 100 Hz: no member of the model's family runs at it" in summary, summary
    assert "give --tracker --rate 80" in summary


def test_a_reader_that_falls_behind_takes_the_newest_frame_and_counts_the_rest(tmp_path):
    """QTM sends 3000 frames at once: more than --max-lag's worth waits at each read, so ikid
    takes the newest and counts the others as skipped; every frame is either read or skipped."""
    n = 3000
    server = FakeQtm(trial_frames(n), burst=True)
    try:
        r = _qtm_stream(server, tmp_path, "--max-lag", "0.002", count=n)
    finally:
        server.close()
    _, rows = _header_and_rows(r.stdout)
    summary = _summary(r.stderr)
    skipped = _count(summary, "skipped")
    assert skipped > 0 and len(rows) + skipped == n, summary
    assert _count(summary, "lost (by frame number)") == 0 and "refused" not in summary, summary
    assert r.returncode == 3
    numbers = [int(row[0]) for row in rows]
    assert numbers == sorted(numbers) and numbers[-1] == n  # the newest is always taken


def test_the_fake_qtm_server_speaks_qualisys_own_client(tmp_path):
    """qtm-rt (Qualisys' Python SDK) reads the fake server's parameters and frames as it
    reads QTM's: the tests' server is checked against the real client, not against ikid's."""
    qtm_rt = pytest.importorskip("qtm_rt")
    import asyncio
    import xml.etree.ElementTree as ET

    frames = trial_frames(40)
    server = FakeQtm(frames, hide=(5, 6, 0))
    got = []

    async def client():
        conn = await qtm_rt.connect("127.0.0.1", port=server.port, version="1.25", timeout=5)
        assert conn is not None
        xml = await conn.get_parameters(parameters=["general", "3d"])
        root = ET.fromstring(xml)
        labels = [e.text for e in root.findall("./The_3D/Label/Name")]
        done = asyncio.Event()

        def on_packet(packet):
            header, markers = packet.get_3d_markers()
            got.append((packet.framenumber, [(m.x, m.y, m.z) for m in markers]))
            if len(got) == 10:
                done.set()

        await conn.stream_frames(components=["3d"], on_packet=on_packet)
        await asyncio.wait_for(done.wait(), 10)
        conn.disconnect()
        return labels, root.findtext("./General/Frequency")

    try:
        labels, rate = asyncio.run(asyncio.wait_for(client(), 20))
    finally:
        server.close()
    assert labels == ["C7", *[LAB_LABELS[m] for m in reversed(list(LAB_LABELS))]] and float(rate) == 1000.0
    assert [g[0] for g in got[:10]] == list(range(1, 11))
    rsp = labels.index(LAB_LABELS["RSP"])
    for number, markers in got[:10]:
        k = number - 1
        xyz = np.array(markers[rsp])
        if k == 5:
            assert np.isnan(xyz).all()  # hidden: NaN, as QTM sends it
        else:
            np.testing.assert_allclose(xyz, frames[k, :3] * 1000, rtol=1e-6)


def _stamped_lines(frames: np.ndarray, times: np.ndarray) -> str:
    rows = np.column_stack([times, frames])
    buf = io.StringIO()
    np.savetxt(buf, rows, delimiter=",", fmt="%.17g")
    return buf.getvalue()


@pytest.mark.parametrize("bad", [600.0, 1e300, -5.0, "repeat"])
def test_one_bad_stamp_on_stdin_is_refused_alone(bad):
    n, k0 = 3000, 1000
    frames = trial_frames(n)
    times = np.arange(n) * 1e-3
    times[k0] = times[k0 - 1] if bad == "repeat" else times[k0] + bad
    r = subprocess.run(
        [*IKID, "stream", "--time"],
        input=_stamped_lines(frames, times),
        capture_output=True,
        text=True,
        timeout=120,
    )
    _, rows = _header_and_rows(r.stdout)
    refused = [k for k, row in enumerate(rows) if row[1].startswith("refused")]
    assert refused == [k0], (bad, refused[:10], r.stderr)
    assert "1 time stamp jumped (refused alone)" in r.stderr
    assert _count(_summary(r.stderr), "lost (by time)") == 0  # refused, not lost


def test_one_bad_frame_number_on_stdin_is_refused_alone():
    n, k0 = 2000, 700
    frames = trial_frames(n)
    numbers = np.arange(n) + 1
    numbers[k0] = 10**9
    rows = np.column_stack([numbers, frames])
    buf = io.StringIO()
    np.savetxt(buf, rows, delimiter=",", fmt="%.17g")
    r = subprocess.run(
        [*IKID, "stream", "--rate", "1000", "--frame-number"],
        input=buf.getvalue(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    _, out = _header_and_rows(r.stdout)
    assert [k for k, row in enumerate(out) if row[1].startswith("refused")] == [k0], r.stderr
    assert _count(_summary(r.stderr), "lost (by frame number)") == 1  # frame k0's own number never came


def test_a_long_line_on_stdin_is_refused_with_bounded_memory():
    """256 MiB with no newline, then good lines: the long line is refused, the rest is read,
    and the process never holds the line (its peak RSS, VmHWM, read while it runs: a forked
    child's rusage would count the test process's own memory)."""
    if not Path("/proc/self/status").exists():
        pytest.skip("peak memory is read from /proc/<pid>/status (Linux)")
    frames = trial_frames(20)
    good = _stamped_lines(frames, np.arange(20) * 1e-3)
    proc = subprocess.Popen([*IKID, "stream", "--time"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)  # fmt: skip
    import threading

    def feed():
        assert proc.stdin is not None
        chunk = b"1" * (1 << 20)
        for _ in range(256):
            proc.stdin.write(chunk)
        proc.stdin.write(b"\n" + good.encode())
        proc.stdin.close()

    out: list[bytes] = []
    reader = threading.Thread(target=lambda: out.append(proc.stdout.read()), daemon=True)  # type: ignore[union-attr]
    reader.start()
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    peak_kb = 0
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            status_text = Path(f"/proc/{proc.pid}/status").read_text()
        except OSError:
            break  # gone between poll and read
        hwm = [line.split()[1] for line in status_text.splitlines() if line.startswith("VmHWM:")]
        peak_kb = max(peak_kb, int(hwm[0]) if hwm else 0)
        time.sleep(0.02)
    feeder.join(10)
    proc.wait(timeout=30)
    reader.join(10)
    err = proc.stderr.read().decode()  # type: ignore[union-attr]
    lines = out[0].decode().strip().splitlines()
    assert lines[1].split(",")[1].startswith("refused:line longer than"), lines[1][:200]
    assert len(lines) == 1 + 1 + 20 and "1 unreadable line" in err
    peak_mb = peak_kb / 1024
    assert 0 < peak_mb < 100, f"peak RSS {peak_mb:.0f} MB"


def test_stdin_frames_read_too_late_are_not_skipped():
    """--max-lag is for live sources: a file piped in is read whole, nothing skipped."""
    frames = trial_frames(300)
    r = subprocess.run(
        [*IKID, "stream", "--time", "--max-lag", "0.001"],
        input=_stamped_lines(frames, np.arange(300) * 1e-3), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert len(_header_and_rows(r.stdout)[1]) == 300


def test_a_qtm_source_that_never_answers_is_an_error_not_a_hang(tmp_path):
    import socket

    with socket.create_server(("127.0.0.1", 0)) as silent:
        port = silent.getsockname()[1]
        t0 = time.monotonic()
        r = subprocess.run(
            [*IKID, "stream", "--source", f"qtm:127.0.0.1:{port}", "--idle", "1"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    assert r.returncode == 2 and "qtm:127.0.0.1" in r.stderr, r.stderr
    assert time.monotonic() - t0 < 30
    assert not math.isnan(0.0)


def test_sources_and_sinks_are_named_and_checked():
    for argv, words in [
        (["--source", "zmq:x"], ["lsl:<stream name>", "qtm:<host>"]),
        (["--source", "qtm:127.0.0.1:99999"], ["port 99999"]),
        (["--sink", "csv"], ["lsl:<stream name>"]),
        (["--udp", "0", "--source", "lsl:x"], ["give one"]),
        (["--map", "x.toml"], ["--map is for a live source"]),
    ]:
        r = subprocess.run(
            [*IKID, "stream", *argv], capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL
        )
        assert r.returncode == 2 and all(w in r.stderr for w in words), (argv, r.stderr)


def test_the_tracker_path_writes_each_value_with_its_standard_deviation():
    n = 400
    frames = trial_frames(n)
    frames[200:230, 12:15] = np.nan  # MC5 hidden: the tracker goes on without it
    r = subprocess.run(
        [*IKID, "stream", "--tracker", "--time", "--rate", "1000"],
        input=_stamped_lines(frames, np.arange(n) * 1e-3).replace("nan", ""),
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    header, rows = _header_and_rows(r.stdout)
    # The frames MC5 was hidden in say so (the tracker fills nothing: it went without it).
    assert [row[1] for row in rows[200:230]] == ["missing:MC5"] * 30 and rows[199][1] == rows[230][1] == "ok"
    assert "30 missing" in r.stderr, r.stderr
    names = [c[0] for c in ikid._native.COORDINATES]
    values = names + [f"{c}_moment" for c in names]
    assert header[2:] == [h for v in values for h in (v, f"{v}_sd")]
    # The oracle: ikid.Tracker on the same frames in this process.
    tracker = ikid.Tracker(rate_hz=1000.0)
    for k, row in enumerate(rows):
        out = tracker.push(frames[k])
        sd = tracker.output_sd
        if out is None:
            assert row[1] == "filling" and row[2] == ""
            continue
        got = np.array([float(v) for v in row[2:]]).reshape(6, 2)
        np.testing.assert_allclose(got[:, 0], np.concatenate([out[0], out[3]]), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(got[:, 1], np.concatenate([sd[0], sd[1]]), rtol=1e-6)
        assert np.all(got[:, 1] > 0)


def test_a_tracker_that_never_starts_for_a_marker_never_seen_says_so_and_exits_non_zero():
    # Review 6: MC5 left unlabelled by the mocap system: every line "filling", exit 0, even
    # with --strict, and nothing named the marker (the networks refuse each frame by name).
    n = 200
    frames = trial_frames(n)
    frames[:, 12:15] = np.nan
    lines = _stamped_lines(frames, np.arange(n) * 1e-3).replace("nan", "")
    for strict in ([], ["--strict"]):
        r = subprocess.run(
            [*IKID, "stream", "--tracker", "--time", "--rate", "1000", *strict],
            input=lines, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        _, rows = _header_and_rows(r.stdout)
        why = "missing MC5: the tracker starts from a frame with every marker"
        if strict:
            assert r.returncode == 2 and why in r.stderr and len(rows) == 0, r.stderr
        else:
            assert r.returncode == 3, r.stderr
            assert [row[1] for row in rows] == [f"refused:{why}"] * n
            assert f"{n} {why}" in r.stderr, r.stderr


def test_the_lsl_sink_carries_the_networks_standard_deviations(lab):
    """``--sd``: each output followed by its σ (``Stream.output_sd``) on the sink, channels named
    ``<output>_sd`` in the output's unit; a frame before its σ is known is not published."""
    import json

    d, env = lab
    n, name, sink = 300, f"qualisys-{os.getpid()}-sd", f"ikid-{os.getpid()}-sd"
    code, out, err, got, reader_err = _lsl_pipeline(d, env, n, name, sink, [], ["--sd"])
    assert code == 0, err
    _, rows = _header_and_rows(out)
    times = np.array([float(r[1]) for r in rows])
    # The oracle: the same frames and times through ikid.Stream in this process.
    s = ikid.load("wrist-ik").stream()
    expected = []
    for f, t in zip(_as_sent_in_mm(trial_frames(n + 50)[:n]), times, strict=True):
        value = s.push(f.astype(np.float32), time=float(t))
        sd = s.output_sd
        expected.append(None if value is None or sd is None else np.column_stack([value, sd]).ravel())
    lines = got.strip().splitlines()
    meta = json.loads(lines[0])
    names = ikid.load("wrist-ik").output_names
    assert [c["label"] for c in meta["channels"]] == [*(x for v in names for x in (v, f"{v}_sd")), "status"]
    assert [c["unit"] for c in meta["channels"]] == ["rad"] * 6 + ["bits"]
    samples = [json.loads(line) for line in lines[1:]]
    with_output = [k for k in range(n) if expected[k] is not None]
    assert len(samples) == len(with_output) and len(with_output) > n - 60, reader_err
    values = np.array([smp[2:8] for smp in samples])
    np.testing.assert_allclose(values, np.array([expected[k] for k in with_output]), rtol=1e-6)
    assert np.all(values[:, 1::2] > 0)
