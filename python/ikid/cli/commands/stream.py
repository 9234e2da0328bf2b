"""`ikid stream`: live frames (stdin, UDP, Lab Streaming Layer, Qualisys QTM) in, one CSV line
per frame out (and optionally an LSL stream)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter

import numpy as np

import ikid
from ikid.cli.common import _model_file, _model_for, _refuse_over_inputs, _stdout_fd, subject_size
from ikid.cli.options import PORT, POSITIVE, POSITIVE_INT, unchecked_option
from ikid.io._common import to_ikid_lab


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "stream",
        help="live frames (stdin, UDP on 127.0.0.1, LSL, QTM) -> one CSV line per frame",
        description="Frames in, one result line out per frame (CSV: frame,status,outputs; angles in rad,\n"
        "torques in N·m, unlike ik's .mot in degrees).\n\n"
        "  ikid stream --rate 1000 < frames.csv              # 18 numbers per line (m), 1 kHz\n"
        "  ikid stream --time --torque-model wrist-chain < frames.csv   # time first\n"
        "  ikid stream --rate 100 --udp 9870 --idle 5        # datagrams at 100 Hz, 'END' stops\n"
        "  ikid stream --udp 9870 --frame-number --time       # 'N,t,x1,...,z6': lost frames counted\n"
        "  ikid stream --source lsl:Qualisys --map lab.toml --sink lsl:ikid   # LSL in and out\n"
        "  ikid stream --source qtm:192.168.0.10 --map lab.toml             # QTM's real-time server\n\n"
        "Live sources (lsl:, qtm:) give their labels (mapped with --map's [markers]), rate and time\n"
        "stamps; a hidden marker is a gap; a bad time stamp is refused alone; a source that goes\n"
        "away is reconnected; frames older than --max-lag when read are skipped (counted). See\n"
        "docs/live.md.\n\n"
        "Status: ok, filled:<markers> (--tracker: missing:<markers>, gone without), flagged:<status\n"
        "bits>, filling, or refused:<reason> (an output no wrist can give is not written). The\n"
        "first 20 frames with every marker are checked as ik and track check a file (uncalibrated\n"
        "markers the body model cannot read, another subject's calibration: exit 2), their lines\n"
        "held until then.\n\n"
        "At the end, a summary on stderr: frames received, ok, filled, flagged, filling, refused (by\n"
        "reason), lost (counted from the source's frame numbers, --frame-number, or its\n"
        "times, --time), skipped, reconnections and time re-anchors. UDP asks for an 8 MiB receive\n"
        "buffer for bursts and says if it got less.\n\n"
        "Exit status: 0 every frame was processed; 3 frames were lost or refused; 2 an error\n"
        "(or, with --strict, the first refused frame).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default="wrist-ik", help="model (default wrist-ik)")
    p.add_argument(
        "--torque-model", default=None, help="a second model on the same frames (e.g. wrist-chain)"
    )
    p.add_argument(
        "--tracker",
        action="store_true",
        help="run ikid.Tracker (the extended Kalman filter over the body model) instead of the networks: "
        "angles and torques (<coordinate>_moment), each followed by its standard deviation (<name>_sd, "
        "from the filter's covariance; see docs/live.md for how far to trust it)",
    )
    p.add_argument(
        "--up",
        default=None,
        metavar="AXIS",
        help="the lab axis pointing up (+x, -x, +y, -y, +z, -z): torques depend on it (default: a live "
        "source's --map's up, else +y, OpenSim's; Vicon and Qualisys labs are usually +z)",
    )
    p.add_argument(
        "--sd",
        action="store_true",
        help="each network output followed by its standard deviation (<name>_sd; the model card's "
        "uncertainty, studies/net_sigma.py measures how well it covers), on stdout and the LSL sink; a frame "
        "whose σ is not yet known (the first frames after the window restarts) is 'filling'",
    )
    p.add_argument(
        "--udp",
        type=PORT,
        default=None,
        metavar="PORT",
        help="read datagrams on 127.0.0.1:PORT (0: any free port)",
    )
    p.add_argument(
        "--source",
        default=None,
        metavar="SPEC",
        help="a live source: lsl:<stream name> (Lab Streaming Layer) or qtm:<host>[:<port>] (Qualisys "
        "Track Manager's real-time server, port 22223 by default); stdin when absent",
    )
    p.add_argument(
        "--map", metavar="TOML", help="live sources: which of the source's marker labels is which ikid marker"
    )
    p.add_argument(
        "--sink",
        default=None,
        metavar="SPEC",
        help="also publish each output frame: lsl:<stream name> (outputs and status bits, stamped "
        "with the source frame's time); the CSV on stdout stays",
    )
    p.add_argument(
        "--max-lag",
        type=POSITIVE,
        default=0.05,
        metavar="S",
        help="live sources: when more than this many seconds of frames wait to be read, only the "
        "newest is processed and the others are counted as skipped (default 0.05)",
    )
    p.add_argument("--count", type=POSITIVE_INT, default=None, help="stop after this many frames")
    p.add_argument(
        "--idle",
        type=POSITIVE,
        default=10.0,
        help="UDP and live sources: stop after this many seconds without a frame (a lost live "
        "source is reconnected within it)",
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
        "wrist-ik-100hz); refused if it has none (a live stream is not resampled). Needed for frames on "
        "stdin or UDP without --time (a source at an unknown rate is refused)",
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
            # "97.000000" (np.savetxt with one format for every column) is frame 97; "97.5" is no frame.
            try:
                whole = float(fields[0])
            except ValueError:
                whole = math.nan
            if not (math.isfinite(whole) and whole == int(whole)):
                raise ikid.InputError(f"frame number {fields[0]!r} is not an integer") from None
            number = int(whole)
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
    k - 1 lost), else from its times (a gap of k periods is k - 1 lost). A frame number that is
    not after the last one (late or repeated), or far ahead of it, is refused alone; only
    ``REANCHOR_FRAMES`` such numbers in a row, each one after the other, are taken as the
    source's new numbering (it was restarted), as ikid.Stream does with time stamps."""

    #: Numbers in a row that make a jumped numbering the source's new one.
    REANCHOR_FRAMES = 3
    #: Largest jump in frame numbers counted as frames lost, s of frames at the stream's rate.
    MAX_JUMP_S = 1.0
    #: Steps between the first time stamps kept to say at what rate the source sends.
    RATE_STEPS = 100

    def other_rate(self) -> float | None:
        """The source's rate from its time stamps (their median step) when it is not the
        stream's, by more than the core's ``RATE_TOLERANCE``: then every frame is mis-timed,
        or reads as several lost. None when it is the stream's, or with under 10 steps."""
        if len(self.steps) < 10:
            return None
        rate = 1.0 / float(np.median(self.steps))
        return rate if abs(rate / self.rate_hz - 1.0) > ikid._native.RATE_TOLERANCE else None

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.lost = 0
        self.reanchors = 0
        self.last_number: int | None = None
        self.last_time: float | None = None
        #: The last stamp as it came (last_time steps over a clock glitch instead).
        self.last_stamp: float | None = None
        self.candidate: int | None = None
        self.candidate_frames = 0
        #: Time stamps in a row more than MAX_JUMP_S after the last counted one.
        self.jumps = 0
        #: The first steps between time stamps, s: what rate the source sends at.
        self.steps: list[float] = []
        #: Unreadable lines since the last frame number: frames that came, not lost.
        self.unnumbered = 0

    def number(self, n: int) -> None:
        last = self.last_number
        if last is not None and not 0 < n - last <= max(1, round(self.MAX_JUMP_S * self.rate_hz)):
            follows = self.candidate is not None and n == self.candidate + 1
            self.candidate_frames = self.candidate_frames + 1 if follows else 1
            self.candidate = n
            if self.candidate_frames < self.REANCHOR_FRAMES:
                what = "late or repeated" if n <= last else "too far ahead"
                raise ikid.InputError(f"frame number {n} after {last} ({what})")
            self.reanchors += 1
            last = None
        if last is not None:
            # Lines that came unreadable since the last number took some of the numbers between.
            self.lost += max(0, n - last - 1 - self.unnumbered)
        self.last_number, self.candidate, self.candidate_frames = n, None, 0
        self.unnumbered = 0

    def stamp(self, t: float) -> None:
        """Every time stamp as it comes, refused or not: the source's own steps, stamp to
        stamp, say its rate (stamps in ms step by more than MAX_JUMP_S every frame, and each is
        refused as a clock glitch until three in a row re-anchor it)."""
        if self.last_stamp is not None and len(self.steps) < self.RATE_STEPS and t > self.last_stamp:
            self.steps.append(t - self.last_stamp)
        self.last_stamp = t

    def time(self, t: float) -> None:
        if self.last_time is not None and t - self.last_time > self.MAX_JUMP_S:
            # A glitch of the source's clock, not frames lost (ikid.Stream refuses it; the
            # tracker, which takes no stamps, runs on): not counted, and the new place only
            # once REANCHOR_FRAMES stamps in a row say so.
            self.jumps += 1
            if self.jumps < self.REANCHOR_FRAMES:
                self.last_time += 1.0 / self.rate_hz
                return
            self.last_time, self.jumps = t, 0
            return
        self.jumps = 0
        if self.last_time is not None and t > self.last_time:
            self.lost += max(0, round((t - self.last_time) * self.rate_hz) - 1)
        self.last_time = t

    def refused_in_place(self) -> None:
        """A frame came but its time stamp was refused: it is not lost, and the next one's gap
        is counted from its place."""
        if self.last_time is not None:
            self.last_time += 1.0 / self.rate_hz
        self.jumps += 1

    def restart(self) -> None:
        """After a reconnection: the source's numbering and clock may start again."""
        self.last_number = self.last_time = self.last_stamp = self.candidate = None
        self.candidate_frames = self.jumps = 0


