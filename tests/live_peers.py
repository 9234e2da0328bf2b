"""Peers for the live tests and `make live`: an LSL outlet and inlet (run as processes, each
with the test's own liblsl config, so nothing in the test process calls liblsl) and a fake
Qualisys QTM real-time server (a thread, or a process for the bench). Loopback only.

    python tests/live_peers.py lsl-outlet NAME --frames N [--restart-at K] [--glitch I:DT] ...
    python tests/live_peers.py lsl-inlet NAME --samples N --ready FILE
    python tests/live_peers.py qtm-server --frames N --port-file FILE
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import struct
import sys
import threading
import time
import uuid
from pathlib import Path

import numpy as np

#: The lab's labels for ikid's markers in the peers' streams (a marker map is needed to read them).
LAB_LABELS = {
    "RSP": "R_RSTY",
    "USP": "R_USTY",
    "FAP": "R_FA",
    "MC2": "R_MCP2",
    "MC5": "R_MCP5",
    "MCB": "R_MCB3",
}
#: A marker the source sends that ikid does not use (ignored).
EXTRA_LABEL = "C7"


def lsl_config(directory: Path) -> dict[str, str]:
    """The environment for a process whose liblsl stays on this machine: resolution scoped to
    the machine, listening on 127.0.0.1, no IPv6, and a session id of its own (streams of
    other sessions are invisible to it)."""
    path = directory / f"lsl-{uuid.uuid4().hex}.cfg"
    path.write_text(
        "[ports]\nIPv6 = disable\n"
        "[multicast]\nResolveScope = machine\nListenAddress = 127.0.0.1\n"
        f"[lab]\nSessionID = ikid-test-{uuid.uuid4().hex}\n"
        "[log]\nlevel = -2\n"  # errors only: liblsl's INFO lines would fill the test's stderr
    )
    return {**os.environ, "LSLAPICFG": str(path)}


def map_toml() -> str:
    return "[markers]\n" + "".join(f'{m} = "{lab}"\n' for m, lab in LAB_LABELS.items())


def trial_frames(n: int, seed: int = 5) -> np.ndarray:
    """``n`` frames of a simulated trial at 1 kHz (metres, ikid's marker order)."""
    import ikid

    return ikid.simulate(seed=seed, duration=n / 1000.0 + 0.01).markers[:n].astype(np.float64)


def source_channels(frame_m: np.ndarray, scale: float) -> np.ndarray:
    """A source's channels for one frame (ikid's six markers, or as many as its labels): the
    extra marker first, then the frame's markers in reverse order (the source's order is not
    ikid's), in the source's unit."""
    markers = frame_m.reshape(-1, 3)[::-1]
    return np.concatenate([[0.1, 0.2, 1.4], markers.ravel()]) * scale


def source_labels(labels: list[str] | None = None) -> list[str]:
    """The source's labels: the extra marker's, then ``labels`` (the frame's markers', in its
    order; the lab's six by default) reversed."""
    return [EXTRA_LABEL, *reversed(labels if labels is not None else list(LAB_LABELS.values()))]


def pace(start: float, k: int, rate: float) -> None:
    """Wait until frame ``k``'s send time (sleep most of it, spin the last 0.3 ms)."""
    due = start + k / rate
    while (left := due - time.perf_counter()) > 3e-4:
        time.sleep(left - 3e-4)
    while time.perf_counter() < due:
        pass


def _lsl_outlet(a: argparse.Namespace) -> None:
    import pylsl

    frames = trial_frames(a.frames + 50)
    scale = 1000.0 if a.unit == "millimeters" else 1.0

    def outlet():
        info = pylsl.StreamInfo(a.name, "Mocap", 18 + 3, a.rate, pylsl.cf_float32, "ikid-test-qualisys")
        channels = info.desc().append_child("channels")
        for label in source_labels():
            for axis in "XYZ":
                ch = channels.append_child("channel")
                ch.append_child_value("label", f"{label}_{axis}")
                ch.append_child_value("unit", a.unit)
                ch.append_child_value("type", "Position")
        out = pylsl.StreamOutlet(info, chunk_size=1)
        if not out.wait_for_consumers(20.0):
            sys.exit("no consumer within 20 s")
        return out

    out = outlet()
    if a.ready:  # wait for the other reader (ikid's sink's inlet) to be ready
        deadline = time.monotonic() + 20
        while not Path(a.ready).exists() and time.monotonic() < deadline:
            time.sleep(0.01)
    hide = tuple(int(v) for v in a.hide.split(":")) if a.hide else None
    glitch = (int(a.glitch.split(":")[0]), float(a.glitch.split(":")[1])) if a.glitch else None
    time.sleep(0.05)
    # Each frame stamped with its capture time on this machine's clock (as a mocap system
    # stamps it), and sent once that time has come.
    start, clock0 = time.perf_counter(), pylsl.local_clock()
    for k in range(a.frames):
        if a.restart_at is not None and k == a.restart_at:
            time.sleep(0.1)  # what was pushed is sent (liblsl has no flush), then the source stops
            del out
            time.sleep(a.pause)
            out = outlet()
            start, clock0 = time.perf_counter() - k / a.rate, pylsl.local_clock() - k / a.rate
        sample = source_channels(frames[k], scale)
        if hide and hide[0] <= k < hide[1]:
            sample[3 * (1 + 5 - hide[2]) : 3 * (1 + 5 - hide[2]) + 3] = np.nan  # ikid marker hide[2]
        pace(start, k, a.rate)
        stamp = clock0 + k / a.rate
        if glitch and k == glitch[0]:
            stamp += glitch[1]
        out.push_sample(sample, stamp)
    time.sleep(a.linger)


def _lsl_inlet(a: argparse.Namespace) -> None:
    import pylsl

    infos = pylsl.resolve_byprop("name", a.name, minimum=1, timeout=20)
    if not infos:
        sys.exit(f"no stream {a.name}")
    inlet = pylsl.StreamInlet(infos[0], max_chunklen=1, recover=False)
    info = inlet.info(timeout=5)
    channels, ch = [], info.desc().child("channels").child("channel")
    while not ch.empty():
        channels.append({"label": ch.child_value("label"), "unit": ch.child_value("unit")})
        ch = ch.next_sibling("channel")
    print(json.dumps({"type": info.type(), "rate": info.nominal_srate(), "channels": channels}), flush=True)
    inlet.open_stream(timeout=5)
    Path(a.ready).write_text("ready")
    got = 0
    while got < a.samples:
        sample, stamp = inlet.pull_sample(timeout=a.timeout)
        if stamp is None:
            break
        print(json.dumps([pylsl.local_clock(), stamp, *[None if v != v else v for v in sample]]), flush=True)
        got += 1


# The QTM real-time protocol, as the server side speaks it (little-endian).
HEADER, DATA, COMPONENT, THREE_D = (
    struct.Struct("<II"),
    struct.Struct("<qII"),
    struct.Struct("<II"),
    struct.Struct("<Ihh"),
)
ERROR, COMMAND, XML, FRAME, NO_MORE_DATA = 0, 1, 2, 3, 4


def packet(kind: int, payload: bytes) -> bytes:
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def qtm_parameters(rate: float, names: list[str] | None = None, up: str = "+Y") -> str:
    """QTM's General and 3D parameters: ``up`` its AxisUpwards (QTM's default is +Z; the fake's
    frames are ikid's simulated ones, +Y up, unless it is given frames of another lab)."""
    names = names if names is not None else source_labels()
    labels = "".join(f"<Label><Name>{lab}</Name><RGBColor>255</RGBColor></Label>" for lab in names)
    return (
        f"<QTM_Parameters_Ver_1.25><General><Frequency>{rate:g}</Frequency><Capture_Time>60</Capture_Time>"
        f"</General><The_3D><AxisUpwards>{up}</AxisUpwards>"
        "<CalibrationTime>2026-01-01 12:00:00</CalibrationTime>"
        f"<Labels>{len(names)}</Labels>{labels}</The_3D></QTM_Parameters_Ver_1.25>"
    )


class FakeQtm:
    """A QTM real-time server on 127.0.0.1 streaming ``frames`` (metres, ikid order) as QTM
    would: 3D in mm, NaN for a hidden marker, its own frame numbers (from 1) and µs capture
    time stamps (this machine's monotonic clock, so a reader can time the path). ``drop``: frame
    indices never sent; ``disconnect_at``: the connection is closed before that frame (the
    next connection streams from it); ``hide``: (first, end, ikid marker) hidden; ``burst``:
    every frame sent at once (stamped at the rate all the same: a reader that cannot keep up);
    ``labels``: the frames' markers' labels in their order (the lab's six by default); ``up``:
    the AxisUpwards it declares (its frames' lab's)."""

    def __init__(
        self,
        frames: np.ndarray,
        rate: float = 1000.0,
        drop=(),
        disconnect_at=None,
        hide=None,
        burst=False,
        declared_rate: float | None = None,
        labels: list[str] | None = None,
        up: str = "+Y",
    ) -> None:
        self.frames, self.rate, self.drop, self.hide, self.burst = frames, rate, set(drop), hide, burst
        self.labels, self.up = source_labels(labels), up
        # The rate its parameters declare (a QTM set up otherwise than it captures): ``rate``'s.
        self.declared_rate = rate if declared_rate is None else declared_rate
        self.disconnect_at = disconnect_at
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.listener.settimeout(20)
        self.port = self.listener.getsockname()[1]
        self.next = 0
        self.connections = 0
        self.sent_frames = 0
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        try:
            while self.next < len(self.frames):
                conn, _ = self.listener.accept()
                self.connections += 1
                with conn:
                    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    conn.settimeout(20)
                    self._session(conn)
        except (OSError, TimeoutError):
            pass
        finally:
            self.listener.close()

    def _command(self, conn: socket.socket) -> str:
        head = b""
        while len(head) < 8:
            chunk = conn.recv(8 - len(head))
            if not chunk:
                raise ConnectionError("client left")
            head += chunk
        size, kind = HEADER.unpack(head)
        body = b""
        while len(body) < size - 8:
            body += conn.recv(size - 8 - len(body))
        return body.rstrip(b"\0").decode()

    def _session(self, conn: socket.socket) -> None:
        conn.sendall(packet(COMMAND, b"QTM RT Interface connected\0"))
        while True:
            cmd = self._command(conn)
            low = cmd.lower()
            if low.startswith("version"):
                conn.sendall(packet(COMMAND, f"Version set to {cmd.split()[1]}\0".encode()))
            elif low.startswith("getparameters"):
                parameters = qtm_parameters(self.declared_rate, self.labels, self.up)
                conn.sendall(packet(XML, parameters.encode() + b"\0"))
            elif low.startswith("streamframes"):
                break
            else:
                conn.sendall(packet(ERROR, f"Parse error: {cmd}\0".encode()))
        # QTM stamps a frame with its capture time (µs): here this machine's monotonic clock
        # at the frame's due time, so a reader on this machine can time the path from it.
        start, clock0 = time.perf_counter(), time.monotonic_ns() // 1000
        first = self.next
        while self.next < len(self.frames):
            k = self.next
            if self.disconnect_at is not None and k == self.disconnect_at:
                self.disconnect_at = None
                return
            self.next += 1
            if k in self.drop:
                continue
            xyz = source_channels(self.frames[k], 1000.0).astype("<f4")
            if self.hide and self.hide[0] <= k < self.hide[1]:
                m = len(self.labels) - 1 - self.hide[2]
                xyz[3 * m : 3 * m + 3] = np.nan
            if not self.burst:
                pace(start, k - first, self.rate)
            body = THREE_D.pack(len(self.labels), 0, 0) + xyz.tobytes()
            component = COMPONENT.pack(COMPONENT.size + len(body), 1) + body
            conn.sendall(
                packet(FRAME, DATA.pack(clock0 + round((k - first) * 1e6 / self.rate), k + 1, 1) + component)
            )
            self.sent_frames += 1
        conn.sendall(packet(NO_MORE_DATA, b""))

    def close(self) -> None:
        self.listener.close()
        self.thread.join(5)


def _qtm_server(a: argparse.Namespace) -> None:
    server = FakeQtm(trial_frames(a.frames), a.rate)
    Path(a.port_file).write_text(str(server.port))
    server.thread.join(a.timeout)


def main() -> None:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    o = sub.add_parser("lsl-outlet")
    o.add_argument("name")
    o.add_argument("--frames", type=int, default=1000)
    o.add_argument("--rate", type=float, default=1000.0)
    o.add_argument("--unit", default="millimeters")
    o.add_argument("--restart-at", type=int, default=None)
    o.add_argument("--pause", type=float, default=0.5)
    o.add_argument("--glitch", default=None, help="I:DT: frame I's stamp DT s off")
    o.add_argument("--hide", default=None, help="FIRST:END:MARKER (ikid marker index)")
    o.add_argument("--ready", default=None, help="wait for this file before sending")
    o.add_argument("--linger", type=float, default=0.5)
    i = sub.add_parser("lsl-inlet")
    i.add_argument("name")
    i.add_argument("--samples", type=int, default=1000)
    i.add_argument("--ready", required=True)
    i.add_argument("--timeout", type=float, default=5.0)
    q = sub.add_parser("qtm-server")
    q.add_argument("--frames", type=int, default=1000)
    q.add_argument("--rate", type=float, default=1000.0)
    q.add_argument("--port-file", required=True)
    q.add_argument("--timeout", type=float, default=60.0)
    a = p.parse_args()
    {"lsl-outlet": _lsl_outlet, "lsl-inlet": _lsl_inlet, "qtm-server": _qtm_server}[a.cmd](a)


if __name__ == "__main__":
    main()
