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
than these (they are ignored). A marker may also be a landmark of its own segment (RSP on the
radial styloid given as ``radial_styloid`` too).

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

A segment marked by more than three markers (a four-marker plate, a cluster of skin markers)
names three of them in ``[markers]`` and the rest in ``[cluster]``, per segment: each frame the
cluster's rigid shape (learned from the recording) is fitted to every one of its markers seen,
and the three take the places the fit gives them (core ``cluster``)::

    [cluster]
    forearm = ["R_FA4"]
    hand = ["R_H4", "R_H5"]
"""

from __future__ import annotations

import difflib
import json
import os
import re
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ikid import _native
from ikid.io import cluster_fit, marker_checks
from ikid.io._common import FileFormatError, ikid_marker_names, parse_up, read_text
from ikid.io._common import MarkerMapWarning as MarkerMapWarning  # its old home, re-exported

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
    #: Segment -> the labels of further markers rigid with its three (``[cluster]``).
    clusters: dict[str, tuple[str, ...]] = field(default_factory=dict)
    #: The clusters' shapes learned so far (:data:`cluster_fit.Shapes`): every block of a file is
    #: fitted with one shape.
    _shapes: cluster_fit.Shapes = field(default_factory=dict, compare=False, repr=False)
    #: A one-marker hand whose forearm markers are a cluster, not its anatomical points.
    forearm_cluster: bool = False
    #: For such a map: the radial styloid, the ulnar styloid and the mid-epicondyles ``(3, 3)``,
    #: metres, in the technical frame of RSP, USP, FAP (core ``cluster::technical_frame``), as a
    #: calibration measured them (``ikid.calibration.map_with_calibration``).
    forearm_landmarks: np.ndarray | None = field(default=None, compare=False, repr=False)
    #: For a one-marker hand: its marker's distance from the mid-styloids as a calibration
    #: measured it (m), which a trial's must keep (:func:`marker_checks.check_hand_point`).
    hand_point_m: float | None = field(default=None, compare=False, repr=False)
    #: The lab axis pointing up (one of ``UP_AXES``), if the map says: it decides over the
    #: file's declaration (``MarkerData.lab_up``). Torques depend on it, angles do not.
    up: str | None = None

    @staticmethod
    def identity() -> MarkerMap:
        return MarkerMap({m: m for m in ikid_marker_names()})

    @staticmethod
    def from_dict(table: dict, source: str = "marker map") -> MarkerMap:
        six = ikid_marker_names()
        hand_point = _native.HAND_POINT[0]
        # A mistyped key is an error, never a default: `sid = "left"` read a left arm as a right
        # one (50-93° off), `[landmark]` sent calibrate to another method.
        unknown_keys = sorted(set(table) - set(_MAP_KEYS))
        if unknown_keys:
            raise FileFormatError(
                f"{source}: unknown key(s) "
                + ", ".join(
                    repr(k)
                    + "".join(f" (did you mean {m!r}?)" for m in difflib.get_close_matches(k, _MAP_KEYS, 1))
                    for k in unknown_keys
                )
                + f"; a marker map has {', '.join(_MAP_KEYS)}"
            )
        markers = table.get("markers")
        if not isinstance(markers, dict):
            raise FileFormatError(
                f"{source}: expected a [markers] table mapping each of {', '.join(six)} to a label"
            )
        unknown = sorted(set(markers) - set(six) - {hand_point})
        if unknown:
            raise FileFormatError(
                f"{source}: unknown ikid marker(s) {', '.join(unknown)}; ikid's "
                f"markers are {', '.join(six)} (or {hand_point} for a hand with one marker)"
            )
        forearm = [m for m in six if _segment(m) == "forearm"]
        hand = [m for m in six if _segment(m) == "hand"]
        if hand_point in markers and any(m in markers for m in hand):
            raise FileFormatError(
                f"{source}: [markers] names {hand_point} and {', '.join(m for m in hand if m in markers)}; "
                f"a hand is three markers ({', '.join(hand)}) or one ({hand_point}), not both"
            )
        names = forearm + ([hand_point] if hand_point in markers else hand)
        missing = [m for m in names if m not in markers]
        if missing:
            named_hand = [m for m in hand if m in markers]
            hint = (
                f" (a hand needs three markers, {', '.join(hand)}, for all three angles; with one marker on "
                f"it, name it {hand_point}: flexion and deviation are written, not {_undetermined_name()}, "
                "the hand's roll about its own axis which one marker does not show)"
                if any(m in hand for m in missing) and len(named_hand) < len(hand)
                else ""
            )
            if len(named_hand) == 2 and hand_point not in markers:
                # Measured (docs/markersets.md): the wrist's centre found from the movement as the
                # third point read real wrists 5-17 degrees off; ikid does not guess the third.
                hint += (
                    " (two hand markers do not fix the hand's turn about the line through them: the "
                    "wrist's centre as the third point, found from the hand's movement, read real wrists "
                    f"5-17 degrees off, so ikid does not use it; name the distal one {hand_point} instead, "
                    "or add a third)"
                )
            raise FileFormatError(
                f"{source}: [markers] does not name {', '.join(missing)} (every one of "
                f"{', '.join(names)} is needed){hint}"
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
        up = parse_up(table["up"], source) if "up" in table else None
        side = table.get("side", "right")
        if side not in ("right", "left"):
            raise FileFormatError(f'{source}: side = {side!r}; expected "right" or "left"')
        # Plug-in Gait names its markers by arm (LWRA, RWRA): its wrist bar, elbow and finger
        # markers all of the other arm than `side` would be read mirrored, every flexion as an
        # extension (measured on a real recording: r = -0.996 against Vicon's angles).
        other, other_side = {"right": ("L", "left"), "left": ("R", "right")}[side]
        pig = {"RSP": "WRA", "USP": "WRB", "FAP": "ELB", hand_point: "FIN"}
        if all(str(markers.get(m, "")).strip().endswith(other + name) for m, name in pig.items()):
            raise FileFormatError(
                f"{source}: side = {side!r}, but [markers] names Plug-in Gait's {other_side} arm ("
                + ", ".join(f"{m} = {markers[m].strip()!r}" for m in pig)
                + f"): the {other_side} arm read as the {side} would give every angle mirrored; set side = "
                f'"{other_side}" (or name the {side} arm\'s markers)'
            )
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
        _check_side_against_labels(source, side, markers, landmarks)
        one_hand = hand_point in markers
        # With one hand marker, the forearm's three are its anatomical points themselves (Plug-in
        # Gait's wrist bar and elbow: the styloid landmarks are RSP's and USP's labels), or a
        # cluster whose anatomical points a static trial's landmarks give.
        forearm_cluster = one_hand and any(
            k in landmarks and str(landmarks[k]).strip() != markers[m]
            for k, m in (("radial_styloid", "RSP"), ("ulnar_styloid", "USP"))
        )
        if forearm_cluster:
            lacking = [k for k in landmark_names() if k not in landmarks]
            if lacking:
                raise FileFormatError(
                    f"{source}: [markers] names {hand_point} and forearm markers that are not the styloids "
                    f"(RSP {markers['RSP']!r}, USP {markers['USP']!r}): a forearm cluster. With one hand "
                    "marker the hand's direction is measured in the forearm's anatomical frame, which a "
                    f"static trial's landmarks give; [landmarks] does not name {', '.join(lacking)} (all "
                    f"of {', '.join(landmark_names())} are needed; the medial epicondyle may be the "
                    "lateral's label when there is none)"
                )
        clusters = _clusters(table.get("cluster", {}), source, seen, one_hand, forearm_cluster)
        # A marker may also be a landmark (RSP on the radial styloid named radial_styloid too), on
        # its own segment only: a forearm landmark on a hand marker moves with the hand.
        segment_of = {m: _segment(m) for m in names}
        for segment, extra in clusters.items():
            for label in extra:
                seen[label] = f"in the {segment}'s [cluster]"
                segment_of[seen[label]] = segment
        forearm_landmarks = set(landmark_names())
        for k, v in landmarks.items():
            marker = seen.get(v.strip())
            if marker is None:
                continue
            landmark_segment = "forearm" if k in forearm_landmarks else "hand"
            if segment_of[marker] != landmark_segment:
                raise FileFormatError(
                    f"{source}: label {v!r} is given to marker {marker} (on the {segment_of[marker]}) and to "
                    f"landmark {k} (on the {landmark_segment}); a marker can be a landmark of its own "
                    "segment "
                    "only: give the landmark its own label"
                )
        # The wrist's angles are the hand's in the radius (its proximal bone; ISB). Three forearm
        # markers one of which is on the ulna (which stays while the radius turns about it in
        # pronation) are no body the hand turns against: they read a share of the pronation as
        # wrist rotation, which they cannot tell apart (pyomeca: 8-14 deg off the radius-fixed
        # reference). A one-marker hand on a wrist bar builds its forearm anew each frame and is
        # not concerned.
        ulnar = str(landmarks.get("ulnar_styloid", "")).strip()
        radial = str(landmarks.get("radial_styloid", "")).strip()
        bar = (str(markers.get("RSP", "")).strip(), str(markers.get("USP", "")).strip())
        if one_hand and (radial, ulnar) == bar[::-1] and radial != ulnar:
            # The wrist bar's two markers named one way in [markers] and the other in
            # [landmarks]: which is right cannot be known, and either way round the other is
            # read as a forearm cluster with a marker on the ulna.
            raise FileFormatError(
                f"{source}: RSP {bar[0]!r} and USP {bar[1]!r} are the landmarks ulnar_styloid and "
                "radial_styloid, the other way round: with one hand marker RSP and USP are the wrist "
                "bar on the styloids, RSP the radial one (the thumb side, Plug-in Gait's WRA) and USP "
                "the ulnar one (WRB); make [markers] and [landmarks] name them alike"
            )
        if (not one_hand or forearm_cluster) and segment_of.get(seen.get(ulnar, ""), "") == "forearm":
            where = (
                "in the forearm's [cluster]"
                if seen[ulnar].startswith("in ")
                else f"forearm marker {seen[ulnar]}"
            )
            raise FileFormatError(
                f"{source}: label {ulnar!r} is {where} and landmark ulnar_styloid: "
                "a marker on the ulna, which stays while the radius turns about it in pronation. The "
                "hand's angles are measured from the radius, and three forearm markers one of which is on "
                "the ulna turn with neither bone: they read part of the forearm's pronation as wrist "
                "rotation, and how much cannot be known from them (measured on a real recording: 8-14 "
                "degrees off). Name as RSP, USP and FAP three markers on the distal radius or a cluster "
                "strapped to it (the radial styloid may be one of them; more in [cluster]), and the ulnar "
                "styloid in [landmarks] only"
            )
        return MarkerMap(
            {m: markers[m].strip() for m in names},
            source,
            {k: landmarks[k].strip() for k in known if k in landmarks},
            side,
            clusters,
            forearm_cluster=forearm_cluster,
            up=up,
        )

    @staticmethod
    def plug_in_gait(side: str = "right", prefix: str = "") -> MarkerMap:
        """Plug-in Gait's upper limb (per arm SHO, UPA, ELB, FRM, WRA, WRB, FIN) as ikid's
        one-hand-marker set: the wrist bar (WRA thumb side, WRB little-finger side) on the
        styloids as RSP/USP and the styloid landmarks, ELB (lateral epicondyle) as FAP and the
        elbow's landmark (named for both epicondyles: Plug-in Gait has no medial one), FIN as
        HND. SHO, UPA and FRM are not used. ``prefix``: the labels' (e.g. ``"Subject:"``)."""
        p = prefix + {"right": "R", "left": "L"}[side]
        table = {
            "side": side,
            "markers": {
                "RSP": f"{p}WRA",
                "USP": f"{p}WRB",
                "FAP": f"{p}ELB",
                _native.HAND_POINT[0]: f"{p}FIN",
            },
            "landmarks": {
                "lateral_epicondyle": f"{p}ELB",
                "medial_epicondyle": f"{p}ELB",
                "radial_styloid": f"{p}WRA",
                "ulnar_styloid": f"{p}WRB",
            },
        }
        return MarkerMap.from_dict(table, f"Plug-in Gait, {side} arm")

    @staticmethod
    def recognise(labels: list[str] | tuple[str, ...], side: str | None = None) -> MarkerMap | None:
        """The shipped set a file's labels are (Plug-in Gait: WRA, WRB, ELB and FIN of one arm,
        with or without a ``Subject:`` prefix), as a map of ``side`` (default: the right arm if
        it is there, else the left); None when no shipped set fits."""
        for s in [side] if side else ["right", "left"]:
            letter = {"right": "R", "left": "L"}[s]
            for label in labels:
                if label.endswith(f"{letter}WRA"):
                    prefix = label[: -len(f"{letter}WRA")]
                    wanted = [f"{prefix}{letter}{m}" for m in ("WRB", "ELB", "FIN")]
                    if all(w in labels for w in wanted):
                        return MarkerMap.plug_in_gait(s, prefix)
        return None

    @staticmethod
    def load(path: str | os.PathLike[str]) -> MarkerMap:
        path = Path(path)
        try:
            table = tomllib.loads(read_text(path, "a marker map is TOML text"))
        except tomllib.TOMLDecodeError as e:
            raise FileFormatError(f"{path}: not valid TOML: {e}") from None
        return MarkerMap.from_dict(table, str(path))

    def label_of(self, name: str) -> str:
        if name not in self.labels and self.one_hand_marker:
            return f"virtual, from {_native.HAND_POINT[0]} {self.labels[_native.HAND_POINT[0]]!r}"
        return self.labels[name]

    def marker_names(self) -> list[str]:
        """The ikid markers this map names, in frame order: the forearm's three, then the
        hand's three, or its one (``HND``)."""
        six = ikid_marker_names()
        return six[:3] + ([_native.HAND_POINT[0]] if self.one_hand_marker else six[3:])

    @property
    def one_hand_marker(self) -> bool:
        """The hand is one marker (``HND``): its three are virtual (core ``body::hand_from_one_marker``)."""
        return _native.HAND_POINT[0] in self.labels

    @property
    def undetermined(self) -> dict[str, str]:
        """Coordinates these markers do not determine -> why: they are not written (no column)."""
        if not self.one_hand_marker:
            return {}
        label = self.labels[_native.HAND_POINT[0]]
        return {
            _undetermined_name(): f"the hand is one marker ({_native.HAND_POINT[0]} = {label!r}): its roll "
            "about its own long axis is not observed, so the rotation about the forearm's axis that the "
            "Y-Z-X order "
            "gives first is not known; flexion and deviation are the hand's direction in the forearm"
        }

    def stretched_segments(self, frames: np.ndarray) -> list[str]:
        """Pairs of a segment's markers, as this map names them, whose distance changes more
        than one segment's do: sentences naming them (:func:`marker_checks.stretched_segments`)."""
        return marker_checks.stretched_segments(self, frames)

    def swapped_across_segments(self, frames: np.ndarray) -> str | None:
        """A sentence when a forearm and a hand marker, as this map names them, are each
        other's (:func:`marker_checks.swapped_across_segments`); None otherwise."""
        return marker_checks.swapped_across_segments(self, frames)

    def hand_held_to_forearm(self, frames: np.ndarray) -> str | None:
        """A sentence when the hand's markers, as this map names them, do not move on the
        forearm (:func:`marker_checks.hand_held_to_forearm`); None when they do."""
        return marker_checks.hand_held_to_forearm(self, frames)

    def flat_segments(self, frames: np.ndarray) -> list[str]:
        """Segments whose three markers lie on a line in most frames: sentences naming them
        (:func:`marker_checks.flat_segments`)."""
        return marker_checks.flat_segments(self, frames)

    def ikid_frames(self, columns: np.ndarray, *, check: bool = True) -> np.ndarray:
        """ikid's ``(n, 18)`` frames from the mapped labels' columns (``labels_in_ikid_order``):
        as they are, or, for a one-marker hand, with its three markers made virtual (and a
        forearm cluster's three its anatomical points: :meth:`anatomical_forearm`).
        ``check``: see :meth:`anatomical_forearm`."""
        if not self.one_hand_marker:
            return columns
        forearm = self.anatomical_forearm(columns, check=check)
        return _native.hand_from_one_marker(forearm, left=self.side == "left")

    def anatomical_forearm(self, columns: np.ndarray, *, check: bool = True) -> np.ndarray:
        """A one-marker hand's ``(n, 12)`` columns with a forearm cluster's three replaced by the
        anatomical points its calibration places in the cluster's frame: the radial and ulnar
        styloids and the mid-epicondyles, as Plug-in Gait's wrist bar and elbow give them. As
        they are for a forearm marked at those points. ``check``: the wrist bar checked to sit
        there (:func:`marker_checks.check_wrist_bar`) and the hand marker as far from the wrist
        as calibrated (:func:`marker_checks.check_hand_point`); a live stream checks its first
        frames once and then converts one frame at a time. An error says what to do when no
        calibration gave a cluster's points."""
        if not self.forearm_cluster:
            if check:
                marker_checks.check_wrist_bar(self, columns)
                marker_checks.check_hand_point(self, columns)
            return columns
        if self.forearm_landmarks is None:
            raise _native.InputError(
                f"{self.source}: the forearm's markers (RSP {self.labels['RSP']!r}, USP "
                f"{self.labels['USP']!r}, FAP {self.labels['FAP']!r}) are a cluster and the hand one marker "
                f"({_native.HAND_POINT[0]} {self.labels[_native.HAND_POINT[0]]!r}): the hand's direction is "
                "measured in the forearm's anatomical frame, which the landmarks of a static trial give. "
                "Calibrate with them (`ikid calibrate --static STATIC --map MAP -o CAL.json`) and pass "
                "--calibration CAL.json"
            )
        columns = np.array(columns, np.float64)
        columns[:, :9] = _native.points_from_technical_frame(columns[:, :9], self.forearm_landmarks)
        if check:
            marker_checks.check_hand_point(self, columns)
        return columns

    def forearm_landmark_points(self, data: MarkerData) -> np.ndarray:
        """``(n, 9)``: the radial styloid, the ulnar styloid and the mid-epicondyles from the
        map's landmark labels in ``data`` (metres, NaN where one is missing)."""
        lateral, medial, radial, ulnar = (
            data.marker(lab, self.up) for lab in self.landmark_labels_in_order(data)
        )
        return np.concatenate([radial, ulnar, (lateral + medial) / 2.0], axis=1)

    def with_hand_point_distance(self, distance_m: float) -> MarkerMap:
        """This map with its one hand marker's calibrated distance from the wrist (see
        :attr:`hand_point_m`)."""
        return replace(self, hand_point_m=float(distance_m))

    def with_forearm_landmarks(self, local: np.ndarray) -> MarkerMap:
        """This map with a forearm cluster's anatomical points ``(3, 3)`` (see
        :attr:`forearm_landmarks`)."""
        return replace(self, forearm_landmarks=np.asarray(local, np.float64).reshape(3, 3))

    def fit_clusters(self, data: MarkerData, columns: np.ndarray) -> np.ndarray:
        """``columns`` (``labels_in_ikid_order``'s) with each ``[cluster]`` segment's three
        markers where its rigid shape, fitted to every marker of it seen, puts them
        (:func:`cluster_fit.fit_clusters`; the shape learned from a file's first block is kept
        in this map for the rest)."""
        return cluster_fit.fit_clusters(self, data, columns, self._shapes)

    def labels_in_ikid_order(self, data: MarkerData) -> list[str]:
        """The file's labels for ikid's markers, in ikid's order; an error lists what the file
        has if any is absent."""
        wanted = [self.labels[m] for m in self.marker_names()]
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
                f"{', '.join(data.labels) or 'no labels'} (landmarks recorded or probed in another file: "
                "ikid calibrate --landmarks FILE)"
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
        descr = {m[0]: m[2] for m in _native.MARKERS} | {_native.HAND_POINT[0]: _native.HAND_POINT[2]}
        if self.one_hand_marker and not self.forearm_cluster:
            # The wrist bar's set puts FAP on the elbow, not on the forearm (Plug-in Gait's ELB).
            descr["RSP"] = "radial styloid process: the wrist bar's thumb side (Plug-in Gait's WRA)"
            descr["USP"] = "ulnar styloid process: the wrist bar's little-finger side (Plug-in Gait's WRB)"
            descr["FAP"] = "lateral epicondyle of the humerus (Plug-in Gait's ELB)"
        lines = [
            "# ikid marker = the label in your C3D/TRC files",
            f'side = "{self.side}"  # "right" or "left": the arm these markers are on (check it: a wrong '
            "side mirrors every flexion and supination; uncalibrated, markers at ikid's anatomical points "
            "that read as the other arm's are refused, a cluster's cannot show it)",
            (f'up = "{self.up}"' if self.up else '# up = "+z"')
            + "  # the lab axis pointing up (torques depend on it): a C3D's POINT:Y_SCREEN says it; for a "
            "TRC, CSV or live source that does not, +y (OpenSim's) is assumed",
            "[markers]",
        ]
        if not self.one_hand_marker:
            lines.append(
                "# the forearm's three turn with the radius: on the distal radius, or a cluster strapped "
                "to it (a marker on the ulnar styloid stays while the radius turns: name it in "
                "[landmarks], not as USP)"
            )
        lines += [f'{m} = "{lab}"  # {descr[m]}' for m, lab in self.labels.items()]
        if self.one_hand_marker:
            lines.append(
                f"# one hand marker: {', '.join(self.undetermined)} is not written (the hand's roll is not "
                "observed); "
                "RSP/USP must be on the styloids and FAP on the elbow (docs/markersets.md)"
            )
        if self.clusters:
            lines += [
                "",
                "# further markers on a segment's rigid cluster, fitted with its three",
                "[cluster]",
            ]
            lines += [
                f"{segment} = [{', '.join(json.dumps(lab) for lab in labels)}]"
                for segment, labels in self.clusters.items()
            ]
        elif not self.one_hand_marker:
            lines += [
                "",
                "# more than three markers on a segment? three above, the rest here (docs/markersets.md)",
                "# [cluster]",
                '# forearm = ["LABEL"]',
            ]
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