def _text_frames(lines, frame_len: int, with_time: bool, with_number: bool):
    """Text lines -> LiveFrame (an unreadable or over-long line as its error)."""
    from ikid.live import MAX_LINE_BYTES, LiveFrame

    first = True
    for line in lines:
        if line is None:
            yield [LiveFrame(None, None, None, f"line longer than {MAX_LINE_BYTES} bytes")]
            continue
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            number, t, x = _parse_frame(line, frame_len, with_time, with_number)
        except ikid.InputError as e:
            if first and _is_header(line):
                # A CSV's column names (RSP_x,RSP_y,...): not a frame, and not counted as one.
                first = False
                continue
            yield [LiveFrame(None, None, None, str(e))]
            continue
        finally:
            first = False
        yield [LiveFrame(number, t, x)]


def _is_header(line: str) -> bool:
    """A first line of column names: every field a name (starting with a letter), none a number."""
    fields = [f.strip() for f in line.replace(";", ",").replace("\t", ",").split(",") if f.strip()]
    return bool(fields) and all(f[0].isalpha() and f.lower() not in ("nan", "inf") for f in fields)


def _live_frames(source, idle_s: float, notes: Counter):
    """Batches of frames from a live source until ``idle_s`` s pass without one; a lost
    source is reconnected within that time (counted in ``notes``)."""
    from ikid.live import SourceLost

    last = time.monotonic()
    while True:
        try:
            batch = source.read(min(0.1, idle_s))
        except SourceLost as e:
            print(f"ikid stream: {e}; reconnecting (up to {idle_s:g} s)", file=sys.stderr, flush=True)
            notes["disconnected"] += 1
            if not source.reconnect(time.monotonic() + idle_s):
                print(
                    f"ikid stream: the source did not come back within {idle_s:g} s, stopping",
                    file=sys.stderr,
                )
                notes["not reconnected"] += 1
                return
            print(f"ikid stream: reconnected to the {source.kind} source", file=sys.stderr, flush=True)
            notes["reconnected"] += 1
            yield None  # the caller restarts its streams: what follows is not continuous
            last = time.monotonic()
            continue
        if batch:
            last = time.monotonic()
            yield batch
        elif time.monotonic() - last > idle_s:
            print(f"ikid stream: no frame for {idle_s:g} s, stopping", file=sys.stderr)
            return


