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

Optionally, for ``ikid calibrate`` (see ``ikid.calibration``): the arm, and the labels of
the forearm's anatomical landmarks (markers, or virtual points from a probing file), any of
lateral_epicondyle, medial_epicondyle, radial_styloid, ulnar_styloid (all four for the
landmark method), and the hand's second_metacarpal_head and fifth_metacarpal_head (both, or
neither: with them the hand's frame is its own)::

    side = "right"       # or "left" (mirrored into a right arm); before the tables
    [markers]
    ...
    [landmarks]
    lateral_epicondyle = "EPICl"
    medial_epicondyle = "EPICm"
    radial_styloid = "STYLr"
    ulnar_styloid = "STYLu"
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ikid import _native
from ikid.io._common import FileFormatError, ikid_marker_names, read_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

if TYPE_CHECKING:
    from ikid.io.markers import MarkerData


@dataclass(frozen=True)
class MarkerMap:
    """ikid marker name -> the label a lab's files use for it; optionally the arm's side and
    landmark name -> label (see the module docstring)."""

    labels: dict[str, str]
    source: str = "identity"
    landmarks: dict[str, str] = field(default_factory=dict)
    side: str = "right"

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
        side = table.get("side", "right")
        if side not in ("right", "left"):
            raise FileFormatError(f'{source}: side = {side!r}; expected "right" or "left"')
        landmarks = table.get("landmarks", {})
        known = landmark_names() + hand_landmark_names()
        if not isinstance(landmarks, dict):
            raise FileFormatError(f"{source}: [landmarks] must be a table of landmark = label")
        unknown = sorted(set(landmarks) - set(known))
        if unknown:
            raise FileFormatError(
                f"{source}: unknown landmark(s) {', '.join(unknown)}; the landmarks are {', '.join(known)}"
            )
        bad = [k for k, v in landmarks.items() if not isinstance(v, str) or not v.strip()]
        if bad:
            raise FileFormatError(
                f"{source}: the label for landmark {', '.join(bad)} must be a non-empty string"
            )
        for k, v in landmarks.items():
            if v.strip() in seen:
                raise FileFormatError(
                    f"{source}: label {v!r} is given to both marker {seen[v.strip()]} and landmark {k}"
                )
        return MarkerMap(
            {m: markers[m].strip() for m in names},
            source,
            {k: landmarks[k].strip() for k in known if k in landmarks},
            side,
        )

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

    def landmark_labels_in_order(self, data: MarkerData) -> list[str]:
        """The file's labels for the four landmarks, in ``ikid.Calibration.LANDMARKS`` order;
        an error names what the map or the file lacks."""
        missing = [k for k in landmark_names() if k not in self.landmarks]
        if missing:
            raise _native.InputError(
                f"{self.source}: [landmarks] does not name {', '.join(missing)}; the landmark method "
                f"needs all of {', '.join(landmark_names())} (or calibrate from the neutral posture alone)"
            )
        labels = [self.landmarks[k] for k in landmark_names()]
        absent = [
            f"{lab} ({k})" for k, lab in zip(landmark_names(), labels, strict=True) if lab not in data.labels
        ]
        if absent:
            raise _native.InputError(
                f"{data.source or 'markers'}: landmark label(s) {', '.join(absent)} not found; the file has "
                f"{', '.join(data.labels) or 'no labels'}"
            )
        return labels

    def hand_landmark_labels_in_order(self, data: MarkerData) -> list[str] | None:
        """The file's labels for the hand's two landmarks (``ikid.Calibration.HAND_LANDMARKS``
        order), None when the map names neither; an error when it names one only or the file
        lacks one."""
        named = [k for k in hand_landmark_names() if k in self.landmarks]
        if not named:
            return None
        if len(named) < len(hand_landmark_names()):
            raise _native.InputError(
                f"{self.source}: [landmarks] names {named[0]} but not the other hand landmark; the hand's "
                f"frame needs both of {', '.join(hand_landmark_names())} (or neither)"
            )
        labels = [self.landmarks[k] for k in hand_landmark_names()]
        absent = [
            f"{lab} ({k})"
            for k, lab in zip(hand_landmark_names(), labels, strict=True)
            if lab not in data.labels
        ]
        if absent:
            raise _native.InputError(
                f"{data.source or 'markers'}: landmark label(s) {', '.join(absent)} not found; the file has "
                f"{', '.join(data.labels) or 'no labels'}"
            )
        return labels

    def to_toml(self) -> str:
        descr = {m[0]: m[2] for m in _native.MARKERS}
        lines = [
            "# ikid marker = the label in your C3D/TRC files",
            f'side = "{self.side}"  # or "left": the arm these markers are on',
            "[markers]",
        ]
        lines += [f'{m} = "{lab}"  # {descr[m]}' for m, lab in self.labels.items()]
        lm_descr = dict(_native.Calibration.LANDMARKS) | dict(_native.Calibration.HAND_LANDMARKS)
        lines += [
            "",
            "# optional, for `ikid calibrate` from anatomical landmarks: their labels",
            "[landmarks]",
        ]
        for k in landmark_names() + hand_landmark_names():
            if k in self.landmarks:
                lines.append(f'{k} = "{self.landmarks[k]}"  # {lm_descr[k]}')
            else:
                lines.append(f'# {k} = "LABEL"  # {lm_descr[k]}')
        return "\n".join(lines) + "\n"


def landmark_names() -> list[str]:
    """The forearm's landmarks a marker map may name, in ``ikid.Calibration.LANDMARKS`` order."""
    return [name for name, _ in _native.Calibration.LANDMARKS]


def hand_landmark_names() -> list[str]:
    """The hand's optional landmarks, in ``ikid.Calibration.HAND_LANDMARKS`` order."""
    return [name for name, _ in _native.Calibration.HAND_LANDMARKS]
