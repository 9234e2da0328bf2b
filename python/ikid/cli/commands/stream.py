"""`ikid stream`: live frames (stdin or UDP) in, one CSV line per frame out."""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter

import numpy as np

import ikid
from ikid.cli.common import _model_file, _model_for, _refuse_over_inputs, _stdout_fd
from ikid.cli.options import PORT, POSITIVE, POSITIVE_INT, unchecked_option


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "stream",
        help="live frames (stdin or UDP on 127.0.0.1) -> one CSV line per frame",
        description="Frames in, one result line out per frame (CSV: frame,status,outputs).\n\n"
        "  ikid stream < frames.csv                          # 18 numbers per line (m)\n"
        "  ikid stream --time --torque-model wrist-chain < frames.csv   # time first\n"
        "  ikid stream --udp 9870 --count 100000 --idle 5     # datagrams, 'END' stops\n"
        "  ikid stream --udp 9870 --frame-number --time       # 'N,t,x1,...,z6': lost frames counted\n\n"
        "At the end, a summary on stderr: frames received, ok, filled, filling, refused (by\n"
        "reason) and lost (counted from the source's frame numbers, --frame-number, or its\n"
        "times, --time). UDP asks for an 8 MiB receive buffer for bursts and says if it got less.\n\n"
        "Exit status: 0 every frame was processed; 3 frames were lost or refused; 2 an error\n"
        "(or, with --strict, the first refused frame).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default="wrist-ik", help="model (default wrist-ik)")
    p.add_argument(
        "--torque-model", default=None, help="a second model on the same frames (e.g. wrist-chain)"
    )
    p.add_argument(
        "--udp",
        type=PORT,
        default=None,
        metavar="PORT",
        help="read datagrams on 127.0.0.1:PORT (0: any free port)",
    )
    p.add_argument("--count", type=POSITIVE_INT, default=None, help="stop after this many frames")
    p.add_argument(
        "--idle", type=POSITIVE, default=10.0, help="UDP: stop after this many seconds without a frame"
    )
    p.add_argument(
        "--time",
        action="store_true",
        help="each line starts with the frame's time (s): gaps restart the window and count lost frames",
    )
    p.add_argument(
        "--frame-number",
        action="store_true",
        help="each line starts with the source's frame number (before the time with --time): a jump "
        "counts the frames lost between; a number not after the last is refused",
    )
    p.add_argument(
        "--rate",
        type=POSITIVE,
        default=None,
        help="the source's frame rate (Hz): the model family's member at that rate (wrist-ik at 100 -> "
        "wrist-ik-100hz); refused if it has none (a live stream is not resampled)",
    )
    p.add_argument(
        "--missing-markers", choices=["fill", "refuse"], default=None, help="override the model's policy"
    )
    p.add_argument(
        "--calibration", metavar="JSON", help="the subject's marker placement (see `ikid calibrate`)"
    )
    p.add_argument("--strict", action="store_true", help="stop at the first refused frame (exit 2)")
    p.add_argument("--flush", action="store_true", help="flush stdout after every line (for pipes read live)")
    unchecked_option(p)
    p.set_defaults(func=run)


#: Exit status of `ikid stream` when it ran to the end but frames were lost or refused.
EXIT_FRAMES_LOST = 3