def _stdin_lines(count: int | None):
    from ikid.live import bounded_lines

    # The binary buffer read in bounded pieces: a line with no end never fills memory.
    source = bounded_lines(sys.stdin.buffer) if hasattr(sys.stdin, "buffer") else iter(sys.stdin)
    for k, line in enumerate(source):
        if count is not None and k >= count:
            return
        yield line


#: Substring of ikid.Stream's refusal of a time stamp that jumped (see Stream::push_at).
_CLOCK_GLITCH = "glitch of the source's clock"
#: What the core says of stamps steadily further apart than the rate, or whose mean step is off
#: it (``SourcePace``).
_SLOW_SOURCE = "the source runs at about"


def run(args: argparse.Namespace) -> int:
    """Frames from stdin, UDP or a live source -> one CSV line per frame on stdout:
    ``frame,status,<outputs>`` (``frame,time,status,<outputs>`` for a live source); status
    ``ok``, ``filled:<markers>``, ``flagged:<status bits>``, ``filling`` (window not full yet) or
    ``refused:<reason>`` (outputs empty; an output no wrist can give is not written). Nothing is
    skipped silently: the summary on stderr counts frames received, refused (by reason), lost,
    skipped and reconnections; exit status 0 if every frame was processed, 3 if frames were lost,
    skipped or refused, 2 on an error."""
    from ikid.calibration import map_with_calibration
    from ikid.io.mapping import MarkerMap
    from ikid.pipeline import refusal_reason

    if args.udp is not None and args.source is not None:
        raise ikid.InputError("--udp and --source name two sources; give one")
    if args.map and args.source is None:
        raise ikid.InputError("--map is for a live source's labels (--source lsl:... or qtm:...)")
    if args.sink is not None and not (args.sink.startswith("lsl:") and len(args.sink) > 4):
        raise ikid.InputError(
            f"--sink {args.sink!r}: expected lsl:<stream name> (the CSV on stdout always stays)"
        )
    stdin = None
    if args.udp is None and args.source is None:
        try:
            stdin = sys.stdin.fileno()
        except (AttributeError, OSError, ValueError):
            pass
    _refuse_over_inputs(
        [_stdout_fd()],
        [stdin, args.calibration, args.map, _model_file(args.model), _model_file(args.torque_model)],
    )
    from ikid.io._common import parse_up

    # --map is a live source's (refused above otherwise): loaded once, for its labels and its up.
    marker_map = MarkerMap.load(args.map) if args.map else MarkerMap.identity()
    args.one_hand = None
    if marker_map.one_hand_marker:
        # Its six markers are built from four each frame, as a file's are; a forearm cluster's
        # anatomical points come from the calibration (refused here, before the source opens,
        # without one that has them).
        args.one_hand = _OneMarkerHand(map_with_calibration(marker_map, args.calibration))
    args.up_from = "--up" if args.up is not None else f"{args.map}'s up" if marker_map.up else None
    args.up = parse_up(args.up, "--up") if args.up is not None else marker_map.up
    source = None
    rate_hz = args.rate
    if args.source is not None:
        from ikid.live import open_source

        source = open_source(args.source, marker_map, args.idle)
        declared = f"{source.rate_hz:g} Hz" if source.rate_hz else "no declared rate"
        print(
            f"ikid stream: reading {args.source} at {declared} "
            f"({len(source.labels)} markers, ikid's {len(marker_map.marker_names())} mapped)",
            file=sys.stderr,
            flush=True,
        )
        if source.rate_hz is not None:
            if args.rate is not None and not math.isclose(args.rate, source.rate_hz, rel_tol=1e-6):
                # A source set up otherwise than it sends (an LSL outlet's nominal rate, a QTM
                # project's): its stamps say so, and --rate is the way out a lab has.
                print(
                    f"ikid stream: --rate {args.rate:g} Hz overrides the {source.kind} source's declared "
                    f"{source.rate_hz:g} Hz",
                    file=sys.stderr,
                    flush=True,
                )
            else:
                rate_hz = source.rate_hz
        if source.up is not None and args.up is None:
            # QTM says which of its axes points up (+Z by default): taken, as a file's header is.
            args.up, args.up_from = source.up, f"{source.kind.upper()}'s AxisUpwards"
        elif source.up is not None and source.up != args.up:
            print(
                f"ikid stream: the lab's up is taken as {args.up} ({args.up_from}), where "
                f"{source.kind.upper()} says its AxisUpwards is {source.up}",
                file=sys.stderr,
                flush=True,
            )
    if rate_hz is None and not args.time:
        if source is not None:
            source.close()
        # Read at the model's rate, a 100 Hz source gave 1.3° RMS angles and 3.6 N·m torques
        # (true: 0.17 N·m) with every line "ok": the rate is an input, never a guess.
        raise ikid.InputError(
            "the source's frame rate is not known (no --rate, no --time stamps, and the source declares "
            "none): give --rate HZ, the rate it sends frames at (read at another rate than its own, "
            "every angle and torque would be wrong and nothing could say so)"
        )
    try:
        return _run(args, source, rate_hz, refusal_reason)
    finally:
        if source is not None:
            source.close()


