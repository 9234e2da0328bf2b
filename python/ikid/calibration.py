"""Calibration to a subject's marker placement, measured once per session and saved as JSON.

    from ikid.calibration import calibrate_neutral, check_calibration_map
    cal = calibrate_neutral(frames[:10], landmarks[:10])          # landmarks + neutral frames
    cal = calibrate_functional(frames[:10], circles)              # neutral + any flexion/deviation
    cal = ikid.calibrate(static_frames, {"ra_wr_e_f": flexion_frames, "ra_wr_s_p": pronation_frames})
    ikid.save_calibration(cal, "subject01.json", marker_map=lab_map)
    check_calibration_map("subject01.json", lab_map)             # the trial's map: refused if another
    stream = model.stream(calibration=ikid.load_calibration("subject01.json"))

The measurement itself is the core's (``crates/ikid/src/calibration.rs``, :class:`ikid.Calibration`):

- **landmarks**: the epicondyles and styloids give the forearm's ISB frame, the hand's equals
  the forearm's at the neutral posture (chosen frames of any trial);
- **neutral**: the neutral posture alone (the forearm keeps the body model's placement);
- **functional**: the neutral posture plus any movement mixing flexion and deviation, the
  forearm's rotation held (the two axes by least squares);
- **movements**: a static trial and single-coordinate movements (one axis per trial);
- **mirror**: the other arm's landmarks calibration, for a forearm carrying the same cluster
  mounted alike (mirror image), checked against this arm's cluster and any landmark it has; the
  hand from this arm's neutral frames (:func:`calibrate_mirror`).

A left arm is mirrored into a right arm (lab z negated) when measured and when applied, so its
angles keep their anatomical signs. The file records the method, the side and the marker map;
:func:`check_calibration_map` refuses a trial read with another map.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ikid import _native
from ikid._native import Calibration, IkidError, InputError, fill_gaps
from ikid.io._atomic import write_text_atomic
from ikid.io.markers import FileFormatError, read_text

if TYPE_CHECKING:
    from ikid.io.mapping import MarkerMap

FORMAT = "ikid-calibration"
FORMAT_VERSION = 2
#: Versions this ikid reads (1: no method, side or marker map recorded: a right arm).
READABLE_VERSIONS = (1, 2)


def calibrate(static_frames, movements: dict, *, fill: bool = True) -> Calibration:
    """Measure a :class:`Calibration` from a neutral static trial and single-coordinate
    movements ``{coordinate name: frames}`` (``(n, 18)`` metres each). With ``fill``, a
    single missing marker per segment is filled first (``ikid.fill_gaps``)."""

    def prepared(frames):
        frames = np.asarray(frames, np.float64)
        if fill and frames.ndim == 2 and not np.isfinite(frames).all():
            frames = fill_gaps(frames)[0]
        return frames

    static = prepared(static_frames)
    moves = {k: prepared(v) for k, v in movements.items()}
    return _with_shapes(Calibration.from_trials(static, moves), static)


def _with_shapes(calibration: Calibration, neutral_frames) -> Calibration:
    """``calibration`` with its segments' marker shapes from the ``neutral_frames`` it was
    measured on (``Calibration.with_shapes_of``: streams and the Tracker then fit the segments
    to them, not to a trial's first frames); as it is when no frame has all six markers."""
    try:
        return calibration.with_shapes_of(np.asarray(neutral_frames, np.float64))
    except IkidError:
        return calibration


def calibrate_neutral(
    neutral_frames, landmarks=None, *, landmark_frames=None, side: str = "right", hand_landmarks=None
) -> Calibration:
    """Measure a :class:`Calibration` from frames of the neutral posture ``(n, 18)`` (a static
    trial, or chosen frames of any trial; NaN = missing, no filling needed) and, when given,
    the forearm's landmarks ``(m, 12)`` (lateral and medial epicondyle, radial and ulnar
    styloid, x y z each, metres, NaN = not seen) seen with ``landmark_frames`` ``(m, 18)``
    (default: the neutral frames). With ``hand_landmarks`` ``(m, 6)`` too (second and fifth
    metacarpal heads, same frames) the hand's frame is its own rather than the forearm's at
    the neutral frames. ``side``: "right" or "left"."""
    # Units first: frames in mm read as an arm 1000 times too large, which the landmark checks
    # below would name as landmarks of another arm.
    _native.check_marker_units(np.asarray(neutral_frames, np.float64))
    calibration = Calibration.from_neutral(
        np.asarray(neutral_frames, np.float64),
        None if landmarks is None else np.asarray(landmarks, np.float64),
        None if landmark_frames is None else np.asarray(landmark_frames, np.float64),
        side,
        None if hand_landmarks is None else np.asarray(hand_landmarks, np.float64),
    )
    return _with_shapes(calibration, neutral_frames)


def calibrate_functional(neutral_frames, movement_frames, *, side: str = "right") -> Calibration:
    """Measure a :class:`Calibration` from frames of the neutral posture ``(n, 18)`` and a
    movement ``(m, 18)`` that bends the wrist through flexion-extension and radial-ulnar
    deviation together (circles, or a task), the forearm's rotation held: the two axes by a
    least-squares functional fit (NaN = missing; such frames are skipped). The report's
    ``functional`` entry gives the ranges seen and the fit's residual. ``side``: "right" or
    "left"."""
    calibration = Calibration.functional(
        np.asarray(neutral_frames, np.float64), np.asarray(movement_frames, np.float64), side
    )
    return _with_shapes(calibration, neutral_frames)


def calibrate_mirror(
    other: str | os.PathLike[str],
    neutral_frames,
    landmarks=None,
    *,
    landmark_frames=None,
    side: str | None = None,
) -> Calibration:
    """Measure a :class:`Calibration` of one arm from the other arm's calibration file ``other``
    (written by :func:`save_calibration` from that arm's landmarks): its forearm frame, for a
    forearm whose cluster is the same and mounted as its mirror image, and the hand from this
    arm's ``neutral_frames`` ``(n, 18)``. ``landmarks`` ``(m, 12)`` (``Calibration.LANDMARKS``
    order, NaN where this arm has none; the lateral epicondyle alone is enough) seen with
    ``landmark_frames`` ``(m, 18)`` (default: the neutral frames) check which of this cluster's
    markers matches which of the other's and that the two are mounted alike. ``side``: this
    arm (default: the other side). Refused (``ikid.InputError``), saying what to record or
    change, when that cannot be known or does not hold."""
    path = Path(other)
    info = calibration_info(path)
    geometry = ((info.get("report") or {}).get("landmarks") or {}).get("geometry")
    if info.get("method") != "landmarks" or geometry is None:
        raise InputError(
            f"{path}: the mirror method takes the other arm's landmarks calibration, which records its "
            f"forearm's cluster and landmarks; this one is {info.get('method')!r}"
            + (
                ""
                if geometry is not None or info.get("method") != "landmarks"
                else " written by an older ikid"
            )
            + ": calibrate the other arm with `ikid calibrate` from its epicondyles and styloids"
        )
    names = [name for name, _ in Calibration.LANDMARKS]
    try:
        cluster = np.asarray(geometry["cluster_mm"], np.float64) / 1e3
        at = geometry["landmarks_mm"]
        others = np.array([[np.nan] * 3 if at.get(k) is None else at[k] for k in names], np.float64) / 1e3
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise InputError(f"{path}: the report's landmarks geometry is malformed ({e})") from None
    side = side or ("left" if info["side"] == "right" else "right")
    calibration = Calibration.mirrored(
        load_calibration(path),
        cluster,
        others,
        np.asarray(neutral_frames, np.float64),
        None if landmarks is None else np.asarray(landmarks, np.float64),
        None if landmark_frames is None else np.asarray(landmark_frames, np.float64),
        side,
    )
    return _with_shapes(calibration, neutral_frames)


def save_calibration(
    calibration: Calibration,
    path: str | os.PathLike[str],
    *,
    marker_map: MarkerMap | None = None,
    forearm_landmarks: dict | None = None,
    marker_distances: dict[str, list[float]] | None = None,
    hand_point_m: float | None = None,
    **provenance,
) -> Path:
    """Write ``calibration`` (its method, side and report, the marker map it was measured
    with — the identity map when None —, a forearm cluster's anatomical points for a
    one-marker hand (``forearm_landmarks``: ``in_frame_of``, ``points_m``; see
    :func:`map_with_calibration`), such a hand's marker's distance from the wrist
    (``hand_point_m``) and any ``provenance`` given) as JSON, atomically."""
    from ikid.io.mapping import MarkerMap

    marker_map = marker_map or MarkerMap.identity()
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "method": calibration.method,
        "side": calibration.side,
        "marker_map": {
            "source": marker_map.source,
            "side": marker_map.side,
            "markers": dict(marker_map.labels),
            "landmarks": dict(marker_map.landmarks),
            "cluster": {k: list(v) for k, v in marker_map.clusters.items()},
        },
        "forearm": np.asarray(calibration.forearm).tolist(),
        "hand": np.asarray(calibration.hand).tolist(),
        "report": calibration.report,
        "provenance": provenance,
    }
    if forearm_landmarks is not None:
        doc["forearm_landmarks"] = forearm_landmarks
    if marker_distances:
        doc["marker_distances_m"] = marker_distances
    if hand_point_m is not None and np.isfinite(hand_point_m):
        doc["hand_point_from_wrist_m"] = float(hand_point_m)
    if calibration.marker_shapes is not None:
        doc["marker_shapes_m"] = np.asarray(calibration.marker_shapes).tolist()
    return write_text_atomic(path, json.dumps(doc, indent=1) + "\n")


