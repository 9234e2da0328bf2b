"""Where live frames come from: an LSL inlet, a QTM real-time client, bounded text lines.

A source has ``labels`` (what it calls its markers), ``rate_hz`` (its own frame rate, None if
it declares none), ``read(timeout)`` (the frames that arrived, oldest first: an empty list when
none came within ``timeout`` s; :class:`SourceLost` when the connection is gone),
``reconnect(deadline)`` and ``close()``, and counts ``reconnected``.
"""

from __future__ import annotations

import re
import socket
import struct
import time
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from typing import Any, BinaryIO, NamedTuple

import numpy as np

from ikid import _native
from ikid.io._common import parse_up
from ikid.io.mapping import MarkerMap, MarkerMapWarning

#: Longest text line read from stdin or a datagram, bytes: a frame of 18 numbers with a frame
#: number and a time is under 1 KiB; a longer line is refused (its bytes read and dropped in
#: pieces of this size, so memory stays bounded whatever the source sends).
MAX_LINE_BYTES = 1 << 16


class LiveFrame(NamedTuple):
    """One frame from a source: its frame number and time stamp (s) when the source gives
    them, the map's marker values in ikid's order in metres (:func:`marker_columns`; NaN for a
    marker the source marks missing), or ``error`` (why it could not be read)."""

    number: int | None
    time: float | None
    values: np.ndarray | None
    error: str | None = None


class SourceLost(Exception):
    """The source's connection is gone (closed, reset, or a packet that cannot be read)."""


def bounded_lines(stream: BinaryIO, limit: int = MAX_LINE_BYTES) -> Iterator[str | None]:
    """Text lines of a binary stream, each at most ``limit`` bytes; ``None`` for a longer line,
    whose bytes are read and dropped ``limit`` at a time (never held whole)."""
    while True:
        line = stream.readline(limit + 1)
        if not line:
            return
        if len(line) > limit and not line.endswith(b"\n"):
            while line and not line.endswith(b"\n"):
                line = stream.readline(limit)
            yield None
            continue
        yield line.decode("utf-8", "replace")


def marker_columns(
    positions: dict[str, tuple[int, int, int]], marker_map: MarkerMap, source: str
) -> np.ndarray:
    """Indices into a source's channels of the map's markers' values, x y z each, in ikid's
    marker order (:meth:`MarkerMap.marker_names`: ikid's six, 18 values; or a one-marker hand's
    forearm three and ``HND``, 12, which ``ikid stream`` makes six as files' are), from the
    source's marker label -> its three channels and the marker map."""
    columns: list[int] = []
    absent: list[str] = []
    if marker_map.clusters:
        # A cluster's shape is learned from a recording's frames; a live source is read a frame
        # at a time, so each segment is its three markers here (a calibration holds for both).
        extra = ", ".join(lab for labels in marker_map.clusters.values() for lab in labels)
        warnings.warn(
            f"{source}: the marker map's [cluster] markers ({extra}) are not used on a live source: each "
            "segment is read from its three [markers]",
            MarkerMapWarning,
            stacklevel=2,
        )
    for m in marker_map.marker_names():
        label = marker_map.labels[m]
        if label not in positions:
            absent.append(f"{label} ({m})")
            continue
        columns.extend(positions[label])
    if absent:
        hint = (
            " (give a marker map: --map FILE.toml, see `ikid map-template`)"
            if marker_map.source == "identity"
            else f" (marker map {marker_map.source})"
        )
        raise _native.InputError(
            f"{source}: marker label(s) {', '.join(absent)} not found; the source has "
            f"{', '.join(positions) or 'no labelled markers'}{hint}"
        )
    return np.asarray(columns, np.intp)


_AXIS_SUFFIX = re.compile(r"(.+?)[_.\-: ]?([xyzXYZ])")


def lsl_marker_channels(channel_labels: list[str]) -> dict[str, tuple[int, int, int]]:
    """Marker label -> its x, y, z channels, from LSL channel labels ``<marker>_X/_Y/_Z`` (what
    Qualisys' LSL app writes; ``.x``, ``-x``, ``x`` suffixes too). Markers lacking an axis are
    left out."""
    axes: dict[str, dict[str, int]] = {}
    for i, label in enumerate(channel_labels):
        match = _AXIS_SUFFIX.fullmatch(label.strip())
        if match:
            axes.setdefault(match.group(1), {})[match.group(2).lower()] = i
    return {m: (a["x"], a["y"], a["z"]) for m, a in axes.items() if len(a) == 3}