class _TrackerStream:
    """ikid.Tracker behind the stream's interface: per frame, each angle and torque followed by
    its standard deviation (``Tracker.output_sd``); None until the filter has started. The
    tracker runs at its rate: a time stamp more than 1.5 periods after the last restarts it
    (the core's ``Tracker.push(frame, time=)``)."""

    def __init__(self, rate_hz: float, calibration, calibration_path: str | None) -> None:
        from ikid.io.storage import coordinate_names, moment_names

        self.rate_hz = rate_hz
        self.calibration = calibration
        # The subject's size as `ikid track` takes it from the same calibration.
        self.length_scale, self.mass_scale, self.size_from = subject_size(calibration_path)
        self.tracker = self._new_tracker()
        values = coordinate_names() + moment_names()
        self.output_names = [n for v in values for n in (v, f"{v}_sd")]
        self.output_units = [u for k in range(len(values)) for u in 2 * ["rad" if k < 3 else "N*m"]]
        self.filled_markers: list[str] = []
        self.went_without: list[str] = []
        self.status = math.nan
        self.time_reanchors = 0
        self.restarts_before = 0  # gap restarts of the trackers a reset replaced
        self.bridged_before = 0  # and the lost frames they bridged

    @property
    def gap_restarts(self) -> int:
        return self.restarts_before + self.tracker.gap_restarts

    @property
    def bridged_frames(self) -> int:
        return self.bridged_before + self.tracker.bridged_frames

    def push(self, frame: np.ndarray, time: float | None = None) -> np.ndarray | None:
        # Frames lost (or a slower source): the filter's motion model would bridge the gap as
        # one period (torques 4 N·m off after 0.1 s lost); stamped, the core carries it through
        # the lost frames when they are few, and restarts it otherwise.
        out = self.tracker.push(frame, time=time)
        sd = self.tracker.output_sd
        if out is None or sd is None:
            return None
        self.status = float(out.status)  # the frame's status bits, for the sink's status channel
        # Markers the filter went without (it fills none): said on the line, as `track` counts them.
        self.went_without = [m for k, m in enumerate(ikid.marker_names()) if out.missing >> k & 1]
        values = np.concatenate([out.q, out.tau])
        return np.column_stack([values, np.concatenate([sd[0], sd[1]])]).ravel()

    def _new_tracker(self) -> ikid.Tracker:
        return ikid.Tracker(
            rate_hz=self.rate_hz,
            calibration=self.calibration,
            length_scale=self.length_scale,
            mass_scale=self.mass_scale,
        )

    def reset(self) -> None:
        self.restarts_before, self.bridged_before = self.gap_restarts, self.bridged_frames
        self.tracker = self._new_tracker()


def _run(args: argparse.Namespace, source, rate_hz: float | None, refusal_reason) -> int:
    if args.tracker:
        return _run_with(args, source, refusal_reason, *_tracker_streams(args, rate_hz))
    return _run_with(args, source, refusal_reason, *_model_streams(args, rate_hz))


def _stream_calibration(args: argparse.Namespace):
    """The calibration file given, checked against the marker map (its arm, its labels); or,
    without one, the body model's placement for the map's arm (a left arm mirrored)."""
    from ikid.calibration import check_calibration_map, uncalibrated
    from ikid.io import MarkerMap

    marker_map = MarkerMap.load(args.map) if args.map else None
    if args.calibration:
        if marker_map is not None:  # frames on stdin come in ikid's order, with no map to check
            check_calibration_map(args.calibration, marker_map)
        return ikid.load_calibration(args.calibration)
    return uncalibrated(marker_map.side if marker_map else "right")


def _tracker_streams(args: argparse.Namespace, rate_hz: float | None):
    if args.torque_model or args.model != "wrist-ik" or args.missing_markers:
        raise ikid.InputError(
            "--tracker gives angles and torques itself: no --model, --torque-model or --missing-markers"
        )
    if rate_hz is None:
        # Its velocities and torques scale with the rate: time stamps alone do not give it.
        raise ikid.InputError(
            "--tracker needs the frames' rate: give --rate HZ (or a live source that declares it)"
        )
    calibration = _stream_calibration(args)
    stream = _TrackerStream(rate_hz, calibration, args.calibration)
    # The tracker reads marker frames: the 18 values every source gives.
    return [stream], stream.output_names, stream.output_units, stream.rate_hz, len(ikid.marker_names()) * 3


class _WithSd:
    """A network's stream behind the stream's interface, each output followed by its standard
    deviation (``Stream.output_sd``); None (filling) until the σ is known."""

    def __init__(self, stream: ikid.Stream) -> None:
        self.stream = stream

    def push(self, frame: np.ndarray, time: float | None = None) -> np.ndarray | None:
        out = self.stream.push(frame, time=time)
        sd = self.stream.output_sd
        if out is None or sd is None:
            return None
        return np.column_stack([np.asarray(out, np.float64), sd]).ravel()

    def __getattr__(self, name: str):  # status, filled_markers, time_reanchors, reset: the stream's
        return getattr(self.stream, name)


def _column_names(model: ikid.Model) -> list[str]:
    """A model's output columns: its own names, a torque's (N·m) as ``<name>_moment``."""
    return [
        f"{n}_moment" if unit == "N*m" and not n.endswith("_moment") else n
        for n, unit in zip(model.output_names, model.output_units, strict=True)
    ]


def _model_streams(args: argparse.Namespace, rate_hz: float | None):
    unchecked = args.allow_unchecked_model
    models = [_model_for(args.model, "ikid stream --model", ("ik", "chain"), rate_hz, unchecked)]
    if args.torque_model:
        models.append(
            _model_for(args.torque_model, "ikid stream --torque-model", ("chain",), rate_hz, unchecked)
        )
    rate = models[0].frame_rate_hz
    for m in models:
        if m.frame_len != models[0].frame_len:
            raise ikid.InputError(f"models {models[0].name!r} and {m.name!r} read different frames")
    calibration = _stream_calibration(args)
    plain = [m.stream(missing_markers=args.missing_markers, calibration=calibration) for m in models]
    streams: list[ikid.Stream | _WithSd] = list(plain)
    # A torque model names its outputs after the coordinates too: its columns are the moments
    # (`<coordinate>_moment`, as run's .sto), never a second set under the angles' names.
    names = [n for m in models for n in _column_names(m)]
    units = [u for m in models for u in m.output_units]
    if args.sd:
        from ikid.cli.process import _check_uncertainty

        for m in models:
            _check_uncertainty(m.name, m, "ikid stream --sd")
        streams = [_WithSd(s) for s in plain]
        names = [x for n in names for x in (n, f"{n}_sd")]
        units = [u for unit in units for u in (unit, unit)]
    return streams, names, units, rate, models[0].frame_len