#: A segment's marker pairs, as ``marker_distances_m`` lists their distances.
_PAIRS = ((0, 1), (0, 2), (1, 2))


def _distance_rows(frames: np.ndarray, first: int) -> np.ndarray:
    """One segment's three marker distances per frame with all three measured, ``(n, 3)``."""
    f = np.asarray(frames, np.float64).reshape(len(frames), 6, 3)
    d = np.stack([np.linalg.norm(f[:, first + a] - f[:, first + b], axis=1) for a, b in _PAIRS], axis=1)
    return d[np.isfinite(d).all(axis=1)]


def marker_distances(frames: np.ndarray, one_hand_marker: bool = False) -> dict[str, list[float]]:
    """Each segment's three marker distances (pairs 01, 02, 12; median over the frames, metres)
    in ``frames`` ``(n, 18)``: what a calibration keeps of its markers' layout, for
    :func:`check_marker_distances`. A one-marker hand's (virtual) markers are left out; a
    segment with no frame of all three, too."""
    out = {}
    for segment, first in (("forearm", 0), ("hand", 3)):
        if segment == "hand" and one_hand_marker:
            continue
        d = _distance_rows(frames, first)
        if len(d):
            out[segment] = np.median(d, axis=0).tolist()
    return out


#: A distance between two of a segment's markers that holds steady through a trial yet sits
#: further than this from the calibration's (and :data:`MOVED_MARKER_SPREADS` times its own
#: spread) is a marker placed elsewhere since the calibration. Measured (median distance against
#: the calibration's): the real recordings' 0-2.7 mm (pyomeca's skin markers, a task cut from
#: its static frames too); the exam's skin markers up to 12.4 mm, but within 2.7 times their
#: spread over the task (the skin slides with the posture, so the distance moves with it); a
#: pyomeca hand marker moved 12 mm for the whole trial 6.5 mm at 9.9 times its spread, which
#: read every angle 14° off with status 0.
MOVED_MARKER_M = 0.005
#: See :data:`MOVED_MARKER_M`.
MOVED_MARKER_SPREADS = 4.0