def _parse_frame(
    line: str, frame_len: int, with_time: bool, with_number: bool = False
) -> tuple[int | None, float | None, np.ndarray]:
    """One text frame: the source's frame number first with ``--frame-number``, then the time
    with ``--time``, then ``frame_len`` numbers (comma, semicolon, tab or space separated). An
    empty field or ``nan`` is a missing value."""
    line = line.strip()
    fields = [f.strip() for f in line.split(",")] if "," in line else line.replace(";", " ").split()
    lead = int(with_number) + int(with_time)
    want = frame_len + lead
    if len(fields) != want:
        first = ("frame number + " if with_number else "") + ("time + " if with_time else "")
        raise ikid.InputError(f"expected {want} values ({first}{frame_len} frame values), got {len(fields)}")
    number = None
    if with_number:
        try:
            number = int(fields[0])
        except ValueError:
            raise ikid.InputError(f"frame number {fields[0]!r} is not an integer") from None
        fields = fields[1:]
    try:
        values = np.array([float(f) if f else np.nan for f in fields], np.float64)
    except ValueError as e:
        raise ikid.InputError(f"not a number: {e}") from None
    if with_time and not math.isfinite(values[0]):
        raise ikid.InputError(f"time {fields[0]!r} is not a finite number")
    return (number, float(values[0]), values[1:]) if with_time else (number, None, values)


#: Receive buffer `ikid stream --udp` asks for, bytes: a burst of 40,000 frames (~200 bytes a
#: datagram) — a second of a 42 kHz burst, or 40 s at 1 kHz of a reader that stalled.
UDP_RECEIVE_BUFFER = 8 << 20


def _receive_buffer(sock, want: int = UDP_RECEIVE_BUFFER) -> int:
    """Ask for a ``want``-byte receive buffer; the size granted (the system caps it: Linux's
    ``net.core.rmem_max``). Linux reports twice what it grants (its bookkeeping): halved here."""
    import socket

    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, want)
    except OSError:
        pass  # the default stays; reported below
    granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    return granted // 2 if sys.platform.startswith("linux") else granted


def _udp_lines(port: int, count: int | None, idle_s: float):
    """Datagrams on 127.0.0.1:``port`` as text lines, until ``count`` frames, an ``END``
    datagram, or ``idle_s`` seconds without one."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        granted = _receive_buffer(sock)
        sock.bind(("127.0.0.1", port))
        sock.settimeout(idle_s)
        print(f"ikid stream: listening on udp 127.0.0.1:{sock.getsockname()[1]}", file=sys.stderr, flush=True)
        note = (
            ""
            if granted >= UDP_RECEIVE_BUFFER
            else f", asked for {UDP_RECEIVE_BUFFER} (the system's limit; on Linux raise net.core.rmem_max): "
            "a larger burst overflows it and its frames are lost"
        )
        print(f"ikid stream: receive buffer {granted} bytes{note}", file=sys.stderr, flush=True)
        received = 0
        while count is None or received < count:
            try:
                data = sock.recv(65536)
            except TimeoutError:
                print(f"ikid stream: no frame for {idle_s:g} s, stopping", file=sys.stderr)
                return
            for line in data.decode("utf-8", "replace").splitlines():
                if line.strip() == "END":
                    return
                if line.strip():
                    received += 1
                    yield line


class _Losses:
    """Frames lost between those received: from the source's frame numbers (a jump of k is
    k - 1 lost), else from its times (a gap of k periods is k - 1 lost). A frame whose number
    is not after the last one's is refused (late or repeated)."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.lost = 0
        self.last_number: int | None = None
        self.last_time: float | None = None

    def number(self, n: int) -> None:
        if self.last_number is not None:
            if n <= self.last_number:
                raise ikid.InputError(f"frame number {n} after {self.last_number} (late or repeated)")
            self.lost += n - self.last_number - 1
        self.last_number = n

    def time(self, t: float) -> None:
        if self.last_time is not None and t > self.last_time:
            self.lost += max(0, round((t - self.last_time) * self.rate_hz) - 1)
        self.last_time = t


