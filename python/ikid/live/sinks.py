"""Where live outputs go besides stdout's CSV: an LSL outlet."""

from __future__ import annotations

import time

import numpy as np

from ikid.live.sources import _need_pylsl

#: LSL stream type of ikid's output (XDF readers group streams by it).
LSL_OUTPUT_TYPE = "Kinematics"
#: How long a closing sink waits for its readers to take the last samples, s.
DRAIN_S = 0.2
#: Channel holding the frame's status bits (ikid.STATUS_* / IKID_FRAME_*).
STATUS_CHANNEL = "status"


class LslSink:
    """An LSL outlet named ``name`` publishing each output frame: the output columns (labels
    and units in the stream's metadata) and the status bits, stamped with the source frame's
    time."""

    def __init__(
        self, name: str, columns: list[str], units: list[str], rate_hz: float, source_id: str = ""
    ) -> None:
        pylsl = _need_pylsl()
        self.columns = list(columns) + [STATUS_CHANNEL]
        info = pylsl.StreamInfo(
            name, LSL_OUTPUT_TYPE, len(self.columns), rate_hz, pylsl.cf_double64, source_id or f"ikid-{name}"
        )
        channels = info.desc().append_child("channels")
        for column, unit in zip(self.columns, [*units, "bits"], strict=True):
            channel = channels.append_child("channel")
            channel.append_child_value("label", column)
            channel.append_child_value("unit", unit)
            channel.append_child_value("type", "status" if column == STATUS_CHANNEL else "output")
        info.desc().append_child_value("manufacturer", "ikid")
        self.outlet = pylsl.StreamOutlet(info, chunk_size=1, max_buffered=10)
        self.sample = np.zeros(len(self.columns), np.float64)
        self.published = 0

    def publish(self, values: np.ndarray, status: int, stamp: float) -> None:
        self.sample[:-1] = values
        self.sample[-1] = status
        self.outlet.push_sample(self.sample, stamp)
        self.published += 1

    def close(self) -> None:
        # liblsl has no flush, and an outlet destroyed at once drops what its send thread has
        # not sent yet: give a connected reader a moment to take the last samples.
        if self.outlet.have_consumers():
            time.sleep(DRAIN_S)
        del self.outlet