def check_marker_distances(
    path: str | os.PathLike[str], frames: np.ndarray, source: str, whole: bool = True, mapping=None
) -> None:
    """Refuse (``ikid.InputError``) a trial whose markers are not laid out as those the
    calibration at ``path`` was measured with: a distance between two of a segment's markers
    (median over ``frames``) further from the calibration's than the tracker lets a rigid
    segment stray (``RIGID_TOLERANCE_M`` plus ``RIGID_TOLERANCE_REL`` of it). Such a trial is of
    another session, subject or cluster: the calibration says nothing of where its markers sit
    (one of another subject's clusters wrote 4 rows of 700, the rest turned over, exit 0).
    When ``frames`` are a ``whole`` trial, also one that holds steady further from the
    calibration's than :data:`MOVED_MARKER_M` and :data:`MOVED_MARKER_SPREADS` times its own
    spread: a marker taken off and put back elsewhere (a live stream's first frames are too few
    to tell a steady shift from the skin's slide at one posture). Two markers whose labels are
    exchanged, where exchanging them back lays every distance out as calibrated, are named as
    such (with their labels in ``mapping``, an :class:`ikid.io.MarkerMap`). A file written before
    calibrations kept the distances passes."""
    stored = calibration_info(path).get("marker_distances_m") or {}
    names = _native.MARKERS
    now = {}  # each segment's median distances, as marker_distances gives them
    pairs = []  # (segment, pair, here, then, spread), forearm first
    for segment, first in (("forearm", 0), ("hand", 3)):
        rows = _distance_rows(frames, first)
        if len(rows):
            now[segment] = np.median(rows, axis=0).tolist()
        if segment in stored and segment in now:
            spread = rows.std(axis=0)
            for (a, b), then, here, sd in zip(_PAIRS, stored[segment], now[segment], spread, strict=True):
                pairs.append((segment, f"{names[first + a][0]} and {names[first + b][0]}", here, then, sd))

    def fits(here: float, then: float) -> bool:
        return abs(here - then) <= _native.RIGID_TOLERANCE_M + _native.RIGID_TOLERANCE_REL * then

    # Markers laid out otherwise altogether are named as such before a single marker moved.
    for segment, pair, here, then, _ in pairs:
        if fits(here, then):
            continue
        exchanged = zip(
            now.get("forearm", []) + now.get("hand", []),
            stored.get("hand", []) + stored.get("forearm", []),
            strict=True,
        )
        if len(now) == len(stored) == 2 and all(fits(h, t) for h, t in exchanged):
            # Each segment's markers are the other's as calibrated: columns in the wrong order.
            raise InputError(
                f"{source}: the forearm's markers are laid out as the calibration's hand and the hand's as "
                f"its forearm ({path}): the hand's columns come first? ikid reads "
                f"{', '.join(m[0] for m in names)} in that order (three on the forearm, then three on "
                "the hand)"
            )
        if (swap := _exchanged_pair(frames, stored, fits)) is not None:
            # Review 6: two labels exchanged in the mocap system, read live with the right
            # calibration, were told to calibrate this session.
            one, other = (names[k][0] for k in swap)
            labels = ""
            if mapping is not None:
                labels = f" (labels {mapping.label_of(one)!r} and {mapping.label_of(other)!r})"
            raise InputError(
                f"{source}: markers {one} and {other}{labels} seem to be each other's: exchanged, every "
                f"distance between a segment's markers is the calibration's ({path}); as they come, the "
                f"{segment}'s {pair} are {1e3 * here:.0f} mm apart, {1e3 * then:.0f} mm in the calibration. "
                "Exchange their labels (in the mocap system's labelling, or in the marker map)"
            )
        raise InputError(
            f"{source}: its {segment}'s markers {pair} are "
            f"{1e3 * here:.0f} mm apart, {1e3 * then:.0f} mm in the calibration ({path}): it was "
            "measured on markers laid out otherwise (another session, subject or cluster), so it "
            "cannot say where these sit; calibrate this session (`ikid calibrate` on its own static "
            "trial)"
        )
    for segment, pair, here, then, sd in pairs if whole else ():
        if abs(here - then) > max(MOVED_MARKER_M, MOVED_MARKER_SPREADS * sd):
            raise InputError(
                f"{source}: its {segment}'s markers {pair} are {1e3 * here:.1f} mm apart throughout "
                f"(within {1e3 * sd:.1f} mm), {1e3 * then:.1f} mm in the calibration ({path}): a marker "
                "was placed elsewhere since the calibration (taken off and put back, or moved on its "
                "plate), and the calibration cannot say where it sits now: every angle would be off by "
                "as much as that turns the segment. Calibrate with a static trial recorded with the "
                "markers as they are in this one (`ikid calibrate`)"
            )