#: Length units a source may declare for its channels, and their size in metres.
UNITS_M = {"m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0, "mm": 1e-3,
           "millimeter": 1e-3, "millimeters": 1e-3, "millimetre": 1e-3, "millimetres": 1e-3}  # fmt: skip


def _need_pylsl():
    try:
        import pylsl
    except ImportError:
        raise _native.InputError("--source lsl: needs pylsl (pip install 'ikid[live]')") from None
    return pylsl


class LslSource:
    """An inlet on the LSL stream named ``name``: channel labels (``<marker>_X/_Y/_Z``) and
    units from its metadata, its nominal rate, its sample time stamps (the sender's clock)."""

    kind = "lsl"
    #: LSL's mocap metadata names no up axis: --up or the marker map's says it.
    up = None

    def __init__(self, name: str, marker_map: MarkerMap, timeout_s: float) -> None:
        self.pylsl = _need_pylsl()
        from pylsl.util import LostError

        self.lost_error = LostError
        self.name, self.marker_map = name, marker_map
        self.reconnected = 0
        self.inlet: Any = None  # a pylsl.StreamInlet once open
        if not self._open(timeout_s):
            raise _native.InputError(
                f"--source lsl:{name}: no LSL stream named {name!r} found within {timeout_s:g} s"
            )

    def _open(self, timeout_s: float, infos=None) -> bool:
        pylsl = self.pylsl
        if infos is None:
            infos = pylsl.resolve_byprop("name", self.name, minimum=1, timeout=timeout_s)
        if not infos:
            return False
        # recover=False: a vanished outlet raises LostError here, and the stream re-resolves it
        # by name (a restarted source has a new uid; liblsl's own recovery may not find it).
        inlet = pylsl.StreamInlet(infos[0], max_buflen=10, max_chunklen=1, recover=False)
        info = inlet.info(timeout=max(timeout_s, 1.0))
        labels, units = [], []
        channel = info.desc().child("channels").child("channel")
        while not channel.empty():
            labels.append(channel.child_value("label"))
            units.append(channel.child_value("unit").strip().lower())
            channel = channel.next_sibling("channel")
        source = f"LSL stream {self.name!r}"
        if len(labels) != info.channel_count():
            raise _native.InputError(
                f"{source}: its metadata labels {len(labels)} of {info.channel_count()} channels; ikid needs "
                "each channel labelled <marker>_X, _Y or _Z (as Qualisys' LSL app does)"
            )
        positions = lsl_marker_channels(labels)
        columns = marker_columns(positions, self.marker_map, source)
        scale = np.ones(len(columns))
        for k, c in enumerate(columns):
            unit = units[c] or "m"
            if unit not in UNITS_M:
                raise _native.InputError(
                    f"{source}: channel {labels[c]!r} is in {unit!r}; expected metres or millimetres"
                )
            scale[k] = UNITS_M[unit]
        self.inlet, self.columns, self.scale = inlet, columns, scale
        self.labels = list(positions)
        self.rate_hz = info.nominal_srate() or None
        self.inlet.open_stream(timeout=max(timeout_s, 1.0))
        return True

    def _frame(self, sample, stamp: float) -> LiveFrame:
        return LiveFrame(None, stamp, np.asarray(sample, np.float64)[self.columns] * self.scale)

    def read(self, timeout_s: float) -> list[LiveFrame]:
        try:
            sample, stamp = self.inlet.pull_sample(timeout=timeout_s)
            if stamp is None:
                return []
            frames = [self._frame(sample, stamp)]
            while True:  # what else has queued up: the caller decides what to skip
                sample, stamp = self.inlet.pull_sample(timeout=0.0)
                if stamp is None:
                    return frames
                frames.append(self._frame(sample, stamp))
        except self.lost_error:
            raise SourceLost(f"LSL stream {self.name!r} lost") from None

    def reconnect(self, deadline: float) -> bool:
        self.close()
        # A resolver that keeps listening (one-shot resolves of half a second were seen to
        # miss a stream that had come back on a busy machine).
        resolver = self.pylsl.ContinuousResolver(prop="name", value=self.name, forget_after=1.0)
        try:
            while time.monotonic() < deadline:
                infos = resolver.results()
                if infos:
                    try:
                        if self._open(1.0, infos[-1:]):
                            self.reconnected += 1
                            return True
                    except (TimeoutError, self.lost_error):
                        pass  # the one it saw went away meanwhile: look again
                time.sleep(0.02)
            return False
        finally:
            del resolver

    def close(self) -> None:
        if self.inlet is not None:
            self.inlet.close_stream()
            self.inlet = None