def _run_with(
    args: argparse.Namespace, source, refusal_reason, streams, names, units, rate, frame_len
) -> int:
    one_hand: _OneMarkerHand | None = getattr(args, "one_hand", None)
    # What the markers do not determine (a one-marker hand's ra_wr_s_p) is not written: no
    # column, no channel, as ik and track leave it out of their files.
    undetermined = one_hand.undetermined if one_hand is not None else {}
    written = np.array([not _of_undetermined(n, undetermined) for n in names], bool)
    names = [n for n, w in zip(names, written, strict=True) if w]
    units = [u for u, w in zip(units, written, strict=True) if w]
    for name, why in undetermined.items():
        print(f"ikid stream: {name} not written: {why}", file=sys.stderr, flush=True)
    sink = None
    if args.sink is not None:
        from ikid.live.sinks import LslSink

        sink = LslSink(args.sink[4:], names, units, rate)
    live = source is not None
    # Frames in ikid's lab (+Y up): torques depend on which way is up, angles do not.
    up = args.up or "+y"
    out = sys.stdout
    out.write("frame," + ("time," if live else "") + "status," + ",".join(names) + "\n")
    notes: Counter = Counter()
    if live:
        batches = _live_frames(source, args.idle, notes)
        timed, numbered = True, source.kind == "qtm"
    else:
        lines = (
            _udp_lines(args.udp, args.count, args.idle) if args.udp is not None else _stdin_lines(args.count)
        )
        batches = _text_frames(lines, frame_len, args.time, args.frame_number)
        timed, numbered = args.time, args.frame_number
    # A consumer that falls behind takes the newest frame: older ones waiting are skipped.
    max_backlog = max(1, round(args.max_lag * rate))
    counts: Counter = Counter()
    refused: Counter = Counter()
    flags: Counter = Counter()  # flagged frames by status bit
    losses = _Losses(rate)
    frame = 0
    flush = args.flush or live
    # The source restarted (reconnected, or its numbering re-anchored): the next output published
    # carries the RESYNCED bit, as ikid.Stream's own after its clock re-anchors.
    resynced = False
    placement = _PlacementCheck(args, one_hand) if frame_len == len(ikid.marker_names()) * 3 else None
    for batch in batches:
        if batch is None:  # reconnected: what follows does not continue what came before
            for s in streams:
                s.reset()
            losses.restart()
            resynced = True
            continue
        if len(batch) > max_backlog:
            notes["skipped"] += len(batch) - 1
            for f in batch[:-1]:  # skipped, not lost: their numbers and times still count
                try:
                    if f.time is not None:
                        losses.stamp(f.time)
                    if f.number is not None:
                        losses.number(f.number)
                    elif f.time is not None:
                        losses.time(f.time)
                except ikid.InputError:
                    pass
            batch = batch[-1:]
            # What follows does not continue what the window holds (and may be further ahead
            # than a clock glitch's bound): the streams start again from the newest frame. A
            # stamped tracker sees the gap itself and restarts keeping what it learned.
            if not (args.tracker and (batch[0].time is not None or batch[0].number is not None)):
                for s in streams:
                    s.reset()
        for f in batch:
            if args.count is not None and frame >= args.count:
                break
            status, values, label = "ok", "", f.number if f.number is not None else frame
            try:
                if f.error is not None:
                    if numbered:
                        # Its number is unknown (the line is unreadable): none is made up, and the
                        # next number's jump does not count it lost.
                        label = ""
                        losses.unnumbered += 1
                    raise _Refused(f.error, "unreadable frame" if live else "unreadable line")
                if f.number is not None:
                    try:
                        reanchors, lost = losses.reanchors, losses.lost
                        losses.number(f.number)
                        resynced |= losses.reanchors != reanchors
                        if losses.lost > lost and f.time is None and not args.tracker:
                            # Frames were lost: what follows does not continue what the window
                            # holds (with time stamps the stream sees the gap and restarts itself;
                            # the tracker is stamped by frame number, below).
                            for s in streams:
                                s.reset()
                    except ikid.InputError as e:
                        key = (
                            "frame number too far ahead"
                            if "too far ahead" in str(e)
                            else "late or repeated frame number"
                        )
                        raise _Refused(str(e), key) from None
                frame_values = markers = f.values
                if up != "+y" and frame_len == 18:  # marker frames, from a lab of its own
                    frame_values = markers = to_ikid_lab(
                        np.asarray(f.values, np.float64).reshape(-1, 3), up
                    ).reshape(-1)
                if one_hand is not None:
                    frame_values = one_hand.frame(markers)
                if placement is not None and placement.see(frame_values, markers):
                    # Checked (an error here ends the stream, exit 2): what was held goes out.
                    placement.release(out, sink)
                if f.time is not None:
                    losses.stamp(f.time)
                try:
                    stamp = f.time
                    if stamp is None and f.number is not None and args.tracker:
                        # Numbered, not timed: the number is the stamp, so frames lost restart the
                        # filter and it keeps what it learned of the subject (noise, placement),
                        # which a new tracker would learn again.
                        stamp = f.number / rate
                    results = [s.push(frame_values, time=stamp) for s in streams]
                except ikid.InputError as e:
                    if _CLOCK_GLITCH in str(e):
                        if f.number is None:
                            losses.refused_in_place()
                        raise _Refused(e.reason or str(e), "time stamp jumped (refused alone)") from e
                    if f.number is None and f.time is not None:
                        losses.time(f.time)
                    if _SLOW_SOURCE in str(e) and not live and losses.steps:
                        # The stamps say the source sends slower than the rate the stream runs
                        # at (the model's, or --rate's): every frame would be refused. Said once,
                        # with the --rate to give.
                        step = float(np.median(losses.steps))
                        given = (
                            "without --rate the stream runs at the model's rate"
                            if args.rate is None
                            else f"--rate {args.rate:g} says otherwise"
                        )
                        hint = _stamps_hint(1.0 / step, rate, _member_rates(args), len(losses.steps))
                        raise ikid.InputError(f"frame {label}: {hint} ({given})") from None
                    if _SLOW_SOURCE in str(e):
                        # A live source at another rate than the stream's: each frame refused
                        # alone, the summary says what its stamps show and what to give (the
                        # core's "resample it" is no way out for a live stream).
                        said = (e.reason or str(e)).rsplit("; ", 1)[0]
                        if losses.steps:
                            source_hz = 1.0 / float(np.median(losses.steps))
                            said += "; " + _rate_to_give(source_hz, _member_rates(args), len(losses.steps))
                        raise _Refused(said, "time stamps at another rate than the stream's") from e
                    if "resample the source" in str(e):
                        raise _Refused(
                            e.reason or str(e), "time stamp too soon (the source is faster than the model)"
                        ) from e
                    lacks = one_hand.lacks(markers, frame_values) if one_hand is not None else None
                    if lacks is not None:
                        # Said in the map's markers, not the six virtual ones the core was given.
                        raise _Refused(lacks, lacks) from e
                    # The line's frame column is the one to read: the reason alone goes in the status.
                    raise _Refused(e.reason or str(e), refusal_reason(e)) from e
                if f.number is None and f.time is not None:
                    losses.time(f.time)
                ready = [r for r in results if r is not None]
                if not ready and args.tracker and not np.isfinite(frame_values).all():
                    # The filter starts from a frame with every marker: one never seen would
                    # leave the whole session "filling" (exit 0, nothing said).
                    lacks = one_hand.lacks(markers, frame_values) if one_hand is not None else None
                    absent = lacks or "missing " + ", ".join(_absent_markers(frame_values))
                    why = f"{absent}: the tracker starts from a frame with every marker"
                    raise _Refused(why, why)
                if len(ready) < len(results):
                    status = "filling"
                else:
                    output = np.concatenate(ready) if len(ready) > 1 else ready[0]
                    output = output[written]
                    bits = _frame_bits(streams)
                    if bits & _IMPLAUSIBLE:
                        # As ik and track: no output no wrist can give is written as a number.
                        raise _Refused(*_implausible(bits, output, args.tracker))
                    values = ",".join(f"{v:.7g}" for v in output)
                    filled = streams[0].filled_markers
                    if bits & ~_FILLED:
                        status = "flagged:" + "+".join(n for n, b in ikid.FRAME_STATUS.items() if bits & b)
                        flags.update(n for n, b in ikid.FRAME_STATUS.items() if bits & b & ~_FILLED)
                    elif filled:
                        status = "filled:" + "+".join(filled)
                    elif missing := getattr(streams[0], "went_without", None):
                        status = "missing:" + "+".join(missing)
                    if sink is not None:
                        if resynced:
                            bits |= ikid.FRAME_STATUS["resynced"]
                        published = (output, bits, f.time if f.time is not None else _lsl_now())
                        if placement is not None and placement.frames is not None:
                            placement.held_outputs.append(published)
                        else:
                            sink.publish(*published)
                    resynced = False
            except _Refused as e:
                status = "refused:" + e.detail.replace(",", ";").replace("\n", " ")
                refused[e.key] += 1
                if args.strict:
                    if placement is not None and placement.frames is not None:
                        placement.check()
                        placement.release(out, sink)
                    print(f"ikid: error: frame {label}: {e.detail}", file=sys.stderr)
                    return 2
            stamp = ("" if f.time is None else f"{f.time:.6f}") + "," if live else ""
            line = f"{label},{stamp}{status},{values}\n"
            if placement is not None and placement.frames is not None:
                # Held until the first frames are checked: nothing is written of a stream whose
                # markers cannot be read.
                placement.held_lines.append(line)
            else:
                out.write(line)
                if flush:
                    out.flush()
            counts[status.split(":")[0]] += 1
            frame += 1
        if args.count is not None and frame >= args.count:
            break
    if placement is not None and placement.frames is not None:
        placement.check()  # a stream shorter than the frames checked: its frames, checked
        placement.release(out, sink)
    out.flush()
    parts = [
        f"{counts[k]} {k}" for k in ("ok", "filled", "missing", "flagged", "filling", "refused") if counts[k]
    ]
    if flags:
        parts.append("flagged " + ", ".join(f"{name} {n}" for name, n in flags.most_common()))
    other = losses.other_rate() if timed else None
    if not numbered and other is not None:
        # Counted from stamps at another rate than the stream's, every step reads as frames lost.
        losses.lost = 0
        parts.append("lost not counted (the time stamps do not come at the stream's rate)")
    elif numbered or timed:
        parts.append(f"{losses.lost} lost (by {'frame number' if numbered else 'time'})")
    else:
        parts.append("lost not counted (no frame numbers or times: --frame-number, --time)")
    if other is not None:
        parts.append(_stamps_hint(other, rate, _member_rates(args), len(losses.steps)))
    skipped = notes["skipped"]
    if live:
        parts.append(f"{skipped} skipped (read too late: newest taken)")
        parts.append(f"{notes['reconnected']} reconnected")
        if notes["not reconnected"]:
            parts.append("the source was lost and did not come back")
    bridged = getattr(streams[0], "bridged_frames", 0)
    if bridged:
        parts.append(f"{bridged} lost frames bridged (the filter carried through them)")
    gap_restarts = getattr(streams[0], "gap_restarts", 0)
    if gap_restarts:
        parts.append(f"{gap_restarts} restarts after time gaps (the window or filter started again)")
    reanchors = streams[0].time_reanchors + losses.reanchors
    if reanchors:
        parts.append(f"{reanchors} re-anchored (the source's clock or numbering restarted)")
    if getattr(source, "ended", 0):
        parts.append(f"{source.ended} end-of-data from QTM")
    if sink is not None:
        parts.append(f"{sink.published} published on lsl:{args.sink[4:]}")
    if args.tracker or args.torque_model:
        parts.append(
            f"lab up {up}"
            + (
                f" ({args.up_from})"
                if args.up
                else " (assumed: give --up, or up in the --map, if yours is another)"
            )
        )
    parts.extend(f"{name} not written (the hand is one marker)" for name in undetermined)
    if args.tracker:
        s = streams[0]
        parts.append(f"subject ×{s.length_scale:.3g} length, ×{s.mass_scale:.3g} mass ({s.size_from})")
    print(f"ikid stream: {frame} frames received at {rate:g} Hz: " + ", ".join(parts), file=sys.stderr)
    if refused:
        print(
            "ikid stream: refused: " + "; ".join(f"{n} {reason}" for reason, n in refused.most_common()),
            file=sys.stderr,
        )
    if sink is not None:
        sink.close()
    return EXIT_FRAMES_LOST if refused or losses.lost or skipped or notes["not reconnected"] else 0