def _exchanged_pair(frames: np.ndarray, stored: dict, fits) -> tuple[int, int] | None:
    """The one pair of ikid's six markers whose exchange lays ``frames`` out as the stored
    (calibrated) distances say, each segment's within ``fits``; None if no pair, or more than
    one, does."""
    f = np.asarray(frames, np.float64).reshape(len(frames), 6, 3)
    found = []
    for i in range(6):
        for j in range(i + 1, 6):
            swapped = f.copy()
            swapped[:, [i, j]] = swapped[:, [j, i]]
            flat = swapped.reshape(len(f), 18)
            ok = bool(stored)
            for segment, first in (("forearm", 0), ("hand", 3)):
                if segment not in stored:
                    continue
                rows = _distance_rows(flat, first)
                ok = ok and len(rows) > 0
                if ok:
                    here = np.median(rows, axis=0)
                    ok = all(fits(h, t) for h, t in zip(here, stored[segment], strict=True))
            if ok:
                found.append((i, j))
    return found[0] if len(found) == 1 else None


#: Where the landmarks may put the wrist against the hand's markers at the neutral frames: the
#: hand's markers' centroid at most this far from the mid-styloids (metres) and not more than
#: :data:`HAND_PROXIMAL_M` proximal of them along the forearm. Measured: 46-83 mm away and 40-80
#: mm distal on the real recordings (pyomeca, racing, Plug-in Gait's both arms) and the exam's 18
#: statics; landmarks probed with racing's forearm plate put back turned a third of a turn
#: (another session's landmarks) 290 mm away and 245 mm proximal.
HAND_FROM_WRIST_MAX_M = 0.2
#: See :data:`HAND_FROM_WRIST_MAX_M`: a hand at neutral lies distal of the wrist.
HAND_PROXIMAL_M = 0.02


