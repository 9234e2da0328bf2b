"""Whether a recording's markers can be what a marker map names them: one segment's markers
keep their distances (:func:`stretched_segments`) and span a triangle (:func:`flat_segments`),
the hand moves on the forearm (:func:`hand_held_to_forearm`), a one-marker hand's forearm
markers sit at the styloids and the elbow (:func:`check_wrist_bar`). Each says what it found
in sentences naming the markers and their labels (the wrist bar refuses); the
:class:`~ikid.io.mapping.MarkerMap` methods of the same names delegate here."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ikid import _native
from ikid.io._common import ikid_marker_names

if TYPE_CHECKING:
    from ikid.io.mapping import MarkerMap


#: How much the distance between two markers of one segment may change over a recording (its
#: 10th to 90th percentile, the markers' frame-to-frame noise taken out), metres: on the real
#: recordings' forearms and hands skin markers change by up to 12 mm and rigid plates by 1 mm,
#: while a "segment" with a marker across the wrist or the elbow changes by 18-120 mm.
MAX_SEGMENT_STRETCH_M = 0.015
# The 10th-90th percentile range of a Gaussian, in standard deviations.
_P10_P90_SIGMAS = 2.563
# A segment's marker pairs (indices among its three).
_PAIRS = ((0, 1), (0, 2), (1, 2))


#: What a one-marker hand's forearm markers span when they are the styloids and the lateral
#: epicondyle, metres: the wrist bar (Plug-in Gait's real recordings 62-68 mm) and the forearm
#: from the mid-styloids to the elbow (236-246 mm); wide enough for children and large adults.
WRIST_BAR_M = (0.030, 0.120)
FOREARM_LENGTH_M = (0.120, 0.400)


#: Least a hand marker travels in the forearm's frame over a task trial (10th-90th percentile),
#: metres, below which the "hand" is said to be fixed to the forearm: real wrists move their
#: markers 32-123 mm (pyomeca, racing), a static trial 0.2-0.6 mm, markers on the forearm's
#: own plate 0.0-0.2 mm.
MIN_HAND_TRAVEL_M = 0.003


#: How far an uncalibrated tracker's subject size may lie from the one its markers' distances
#: say (a share of it) before it is not the subject they were put on. The tracker measures the
#: hand by where its markers sit from the body model's wrist centre: a subject 10 % larger read
#: as the default one had its angles 1-3° off and its torques 20-60× their size, every row
#: status 0 (review 7), where the placement check above only refuses at 25 %.
TRACKER_SIZE_TOLERANCE = 0.02


def marker_length_scale(frames: np.ndarray) -> float | None:
    """The subject's length scale its markers say, for markers at the body model's anatomical
    points (which move out with the subject's length): per frame with every marker, the sum of
    the three distances within each segment over the default subject's, the median over the
    frames. ``None`` without such a frame."""
    frames = np.asarray(frames, np.float64).reshape(-1, 6, 3)
    frames = frames[np.isfinite(frames).all(axis=(1, 2))]
    if len(frames) == 0:
        return None
    model = np.array([m["offset"] for m in _native.body_model()["markers"]], np.float64)

    def spans(points: np.ndarray) -> np.ndarray:
        return sum(
            np.linalg.norm(points[..., first + a, :] - points[..., first + b, :], axis=-1)
            for first in (0, 3)
            for a, b in _PAIRS
        )

    return float(np.median(spans(frames)) / spans(model))


def stretched_segments(mapping: MarkerMap, frames: np.ndarray) -> list[str]:
    """What says that a segment's markers, as this map names them, are not on one segment:
    per pair of markers of a segment (frames ``(n, 18)``, ikid's order, metres) whose
    distance changes over the frames by more than :data:`MAX_SEGMENT_STRETCH_M` (10th-90th
    percentile, less the markers' own noise measured from consecutive frames), a sentence
    naming both and their labels. Empty when none does, or with under 20 frames of the pair;
    a wrist that does not move does not show a marker across it. A one-marker hand's
    virtual markers are rigid by construction and not checked."""
    frames = np.asarray(frames, np.float64).reshape(len(frames), 6, 3)
    names = ikid_marker_names()
    found = []
    for segment, first in (("forearm", 0), ("hand", 3)):
        if segment == "hand" and mapping.one_hand_marker:
            continue
        for a, b in _PAIRS:
            d = np.linalg.norm(frames[:, first + a] - frames[:, first + b], axis=1)
            stretch = _stretch_m(d)
            if stretch is not None and stretch > MAX_SEGMENT_STRETCH_M:
                lo, hi = np.percentile(d[np.isfinite(d)], [10, 90])
                ma, mb = names[first + a], names[first + b]
                found.append(
                    f"the {segment}'s markers {ma} ({mapping.labels.get(ma, ma)!r}) and {mb} "
                    f"({mapping.labels.get(mb, mb)!r}) are {1e3 * lo:.0f}-{1e3 * hi:.0f} mm apart "
                    f"(10th-90th percentile; {1e3 * stretch:.0f} mm beyond the markers' noise), and "
                    "one segment's markers keep their distances within "
                    f"{1e3 * MAX_SEGMENT_STRETCH_M:.0f} mm: one of them seems to be on another segment "
                    "(across the wrist or the elbow), or they slide on the skin that far; check the "
                    "labels the marker map gives them, and expect skin markers' angles to carry that "
                    "sliding"
                )
    return found


def _stretch_m(d: np.ndarray) -> float | None:
    """How much a distance between two markers changes over the frames, metres: its 10th-90th
    percentile range less the markers' frame-to-frame noise. None with under 20 frames of it."""
    seen = np.isfinite(d)
    if seen.sum() < 20:
        return None
    lo, hi = np.percentile(d[seen], [10, 90])
    step = np.diff(d)
    step = step[np.isfinite(step)]
    # Noise variance from consecutive frames (median of chi-square(1) is 0.4549).
    noise = float(np.median(step**2)) / 2 / 0.4549 if len(step) else 0.0
    spread = (hi - lo) / _P10_P90_SIGMAS
    return float(_P10_P90_SIGMAS * np.sqrt(max(spread**2 - noise, 0.0)))


def _segment_stretches_m(frames: np.ndarray) -> tuple[float, float]:
    """The largest :func:`_stretch_m` of the forearm's and of the hand's marker pairs, frames
    ``(n, 6, 3)``."""
    found = []
    for first in (0, 3):
        pairs = (
            _stretch_m(np.linalg.norm(frames[:, first + a] - frames[:, first + b], axis=1)) for a, b in _PAIRS
        )
        found.append(max((s for s in pairs if s is not None), default=0.0))
    return found[0], found[1]


def swapped_across_segments(mapping: MarkerMap, frames: np.ndarray) -> str | None:
    """A sentence when a forearm marker and a hand marker, as this map names them, are each
    other's: as labelled, both segments stretch (one beyond :data:`MAX_SEGMENT_STRETCH_M`,
    each beyond half of it and twice what it does with the two labels exchanged), and with
    them exchanged every segment keeps its distances within it. Every output of such a map
    would be a wrong angle that reads like a right one (on pyomeca's recording, 30° RMS off),
    so the caller refuses. A marker of another segment with no swap to undo (an elbow marker
    on the "hand", whose forearm keeps its shape) is :func:`stretched_segments`' warning.
    None otherwise, and for maps whose markers are not six labels of their own (a one-marker
    hand, ``[cluster]``)."""
    if mapping.one_hand_marker or mapping.clusters:
        return None
    frames = np.asarray(frames, np.float64).reshape(len(frames), 6, 3)
    as_labelled = _segment_stretches_m(frames)
    if max(as_labelled) <= MAX_SEGMENT_STRETCH_M or min(as_labelled) <= MAX_SEGMENT_STRETCH_M / 2:
        return None
    for f in range(3):
        for h in range(3, 6):
            exchanged = frames.copy()
            exchanged[:, [f, h]] = frames[:, [h, f]]
            stretches = _segment_stretches_m(exchanged)
            if max(stretches) > MAX_SEGMENT_STRETCH_M or any(
                lab <= 2 * ex for lab, ex in zip(as_labelled, stretches, strict=True)
            ):
                continue
            names = ikid_marker_names()
            fa, ha = names[f], names[h]
            lf, lh = mapping.labels.get(fa, fa), mapping.labels.get(ha, ha)
            return (
                f"the forearm's marker {fa} ({lf!r}) and the hand's {ha} ({lh!r}) seem to be each "
                "other's: as labelled, the forearm's and the hand's markers change their distances by up "
                f"to {1e3 * as_labelled[0]:.0f} and {1e3 * as_labelled[1]:.0f} mm over the recording, where "
                f"one segment's keep them within {1e3 * MAX_SEGMENT_STRETCH_M:.0f} mm; with the two "
                f"exchanged, by {1e3 * stretches[0]:.0f} and {1e3 * stretches[1]:.0f} mm. Every angle from "
                f"this map would be wrong; in the marker map, give {fa} = {lh!r} and {ha} = {lf!r}"
            )
    return None


def hand_held_to_forearm(mapping: MarkerMap, frames: np.ndarray) -> str | None:
    """What says that the hand's markers, as this map names them, do not move relative to
    the forearm's over ``frames`` (``(n, 18)``, ikid's order): each stays within
    :data:`MIN_HAND_TRAVEL_M` (10th-90th percentile) in the forearm markers' technical
    frame. None when one moves more, or with under 20 frames with all six. A task trial
    shows it when the "hand" is on the forearm (or the wrist held still throughout); a
    static trial always does, so calibration does not ask."""
    frames = np.asarray(frames, np.float64).reshape(len(frames), 18)
    local = _native.points_in_technical_frame(frames[:, :9], frames[:, 9:], 3).reshape(len(frames), 3, 3)
    seen = np.isfinite(local).all(axis=(1, 2))
    if seen.sum() < 20:
        return None
    lo, hi = np.percentile(local[seen], [10, 90], axis=0)
    travel = float(np.linalg.norm(hi - lo, axis=1).max())
    if travel > MIN_HAND_TRAVEL_M:
        return None
    hand = ", ".join(f"{m} ({mapping.label_of(m)!r})" for m in ikid_marker_names()[3:])
    return (
        f"the hand's markers {hand} stay within {1e3 * travel:.1f} mm of one place on the forearm over "
        f"{int(seen.sum())} frames (10th-90th percentile): either the wrist did not move at all, or "
        "these markers are on the forearm (or on one rigid body with its markers); check the labels the "
        "marker map gives the hand"
    )


def flat_segments(mapping: MarkerMap, frames: np.ndarray) -> list[str]:
    """What says that a segment's three markers lie on a line (within the core's
    ``cluster::MIN_FRAME_WIDTH_M``) in most frames that see them (``(n, 18)``, ikid's
    order): they give no orientation, and every angle from them would be noise."""
    frames = np.asarray(frames, np.float64).reshape(len(frames), 18)
    names = ikid_marker_names()
    found = []
    for segment, first in (("forearm", 0), ("hand", 9)):
        three = frames[:, first : first + 9]
        seen = np.isfinite(three).all(axis=1)
        if not seen.any():
            continue
        framed = np.isfinite(_native.points_in_technical_frame(three, three[:, :3], 1)).all(axis=1)
        flat = int(np.count_nonzero(seen & ~framed))
        if flat > seen.sum() / 2:
            markers = ", ".join(f"{m} ({mapping.label_of(m)!r})" for m in names[first // 3 : first // 3 + 3])
            found.append(
                f"the {segment}'s markers {markers} lie on one line (within 5 mm) in {flat} of the "
                f"{int(seen.sum())} frames that see them: they give the {segment} no orientation; name "
                "three markers that span a triangle"
            )
    return found


def hand_point_distance(columns: np.ndarray) -> float:
    """A one-marker hand's marker's median distance from the mid-styloids over the frames that
    see both (``columns`` ``(n, 12)``, the forearm's anatomical points then ``HND``; metres),
    NaN if none does."""
    d = np.linalg.norm(columns[:, 9:12] - (columns[:, 0:3] + columns[:, 3:6]) / 2, axis=1)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) else float("nan")


def check_hand_point(mapping: MarkerMap, columns: np.ndarray) -> None:
    """Refuse a one-marker hand's marker that does not sit where the calibration measured it:
    its distance from the mid-styloids (:func:`hand_point_distance`) further from the
    calibration's (:attr:`MarkerMap.hand_point_m`) than a rigid segment's distances may stray.
    Another marker under its label (a mocap system's labelling) reads the hand's direction
    from elsewhere: review 6, a hand marker 67 mm from the wrist under the label of one
    calibrated at 99 mm, every row "ok", flexion 7.1° and deviation 4.2° RMS off. Nothing to
    check without a calibration that measured it."""
    then = mapping.hand_point_m
    if then is None or not mapping.one_hand_marker:
        return
    here = hand_point_distance(columns)
    if np.isnan(here) or abs(here - then) <= _native.RIGID_TOLERANCE_M + _native.RIGID_TOLERANCE_REL * then:
        return
    hand = _native.HAND_POINT[0]
    raise _native.InputError(
        f"{mapping.source}: the hand's one marker {mapping.labels[hand]!r} ({hand}) sits {1e3 * here:.0f} mm "
        f"from the wrist bar's middle, {1e3 * then:.0f} mm in the calibration: another marker is under its "
        "label (check the mocap system's labelling, or the marker map), or it was placed elsewhere since "
        "the calibration (calibrate again with a static trial recorded as this one)"
    )


def check_wrist_bar(mapping: MarkerMap, columns: np.ndarray) -> None:
    """Refuse a one-marker hand's forearm markers that cannot be the styloids and the elbow
    (a plate named as RSP, USP, FAP without its landmarks): their median spans over the
    frames that see them, against :data:`WRIST_BAR_M` and :data:`FOREARM_LENGTH_M`."""
    rsp, usp, fap = columns[:, 0:3], columns[:, 3:6], columns[:, 6:9]
    bar = np.linalg.norm(rsp - usp, axis=1)
    length = np.linalg.norm(fap - (rsp + usp) / 2, axis=1)
    seen = np.isfinite(bar) & np.isfinite(length)
    if not seen.any():
        return
    bar_mm, length_mm = 1e3 * float(np.median(bar[seen])), 1e3 * float(np.median(length[seen]))
    (lo_bar, hi_bar), (lo_len, hi_len) = WRIST_BAR_M, FOREARM_LENGTH_M
    if lo_bar <= bar_mm / 1e3 <= hi_bar and lo_len <= length_mm / 1e3 <= hi_len:
        return
    raise _native.InputError(
        f"{mapping.source}: with one hand marker ({_native.HAND_POINT[0]}), RSP and USP are the wrist's "
        f"styloids (a wrist bar) and FAP the lateral epicondyle; here RSP {mapping.labels['RSP']!r} and USP "
        f"{mapping.labels['USP']!r} are {bar_mm:.0f} mm apart ({1e3 * lo_bar:.0f}-{1e3 * hi_bar:.0f} mm for "
        f"the styloids) and FAP {mapping.labels['FAP']!r} {length_mm:.0f} mm from their midpoint "
        f"({1e3 * lo_len:.0f}-{1e3 * hi_len:.0f} mm for the forearm): they do not sit there. For a "
        "cluster on the forearm, name the styloid and epicondyle landmarks in [landmarks] and calibrate "
        "from a static trial that has them (docs/markersets.md)"
    )
