"""Live sources and sinks for ``ikid stream``: Lab Streaming Layer and Qualisys Track Manager's
real-time protocol in, LSL out, and bounded text input (stdin, UDP) for everything else.

Every source gives :class:`LiveFrame` batches (the frames that arrived since the last read, in
order) and counts what it lost on its side; ``ikid stream`` feeds them to the models and
counts every refusal, skip and reconnection in its summary. See docs/live.md.
"""

from __future__ import annotations

from ikid.live.sources import (
    MAX_LINE_BYTES,
    LiveFrame,
    LslSource,
    QtmSource,
    SourceLost,
    bounded_lines,
    marker_columns,
    open_source,
)

__all__ = [
    "MAX_LINE_BYTES",
    "LiveFrame",
    "LslSource",
    "QtmSource",
    "SourceLost",
    "bounded_lines",
    "marker_columns",
    "open_source",
]