def check_landmarks_place_the_hand(
    neutral_frames: np.ndarray, landmark_points: np.ndarray, landmark_frames: np.ndarray, source: str
) -> None:
    """Refuse (``ikid.InputError``) forearm landmarks that put the wrist where the hand's markers
    at the neutral frames cannot be: over :data:`HAND_FROM_WRIST_MAX_M` from them, or the hand
    over :data:`HAND_PROXIMAL_M` proximal of it. The landmarks are kept in the frame of the
    forearm's markers; measured with those markers placed otherwise (another session's, a plate
    put back turned) they land elsewhere on the arm, and every angle is turned by as much (the
    racing plate a third of a turn off read every frame turned over). ``landmark_points``
    ``(n, 12)``: lateral and medial epicondyle, radial and ulnar styloid, with the forearm's
    markers of ``landmark_frames`` ``(n, 18)``."""
    # Everything in the forearm's markers' technical frame (the core's), where the landmarks
    # are kept: distances and directions there are the lab's.
    frames = np.asarray(landmark_frames, np.float64)
    local = _native.points_in_technical_frame(frames[:, :9], np.asarray(landmark_points, np.float64), 4)
    local = local.reshape(len(frames), 4, 3)
    seen = np.isfinite(local).all(axis=(1, 2))
    f = np.asarray(neutral_frames, np.float64)
    hand = _native.points_in_technical_frame(f[:, :9], f[:, 9:], 3).reshape(len(f), 3, 3).mean(axis=1)
    held = np.isfinite(hand).all(axis=1)
    if not seen.any() or not held.any():
        return  # the calibration itself says what is missing
    epi, med, rad, uln = np.median(local[seen], axis=0)
    wrist = (rad + uln) / 2
    axis = (epi + med) / 2 - wrist
    axis /= np.linalg.norm(axis)
    d = np.median(hand[held], axis=0) - wrist
    away, proximal = float(np.linalg.norm(d)), float(d @ axis)
    if away > HAND_FROM_WRIST_MAX_M or proximal > HAND_PROXIMAL_M:
        raise InputError(
            f"{source}: the landmarks put the wrist (mid-styloids) {1e3 * away:.0f} mm from the hand's "
            f"markers at the neutral frames, the hand {1e3 * abs(proximal):.0f} mm "
            f"{'proximal' if proximal > 0 else 'distal'} of it along the forearm: a hand sits within "
            f"{1e3 * HAND_FROM_WRIST_MAX_M:.0f} mm of the wrist, distal of it. The landmarks were "
            "measured with the forearm's markers placed otherwise (another session's, a plate put "
            "back turned) or under other labels: record them in this session's static trial"
        )