def _stamps_hint(other: float, rate: float, members: list[float], steps: int) -> str:
    """What stamps at ``other`` Hz (from ``steps`` steps between them) say to a stream at
    ``rate`` Hz, and what to give (:func:`_rate_to_give`). Stamps a second or more apart that
    read as a motion capture rate in milliseconds are said to be in ms, with the rate they say
    then."""
    in_ms = 1e3 * other
    if abs(in_ms / rate - 1.0) <= 0.2:
        return (
            f"the time stamps step by {1 / other:.3g}, a frame at {rate:g} Hz: are they in ms? "
            "--time reads seconds"
        )
    if other <= 1.0 and MS_STAMP_RATES_HZ[0] <= in_ms <= MS_STAMP_RATES_HZ[1]:
        return (
            f"the time stamps step by {1 / other:.3g}, a {in_ms:.4g} Hz source if they are ms: are they "
            f"in ms? --time reads seconds: divide them by 1000 and {_rate_to_give(in_ms, members, steps)}"
        )
    source = f"a {other:.4g} Hz source read at {rate:g} Hz"
    give = _rate_to_give(other, members, steps)
    return f"the time stamps come {1e3 / other:.3g} ms apart, {source}: {give}"


#: The rates, Hz, that stamps a second or more apart are read as if in milliseconds: motion
#: capture's (30 Hz webcams to 10 kHz high-speed systems); no wrist source sends under 1 Hz.
MS_STAMP_RATES_HZ = (10.0, 10000.0)