def _side_of_label(label: str) -> str | None:
    """The arm a label names by a word of its own ("right"/"left" in any case, or "R"/"L" beside
    another word): ``ForearmR1``, ``RadialStyloidR``, ``R_Wrist``, ``wrist.left`` (after any
    ``Subject:`` prefix). None when it names none. An all-capitals run stays one word
    (``LARM_ant``, ``RWRA``: Plug-in Gait's are checked by name), a lower-case letter is not read
    as a side (``STYLr``: the radial styloid; ``EPICl``: lateral), nor a letter with a number
    alone (``L0``, ``R2``)."""
    words = re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])", label.rsplit(":", 1)[-1])
    # A letter alone is a side beside another word only (GloveR1); "L0", "R2" are numbered markers.
    letters = {"R": "right", "L": "left"} if len(words) > 1 else {}
    named = {letters.get(w) or w.lower() for w in words} & {"right", "left"}
    return named.pop() if len(named) == 1 else None


def _check_side_against_labels(source: str, side: str, markers: dict, landmarks: dict) -> None:
    """Refuses a map whose labels name the other arm than ``side``: at least three of its
    marker and landmark labels name an arm, all the same one, not ``side``. Nothing in the
    markers themselves tells a right arm from a left (a mirror image of one is the other), so
    a wrong side reads every flexion and supination mirrored and nothing else can say so."""
    named = {str(v).strip(): _side_of_label(str(v)) for v in [*markers.values(), *landmarks.values()]}
    sides = {s for s in named.values() if s is not None}
    if len(sides) != 1 or sum(s is not None for s in named.values()) < 3 or side in sides:
        return
    other = sides.pop()
    shown = [label for label, s in named.items() if s is not None][:4]
    raise FileFormatError(
        f"{source}: side = {side!r}, but its labels name the {other} arm ({', '.join(map(repr, shown))}): "
        f"the {other} arm read as the {side} would give every flexion and supination mirrored; set side = "
        f'"{other}" (or name the {side} arm\'s markers)'
    )