def run(args: argparse.Namespace) -> int:
    """Frames (text lines) from stdin or UDP -> one CSV line per frame on stdout:
    ``frame,status,<outputs>``; status ``ok``, ``filled:<markers>``, ``filling`` (window not
    full yet) or ``refused:<reason>`` (outputs empty). Nothing is skipped silently: the summary
    on stderr counts frames received, refused (by reason) and lost; exit status 0 if every
    frame was processed, 3 if frames were lost or refused, 2 on an error."""
    from ikid.pipeline import refusal_reason

    stdin = None
    if args.udp is None:
        try:
            stdin = sys.stdin.fileno()
        except (AttributeError, OSError, ValueError):
            pass
    _refuse_over_inputs(
        [_stdout_fd()],
        [stdin, args.calibration, _model_file(args.model), _model_file(args.torque_model)],
    )
    unchecked = args.allow_unchecked_model
    models = [_model_for(args.model, "ikid stream --model", ("ik", "chain"), args.rate, unchecked)]
    if args.torque_model:
        models.append(
            _model_for(args.torque_model, "ikid stream --torque-model", ("chain",), args.rate, unchecked)
        )
    rate = models[0].frame_rate_hz
    for m in models:
        if m.frame_len != models[0].frame_len:
            raise ikid.InputError(f"models {models[0].name!r} and {m.name!r} read different frames")
    calibration = ikid.load_calibration(args.calibration) if args.calibration else None
    streams = [m.stream(missing_markers=args.missing_markers, calibration=calibration) for m in models]
    names = [n for m in models for n in m.output_names]
    out = sys.stdout
    out.write("frame,status," + ",".join(names) + "\n")
    lines = (
        _udp_lines(args.udp, args.count, args.idle)
        if args.udp is not None
        else (line for k, line in enumerate(sys.stdin) if args.count is None or k < args.count)
    )
    counts: Counter = Counter()
    refused: Counter = Counter()
    losses = _Losses(rate)
    frame = 0
    for line in lines:
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        status, values, label = "ok", "", frame
        try:
            try:
                number, t, x = _parse_frame(line, models[0].frame_len, args.time, args.frame_number)
            except ikid.InputError as e:
                raise _Refused(str(e), "unreadable line") from None
            if number is not None:
                label = number
                try:
                    losses.number(number)
                except ikid.InputError as e:
                    raise _Refused(str(e), "late or repeated frame number") from None
            elif t is not None:
                losses.time(t)
            try:
                results = [s.push(x, time=t) for s in streams]
            except ikid.InputError as e:
                # The line's frame column is the one to read: the reason alone goes in the status.
                raise _Refused(e.reason or str(e), refusal_reason(e)) from e
            ready = [r for r in results if r is not None]
            if len(ready) < len(results):
                status = "filling"
            else:
                values = ",".join(f"{v:.7g}" for r in ready for v in r)
                filled = streams[0].filled_markers
                if filled:
                    status = "filled:" + "+".join(filled)
        except _Refused as e:
            status = "refused:" + e.detail.replace(",", ";").replace("\n", " ")
            refused[e.key] += 1
            if args.strict:
                print(f"ikid: error: frame {label}: {e.detail}", file=sys.stderr)
                return 2
        out.write(f"{label},{status},{values}\n")
        if args.flush:
            out.flush()
        counts[status.split(":")[0]] += 1
        frame += 1
    out.flush()
    parts = [f"{counts[k]} {k}" for k in ("ok", "filled", "filling", "refused") if counts[k]]
    if args.frame_number or args.time:
        parts.append(f"{losses.lost} lost (by {'frame number' if args.frame_number else 'time'})")
    else:
        parts.append("lost not counted (no frame numbers or times: --frame-number, --time)")
    print(f"ikid stream: {frame} frames received at {rate:g} Hz: " + ", ".join(parts), file=sys.stderr)
    if refused:
        print(
            "ikid stream: refused: " + "; ".join(f"{n} {reason}" for reason, n in refused.most_common()),
            file=sys.stderr,
        )
    return EXIT_FRAMES_LOST if refused or losses.lost else 0


class _Refused(Exception):
    """A frame `ikid stream` gives no output for: ``detail`` for its line, ``key`` to count it by."""

    def __init__(self, detail: str, key: str) -> None:
        super().__init__(detail)
        self.detail, self.key = detail, key