def calibration_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The calibration file's contents (checked to be an ikid calibration of a version this
    ikid reads): ``method``, ``side``, ``marker_map`` (None for version 1), ``report``,
    ``provenance``, the matrices."""
    path = Path(path)
    try:
        doc = json.loads(read_text(path, "a calibration file is JSON text"), object_pairs_hook=_unique_keys)
    except (json.JSONDecodeError, FileFormatError) as e:
        raise InputError(f"{path}: not a calibration file ({e})") from None
    except _DuplicateKey as e:
        raise InputError(
            f"{path}: the key {e.args[0]!r} appears twice in one object; a calibration file names each "
            "field once (which one was meant cannot be known): write it again with `ikid calibrate`"
        ) from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputError(f'{path}: not an ikid calibration (expected "format": "{FORMAT}")')
    if doc.get("format_version") not in READABLE_VERSIONS:
        raise InputError(
            f"{path}: calibration format_version {doc.get('format_version')!r}; "
            f"this ikid reads {', '.join(map(str, READABLE_VERSIONS))}"
        )
    doc.setdefault("method", "movements")
    doc.setdefault("side", "right")
    doc.setdefault("marker_map", None)
    recorded_side = (doc["marker_map"] or {}).get("side")
    if recorded_side is not None and recorded_side != doc["side"]:
        raise InputError(
            f"{path}: the calibration says side {doc['side']!r} but was measured with a marker map of the "
            f"{recorded_side} arm; a calibration of one arm read as the other turns every angle (edited by "
            "hand?): calibrate again with `ikid calibrate`"
        )
    return doc


class _DuplicateKey(Exception):
    pass


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object that names each key once (Python's json keeps the last of a repeated key
    without a word)."""
    doc: dict[str, Any] = {}
    for key, value in pairs:
        if key in doc:
            raise _DuplicateKey(key)
        doc[key] = value
    return doc


def check_calibration_map(path: str | os.PathLike[str], marker_map: MarkerMap | None) -> None:
    """Refuse (``ikid.InputError``) a trial read with ``marker_map`` (None: the identity map,
    ikid's own labels) when the calibration in ``path`` was measured with another map: each
    ikid marker must have the same label. A version-1 file (no map recorded) passes."""
    from ikid.io.mapping import MarkerMap

    info = calibration_info(path)
    recorded = info["marker_map"]
    marker_map = marker_map or MarkerMap.identity()
    if info["side"] != marker_map.side:
        raise InputError(
            f"{path}: a calibration of the {info['side']} arm, for a trial whose marker map "
            f"({marker_map.source}) is of the {marker_map.side} arm: read as the other arm, every angle "
            "turns (flexion changes sign). Give the calibration of this arm, or calibrate it with `ikid "
            'calibrate` and this map (side = "left" or "right" in the map)'
        )
    if recorded is None:
        return
    theirs = recorded.get("markers", {})
    differ = [
        f"{m} is {lab!r} here, "
        + (f"{theirs[m]!r} in the calibration" if m in theirs else "not in the calibration's map")
        for m, lab in marker_map.labels.items()
        if theirs.get(m) != lab
    ]
    if differ:
        raise InputError(
            f"{path}: measured with another marker map ({recorded.get('source')}): {'; '.join(differ)}. "
            "Give the marker map `ikid calibrate` was given (--map), or calibrate again with this one"
        )