#: The keys a marker map may have (tables and values; see the module's docstring).
_MAP_KEYS = ("markers", "side", "up", "landmarks", "cluster")


def _clusters(
    table: object, source: str, seen: dict[str, str], one_hand_marker: bool, forearm_cluster: bool
) -> dict[str, tuple[str, ...]]:
    """The ``[cluster]`` table checked: segment -> its further markers' labels, each a label no
    other marker has."""
    if not isinstance(table, dict):
        raise FileFormatError(f"{source}: [cluster] must be a table of segment = [labels]")
    segments = ("forearm", "hand")
    unknown = sorted(set(table) - set(segments))
    if unknown:
        raise FileFormatError(
            f"{source}: [cluster] names {', '.join(unknown)}; its keys are the segments: "
            f"{', '.join(segments)}"
        )
    clusters: dict[str, tuple[str, ...]] = {}
    taken = dict(seen)
    for segment in segments:
        labels = table.get(segment)
        if labels is None:
            continue
        if (
            not isinstance(labels, list)
            or not labels
            or not all(isinstance(v, str) and v.strip() for v in labels)
        ):
            raise FileFormatError(
                f"{source}: [cluster] {segment} must be a list of one or more labels (the markers beyond "
                f"the {segment}'s three, on the same rigid cluster)"
            )
        if one_hand_marker and (segment == "hand" or not forearm_cluster):
            raise FileFormatError(
                f"{source}: [cluster] {segment} with a one-marker hand ({_native.HAND_POINT[0]}): "
                + (
                    "the hand is that one marker"
                    if segment == "hand"
                    else "its forearm markers here are the styloids and the epicondyle (its [landmarks]), "
                    "built anew each frame, not a rigid cluster"
                )
                + "; a cluster is three markers of a segment in [markers] and more here"
            )
        for label in (v.strip() for v in labels):
            if taken.get(label) == f"the {segment}'s cluster":
                raise FileFormatError(f"{source}: label {label!r} is listed twice in the {segment}'s cluster")
            if label in taken:
                raise FileFormatError(
                    f"{source}: label {label!r} is given to both {taken[label]} and the {segment}'s cluster"
                )
            taken[label] = f"the {segment}'s cluster"
        clusters[segment] = tuple(v.strip() for v in labels)
    return clusters


def _segment(marker: str) -> str:
    """The segment an ikid marker name (one of the six, or HND) sits on."""
    if marker == _native.HAND_POINT[0]:
        return _native.HAND_POINT[1]
    return {m[0]: m[1] for m in _native.MARKERS}[marker]


def _undetermined_name() -> str:
    return _native.ONE_HAND_MARKER_UNDETERMINED


def landmark_names() -> list[str]:
    """The forearm's landmarks a marker map may name, in ``ikid.Calibration.LANDMARKS`` order."""
    return [name for name, _ in _native.Calibration.LANDMARKS]


def hand_landmark_names() -> list[str]:
    """The hand's optional landmarks, in ``ikid.Calibration.HAND_LANDMARKS`` order."""
    return [name for name, _ in _native.Calibration.HAND_LANDMARKS]