# QTM real-time protocol (little-endian, the port QTM configures for it: 22223 by default).
QTM_PORT = 22223
QTM_VERSION = "1.25"
_HEADER = struct.Struct("<II")  # packet size (header included), packet type
_DATA = struct.Struct("<qII")  # time stamp (µs), frame number, component count
_COMPONENT = struct.Struct("<II")  # component size (header included), component type
_3D = struct.Struct("<Ihh")  # marker count, 2D drop rate, out-of-sync rate
PACKET_ERROR, PACKET_COMMAND, PACKET_XML, PACKET_DATA, PACKET_NO_MORE_DATA = 0, 1, 2, 3, 4
COMPONENT_3D = 1
#: Largest packet read from QTM, bytes: 3D of 10,000 markers is 120 kB; a header claiming more
#: is a broken stream (the connection is dropped and made again), never a buffer that large.
QTM_MAX_PACKET = 1 << 20


def _text(payload: bytes) -> str:
    """A command, error or XML packet's text (NUL-terminated)."""
    return payload.rstrip(b"\0").decode("utf-8", "replace")


def qtm_packet(kind: int, payload: bytes) -> bytes:
    """One QTM real-time packet: header and payload."""
    return _HEADER.pack(_HEADER.size + len(payload), kind) + payload


class QtmSource:
    """A client of Qualisys Track Manager's real-time server at ``host:port``: labels and
    frequency from ``GetParameters General 3D``, then ``StreamFrames AllFrames 3D`` (mm, NaN
    for a hidden marker, QTM's frame numbers and µs time stamps)."""

    kind = "qtm"

    def __init__(self, host: str, port: int, marker_map: MarkerMap, timeout_s: float) -> None:
        self.host, self.port, self.marker_map = host, port, marker_map
        self.reconnected = 0
        #: "No more data" packets: QTM's measurement stopped (frames resume with the next).
        self.ended = 0
        self.sock: socket.socket | None = None
        self.pending_loss: SourceLost | None = None
        try:
            self._connect(timeout_s)
        except (OSError, SourceLost) as e:
            raise _native.InputError(f"--source qtm:{host}:{port}: {e}") from None

    def _connect(self, timeout_s: float) -> None:
        self.close()
        self.buf = bytearray()
        self.sock = socket.create_connection((self.host, self.port), timeout=timeout_s)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._expect(PACKET_COMMAND, timeout_s)  # "QTM RT Interface connected"
        self._command(f"Version {QTM_VERSION}")
        reply = self._expect(PACKET_COMMAND, timeout_s)
        if not reply.lower().startswith(b"version set"):
            raise SourceLost(f"QTM refused protocol version {QTM_VERSION}: {reply!r}")
        self._command("GetParameters General 3D")
        xml = self._expect(PACKET_XML, timeout_s)
        self._parameters(_text(xml))
        self._command("StreamFrames AllFrames 3D")

    def _parameters(self, xml: str) -> None:
        source = f"QTM at {self.host}:{self.port}"
        try:
            root = ET.fromstring(xml)
        except ET.ParseError as e:
            raise SourceLost(f"{source}: its parameters are not XML: {e}") from None
        names = [n.text or "" for n in root.findall("./The_3D/Label/Name")]
        frequency = root.findtext("./General/Frequency")
        self.labels = names
        self.rate_hz = float(frequency) if frequency else None
        #: The lab axis QTM's 3D data has pointing up (its AxisUpwards: "+Z" by default).
        self.up = _qtm_up(root.findtext("./The_3D/AxisUpwards"))
        positions = {name: (3 * k, 3 * k + 1, 3 * k + 2) for k, name in enumerate(names)}
        self.columns = marker_columns(positions, self.marker_map, source)
        self.n_markers = len(names)

    def _command(self, text: str) -> None:
        assert self.sock is not None
        self.sock.sendall(qtm_packet(PACKET_COMMAND, text.encode() + b"\0"))

    def _fill(self) -> None:
        assert self.sock is not None
        try:
            data = self.sock.recv(1 << 16)
        except (BlockingIOError, TimeoutError):
            raise  # nothing more yet: the caller's to decide
        except OSError as e:
            raise SourceLost(f"QTM connection lost: {e}") from None
        if not data:
            raise SourceLost("QTM closed the connection")
        self.buf += data

    def _next_packet(self) -> tuple[int, bytes] | None:
        """The next whole packet in the buffer, or None."""
        if len(self.buf) < _HEADER.size:
            return None
        size, kind = _HEADER.unpack_from(self.buf, 0)
        if not _HEADER.size <= size <= QTM_MAX_PACKET:
            raise SourceLost(f"QTM packet of {size} bytes (the stream is broken)")
        if len(self.buf) < size:
            return None
        payload = bytes(self.buf[_HEADER.size : size])
        del self.buf[:size]
        return kind, payload

    def _expect(self, kind: int, timeout_s: float) -> bytes:
        assert self.sock is not None
        self.sock.settimeout(timeout_s)
        while True:
            packet = self._next_packet()
            if packet is None:
                self._fill()
                continue
            got, payload = packet
            if got == PACKET_ERROR:
                raise SourceLost("QTM: " + _text(payload))
            if got == kind:
                return payload

    def _frame(self, payload: bytes) -> LiveFrame | None:
        stamp_us, number, n_components = _DATA.unpack_from(payload, 0)
        offset = _DATA.size
        for _ in range(n_components):
            size, kind = _COMPONENT.unpack_from(payload, offset)
            if size < _COMPONENT.size or offset + size > len(payload):
                return LiveFrame(number, stamp_us * 1e-6, None, "a data component overruns its packet")
            if kind == COMPONENT_3D:
                count = _3D.unpack_from(payload, offset + _COMPONENT.size)[0]
                start = offset + _COMPONENT.size + _3D.size
                if count != self.n_markers or start + 12 * count > offset + size:
                    return LiveFrame(
                        number,
                        stamp_us * 1e-6,
                        None,
                        f"3D component of {count} markers, expected {self.n_markers}",
                    )
                xyz = np.frombuffer(payload, "<f4", 3 * count, start)
                return LiveFrame(number, stamp_us * 1e-6, xyz[self.columns].astype(np.float64) * 1e-3)
            offset += size
        return LiveFrame(number, stamp_us * 1e-6, None, "no 3D component in the data packet")

    def read(self, timeout_s: float) -> list[LiveFrame]:
        if self.sock is None:
            raise SourceLost("not connected")
        if self.pending_loss is not None:
            loss, self.pending_loss = self.pending_loss, None
            raise loss
        frames: list[LiveFrame] = []
        self.sock.settimeout(timeout_s)
        while True:
            packet = self._next_packet()
            if packet is None:
                if frames:
                    # Whatever else has already arrived, without waiting.
                    self.sock.setblocking(False)
                    try:
                        self._fill()
                    except (BlockingIOError, TimeoutError):
                        return frames
                    except SourceLost as e:
                        self.pending_loss = e  # the frames read before it first
                        return frames
                    finally:
                        self.sock.settimeout(timeout_s)
                    continue
                try:
                    self._fill()
                except TimeoutError:
                    return frames
                continue
            kind, payload = packet
            if kind == PACKET_DATA:
                frame = self._frame(payload)
                if frame is not None:
                    frames.append(frame)
            elif kind == PACKET_NO_MORE_DATA:
                self.ended += 1
            elif kind == PACKET_ERROR:
                raise SourceLost("QTM: " + _text(payload))

    def reconnect(self, deadline: float) -> bool:
        while time.monotonic() < deadline:
            try:
                self._connect(min(1.0, max(0.05, deadline - time.monotonic())))
                self.reconnected += 1
                return True
            except (OSError, SourceLost, _native.InputError):
                self.close()
                time.sleep(0.05)
        return False

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