#: Steps between stamps from which a source's rate is known well enough to be held to the
#: core's ``RATE_TOLERANCE``; from fewer (a stream stopped on its third late stamp), the
#: family's member within a quarter of it is named.
RATE_KNOWN_STEPS = 32


def _rate_to_give(hz: float, members: list[float], steps: int) -> str:
    """What to give for a source at ``hz`` (from ``steps`` steps between its stamps): its rate
    (``members`` empty: the tracker runs at any); the family's member the stream takes it as;
    else the tracker, which runs at any rate (a member further off reads every frame
    mis-timed: 80 Hz stamps were told to give --rate 100, which then ran them as 100 Hz)."""
    if not members:
        return f"give --rate {hz:.4g}"
    within = ikid._native.RATE_TOLERANCE if steps >= RATE_KNOWN_STEPS else 0.25
    near = [m for m in members if abs(m / hz - 1.0) <= within]
    if near:
        return f"give --rate {min(near, key=lambda m: abs(m - hz)):g} (the family's member at that rate)"
    return (
        f"no member of the model's family runs at it ({', '.join(f'{m:g}' for m in members)} Hz): "
        f"give --tracker --rate {hz:.4g} (the Tracker runs at any rate), or record at one of those rates"
    )


def _member_rates(args: argparse.Namespace) -> list[float]:
    """The rates of the stream's model family (none for the tracker, which runs at any rate)."""
    if args.tracker:
        return []
    from ikid.pipeline import family_members

    return sorted(m.frame_rate_hz for m in family_members(args.model))


def _lsl_now() -> float:
    import pylsl

    return pylsl.local_clock()


_IMPLAUSIBLE = ikid.FRAME_STATUS["implausible"]
_FILLED = ikid.FRAME_STATUS["filled"]


def _frame_bits(streams) -> int:
    """The status bits of the frame just pushed, over every stream (a torque model's too)."""
    bits = 0
    for s in streams:
        b = s.status
        if not (isinstance(b, float) and math.isnan(b)):
            bits |= int(b)
    return bits


def _implausible(bits: int, output: np.ndarray, tracker: bool) -> tuple[str, str]:
    """Why a frame with the ``implausible`` bit has no output written, and the key it is counted
    by: as ``ik`` and ``track`` say it."""
    from ikid.pipeline import TURNED_OVER_REASON

    if bits & ikid.FRAME_STATUS["turned_over"]:
        return TURNED_OVER_REASON, "hand turned over on the forearm (not written)"
    what = "estimate (a torque or speed no wrist gives)" if tracker else "outputs (far outside training)"
    values = np.array2string(np.asarray(output, np.float64), precision=3).replace("\n", "")
    return f"implausible {what}, not written: {values}", "implausible (not written)"


