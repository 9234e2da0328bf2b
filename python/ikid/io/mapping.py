"""Which of a lab's marker labels is which ikid marker: a small TOML file.

Example (``ikid map-template`` prints one)::

    # ikid marker = the label in your C3D/TRC files
    [markers]
    RSP = "R_RSTY"   # radial styloid process
    USP = "R_USTY"   # ulnar styloid process
    FAP = "R_FA"
    MC2 = "R_MCP2"
    MC5 = "R_MCP5"
    MCB = "R_MCB3"

Every ikid marker must be named, each by a different label; the file may have more labels
than these (they are ignored).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ikid import _native
from ikid.io.markers import FileFormatError, ikid_marker_names, read_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

if TYPE_CHECKING:
    from ikid.io.markers import MarkerData


@dataclass(frozen=True)
class MarkerMap:
    """ikid marker name -> the label a lab's files use for it."""

    labels: dict[str, str]
    source: str = "identity"

    @staticmethod
    def identity() -> MarkerMap:
        return MarkerMap({m: m for m in ikid_marker_names()})

    @staticmethod
    def from_dict(table: dict, source: str = "marker map") -> MarkerMap:
        names = ikid_marker_names()
        markers = table.get("markers")
        if not isinstance(markers, dict):
            raise FileFormatError(
                f"{source}: expected a [markers] table mapping each of {', '.join(names)} to a label"
            )
        unknown = sorted(set(markers) - set(names))
        if unknown:
            raise FileFormatError(
                f"{source}: unknown ikid marker(s) {', '.join(unknown)}; ikid's "
                f"markers are {', '.join(names)}"
            )
        missing = [m for m in names if m not in markers]
        if missing:
            raise FileFormatError(
                f"{source}: [markers] does not name {', '.join(missing)} (every one of "
                f"{', '.join(names)} is needed)"
            )
        bad = [m for m in names if not isinstance(markers[m], str) or not markers[m].strip()]
        if bad:
            raise FileFormatError(f"{source}: the label for {', '.join(bad)} must be a non-empty string")
        seen: dict[str, str] = {}
        for m in names:
            if markers[m] in seen:
                raise FileFormatError(
                    f"{source}: label {markers[m]!r} is given to both {seen[markers[m]]} and {m}"
                )
            seen[markers[m]] = m
        return MarkerMap({m: markers[m].strip() for m in names}, source)

    @staticmethod
    def load(path: str | os.PathLike[str]) -> MarkerMap:
        path = Path(path)
        try:
            table = tomllib.loads(read_text(path, "a marker map is TOML text"))
        except tomllib.TOMLDecodeError as e:
            raise FileFormatError(f"{path}: not valid TOML: {e}") from None
        return MarkerMap.from_dict(table, str(path))

    def label_of(self, name: str) -> str:
        return self.labels[name]

    def labels_in_ikid_order(self, data: MarkerData) -> list[str]:
        """The file's labels for ikid's markers, in ikid's order; an error lists what the file
        has if any is absent."""
        wanted = [self.labels[m] for m in ikid_marker_names()]
        absent = [f"{lab} ({m})" for m, lab in self.labels.items() if lab not in data.labels]
        if absent:
            hint = (
                ""
                if self.source != "identity"
                else " (give a marker map: --map FILE.toml, see `ikid map-template`)"
            )
            raise _native.InputError(
                f"{data.source or 'markers'}: label(s) {', '.join(absent)} not found; the file has "
                f"{', '.join(data.labels) or 'no labels'}{hint}"
            )
        return wanted

    def to_toml(self) -> str:
        descr = {m[0]: m[2] for m in _native.MARKERS}
        lines = ["# ikid marker = the label in your C3D/TRC files", "[markers]"]
        lines += [f'{m} = "{lab}"  # {descr[m]}' for m, lab in self.labels.items()]
        return "\n".join(lines) + "\n"