def _qtm_up(axis: str | None) -> str | None:
    """ikid's name (:data:`ikid.io.UP_AXES`) of QTM's AxisUpwards (``+Z``, ``-Y``, ...); None
    when QTM does not say, or says what is not an axis."""
    try:
        return parse_up(axis.strip(), "AxisUpwards") if axis else None
    except _native.IkidError:
        return None


def open_source(spec: str, marker_map: MarkerMap, timeout_s: float):
    """The source a ``--source`` value names: ``lsl:<stream name>`` or ``qtm:<host>[:<port>]``."""
    kind, _, rest = spec.partition(":")
    if kind == "lsl" and rest:
        return LslSource(rest, marker_map, timeout_s)
    if kind == "qtm" and rest:
        host, _, port = rest.partition(":")
        try:
            number = int(port) if port else QTM_PORT
        except ValueError:
            raise _native.InputError(f"--source {spec}: port {port!r} is not a number") from None
        if not 0 < number < 65536:
            raise _native.InputError(f"--source {spec}: port {number} is not in 1-65535")
        return QtmSource(host, number, marker_map, timeout_s)
    raise _native.InputError(
        f"--source {spec!r}: expected lsl:<stream name> or qtm:<host>[:<port>] "
        "(stdin and --udp are the default)"
    )