class _PlacementCheck:
    """The checks ``ik`` and ``track`` make of a whole file before any output (units, each
    segment's markers, and the placement an uncalibrated run assumes or the calibration's own
    marker distances: ``_subject_calibration``), made live on the first :data:`CHECKED_FRAMES`
    frames with every marker. Uncalibrated real markers read 50-170° off, and another
    subject's calibration gave 2-3 rad, every line "ok"; such a stream ends with the reason."""

    CHECKED_FRAMES = 20

    def __init__(self, args: argparse.Namespace, one_hand: _OneMarkerHand | None = None) -> None:
        from ikid.io import MarkerMap

        self.args = args
        self.mapping = MarkerMap.load(args.map) if args.map else None
        self.one_hand = one_hand
        #: The frames with every marker seen so far; None once checked.
        self.frames: list[np.ndarray] | None = []
        #: Their markers as the source gave them (a one-marker hand's four).
        self.markers: list[np.ndarray] = []
        #: Output lines and sink publications held until then.
        self.held_lines: list[str] = []
        self.held_outputs: list[tuple[np.ndarray, int, float]] = []

    def see(self, values, markers) -> bool:
        """Notes a frame (ikid's six markers, and the ``markers`` they were made from);
        True when this one completes the check (passed: an error otherwise)."""
        if self.frames is None:
            return False
        frame = np.asarray(values, np.float64)
        if frame.shape == (18,) and np.isfinite(frame).all():
            self.frames.append(frame)
            self.markers.append(np.asarray(markers, np.float64))
        if len(self.frames) < self.CHECKED_FRAMES:
            return False
        self.check()
        return True

    def check(self) -> None:
        from ikid.cli.common import _subject_calibration

        frames, self.frames = np.array(self.frames or np.empty((0, 18))), None
        if len(frames) == 0:  # no frame with every marker: nothing to judge
            return
        source = f"the stream's first {len(frames)} frames with every marker"
        if self.one_hand is not None:
            # The wrist bar and the elbow where a one-marker hand's frame needs them, as a
            # file's whole columns are checked (MarkerMap.anatomical_forearm).
            self.one_hand.check_forearm(np.array(self.markers), source)
        _subject_calibration(
            frames,
            self.args.calibration,
            self.mapping,
            source,
            whole=False,
            labelled=self.mapping is not None,
        )
        if self.args.tracker and not self.args.calibration:
            self.check_size(frames, source)

    @staticmethod
    def check_size(frames: np.ndarray, source: str) -> None:
        """An uncalibrated tracker takes the default subject (a stream has no size options):
        markers whose distances say another size are refused, as ``ikid track`` would read
        them at their own (:func:`~ikid.cli.common.subject_size`)."""
        from ikid.io.marker_checks import TRACKER_SIZE_TOLERANCE, marker_length_scale

        said = marker_length_scale(frames)
        if said is not None and abs(said - 1.0) > TRACKER_SIZE_TOLERANCE:
            raise ikid.InputError(
                f"{source}: the markers' distances say the subject is ×{said:.3g} the body model's, and "
                "an uncalibrated tracker takes the body model's size (it measures the hand by where its "
                "markers sit from the model's wrist centre: read at another size its angles and torques "
                "are wrong); calibrate the subject (ikid calibrate) and pass --calibration"
            )

    def release(self, out, sink) -> None:
        """Writes the lines and publishes the outputs held while the frames were checked."""
        out.writelines(self.held_lines)
        out.flush()
        if sink is not None:
            for published in self.held_outputs:
                sink.publish(*published)
        self.held_lines, self.held_outputs = [], []


class _OneMarkerHand:
    """A one-marker hand's live frames (the forearm's three markers and ``HND``, 12 values:
    Plug-in Gait's wrist bar, elbow and finger marker) made ikid's six markers one frame at a
    time, as a file's are (:meth:`ikid.io.MarkerMap.ikid_frames`), and what a frame lacks said
    in the map's labels rather than the six virtual markers the core is given."""

    def __init__(self, marker_map) -> None:
        # A forearm cluster without the calibration that places its anatomical points is
        # refused here, before any source is opened.
        self.names = marker_map.marker_names()  # RSP, USP, FAP, HND
        marker_map.ikid_frames(np.empty((0, 3 * len(self.names))))
        self.map = marker_map
        self.undetermined: dict[str, str] = marker_map.undetermined

    def frame(self, markers) -> np.ndarray:
        """ikid's 18 values (NaN for a segment its markers do not place)."""
        columns = np.asarray(markers, np.float64).reshape(1, -1)
        return self.map.ikid_frames(columns, check=False)[0]

    def check_forearm(self, markers: np.ndarray, source: str) -> None:
        """An error if the forearm's markers over these frames are not a wrist bar and an elbow,
        or the hand's marker does not sit as far from the wrist as calibrated
        (:meth:`ikid.io.MarkerMap.anatomical_forearm`'s checks), naming ``source``."""
        try:
            self.map.anatomical_forearm(markers)
        except ikid.InputError as e:
            raise ikid.InputError(f"{source}: {e.reason or e}") from None

    def lacks(self, markers, frame: np.ndarray) -> str | None:
        """Why this frame gives the core no wrist, counted as such (no numbers in it); None when
        it gives one."""
        points = np.asarray(markers, np.float64).reshape(-1, 3)
        absent = [
            f"{n} {self.map.labels[n]!r}"
            for n, p in zip(self.names, points, strict=True)
            if not np.isfinite(p).all()
        ]
        if absent:
            return f"missing {', '.join(absent)} (with one hand marker every marker is needed)"
        hand = self.names[-1]
        if not np.isfinite(frame[:9]).all():
            return (
                f"FAP {self.map.labels['FAP']!r} within 3 cm of the wrist bar's middle or along it: "
                "no forearm axis"
            )
        if not np.isfinite(frame).all():
            return (
                f"{hand} {self.map.labels[hand]!r} within 3 cm of the wrist bar's middle or along it: "
                "no hand direction"
            )
        return None


def _absent_markers(frame: np.ndarray) -> list[str]:
    """ikid's markers missing (NaN) in an 18-value frame."""
    points = np.asarray(frame, np.float64).reshape(-1, 3)
    return [m for m, p in zip(ikid.marker_names(), points, strict=True) if not np.isfinite(p).all()]


def _of_undetermined(name: str, undetermined: dict[str, str]) -> bool:
    """Whether an output column (a coordinate, its ``_moment``, ``_sd``) is one of these."""
    return any(name == u or name.startswith(u + "_") for u in undetermined)


class _Refused(Exception):
    """A frame `ikid stream` gives no output for: ``detail`` for its line, ``key`` to count it by."""

    def __init__(self, detail: str, key: str) -> None:
        super().__init__(detail)
        self.detail, self.key = detail, key