def map_with_calibration(marker_map: MarkerMap, path: str | os.PathLike[str] | None) -> MarkerMap:
    """``marker_map`` with what the calibration file at ``path`` adds to it, for a one-marker
    hand: its marker's distance from the wrist as calibrated
    (:meth:`ikid.io.MarkerMap.with_hand_point_distance`), and a forearm cluster's anatomical
    points (:meth:`ikid.io.MarkerMap.with_forearm_landmarks`); the map as it is otherwise. A
    calibration without the points, for a map whose forearm is a cluster, is refused, saying to
    calibrate with the landmarks."""
    if path is None or not marker_map.one_hand_marker:
        return marker_map
    distance = calibration_info(path).get("hand_point_from_wrist_m")
    if isinstance(distance, int | float) and np.isfinite(distance) and distance > 0:
        marker_map = marker_map.with_hand_point_distance(float(distance))
    if not marker_map.forearm_cluster:
        return marker_map
    stored = calibration_info(path).get("forearm_landmarks")
    try:
        points = np.asarray(stored["points_m"], np.float64)  # type: ignore[index]
        labels = stored["in_frame_of"]  # type: ignore[index]
        ok = points.shape == (3, 3) and bool(np.isfinite(points).all())
    except (TypeError, KeyError, ValueError):
        ok = False
    if not ok:
        raise InputError(
            f"{path}: has no forearm landmarks in the frame of the forearm's markers, which this map "
            f"({marker_map.source}: a forearm cluster and one hand marker) needs: calibrate with it "
            "(`ikid calibrate --static STATIC --map MAP`), from a static trial with the landmarks"
        )
    mine = [marker_map.labels[m] for m in ("RSP", "USP", "FAP")]
    if labels != mine:
        raise InputError(
            f"{path}: its forearm landmarks are in the frame of markers {labels}, this map's are {mine}: "
            "calibrate again with this map"
        )
    return marker_map.with_forearm_landmarks(points)


def uncalibrated(side: str) -> Calibration | None:
    """What a run of an arm without a calibration file uses: None (the body model's placement)
    for a right arm; for a left one (a marker map's ``side = "left"``) that placement with the
    arm mirrored into a right one, as a left arm's calibration does. A left
    arm read as a right one turns every angle (measured: 45° RMS on flexion and supination)."""
    if side == "left":
        placement = Calibration.body_model()
        return Calibration.from_matrices(placement.forearm, placement.hand, side="left")
    return None


def mirrored_to_right(frames: np.ndarray, side: str) -> np.ndarray:
    """``(n, 3m)`` marker frames of a ``side`` arm as a right arm's: a left arm's lab ``z``
    negated (the core's ``Side::to_right``)."""
    frames = np.asarray(frames, np.float64)
    if side != "left":
        return frames
    return frames * np.tile([1.0, 1.0, -1.0], frames.shape[1] // 3)


def load_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read a calibration written by :func:`save_calibration` (matrices checked, side as
    recorded). Check the trial's marker map against it with :func:`check_calibration_map`."""
    path = Path(path)
    doc = calibration_info(path)
    try:
        calibration = Calibration.from_matrices(doc["forearm"], doc["hand"], side=doc["side"])
        shapes = doc.get("marker_shapes_m")
        if shapes is not None:
            calibration = calibration.with_marker_shapes(np.asarray(shapes, np.float64))
        return calibration
    except KeyError as e:
        raise InputError(f"{path}: no {e.args[0]!r} matrix") from None
    except (InputError, TypeError) as e:
        raise InputError(f"{path}: {e}") from None
