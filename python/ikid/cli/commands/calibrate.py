"""`ikid calibrate`: a subject's marker placement -> calibration JSON."""

from __future__ import annotations

import argparse
import contextlib
import re
import warnings
from collections.abc import Iterator

import numpy as np

import ikid
from ikid.cli.common import _message, _naming, _refuse_over_inputs


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        help="measure a subject's marker placement (landmarks, neutral frames, or movements)",
        description="A subject's marker placement -> calibration JSON (method, side and marker map recorded; "
        "ikid.calibration.check_calibration_map refuses a trial read with another map).\n\n"
        "  # landmarks (the map's [landmarks]: epicondyles, styloids) + neutral frames of any trial:\n"
        "  ikid calibrate --static s01_task.c3d --frames 0-9 --map lab.toml -o s01.json\n"
        "  # neutral posture only (no landmarks in the map, or --method neutral):\n"
        "  ikid calibrate --static s01_static.c3d --method neutral --map lab.toml -o s01.json\n"
        "  # neutral frames + any movement bending the wrist both ways (functional axes):\n"
        "  ikid calibrate --static s01_task.c3d --frames 0-9 --motion s01_circles.c3d \\\n"
        "      --map lab.toml -o s01.json\n"
        "  # static trial + movements of one coordinate each:\n"
        "  ikid calibrate --static s01_static.c3d --movement ra_wr_e_f=s01_flex.c3d \\\n"
        "      --movement ra_wr_s_p=s01_pron.c3d --map lab.toml -o s01.json\n"
        "  # an arm without landmarks, its cluster the mirror image of the other arm's (mounted alike):\n"
        "  ikid calibrate --static s01_task.c3d --frames 0-9 --map left.toml --method mirror \\\n"
        "      --from s01_right.json -o s01_left.json\n"
        "  ikid ik s01_task.c3d -o s01_task.mot --map lab.toml --calibration s01.json\n\n"
        "landmarks: the forearm's ISB frame (y from the mid-styloids to the mid-epicondyles, "
        "x = y x (ulnar -> radial styloid), z = x x y), each landmark averaged in the forearm cluster's "
        "frame over the frames it is seen in; the hand's frame equals the forearm's at the neutral "
        "posture, which reads zero, or, when the map names second_metacarpal_head and fifth_metacarpal_head, "
        "is the hand's own (y from the mid-heads to the mid-styloids, as the forearm's). "
        "With landmarks, clusters may sit at any orientation. "
        "neutral: the same, the forearm at the body model's placement: refused (saying what to record) when "
        "the forearm's markers are not spread as the model's RSP, USP and FAP (clusters, plates). "
        "functional: the flexion axis (fixed in the forearm) and the deviation axis (fixed in the hand) "
        "fitted by least squares to a movement mixing both, pronation held; the neutral frames read zero; "
        "the axes' signs come from the forearm markers' placement (within 60 degrees of the body model's), "
        "the hand's cluster may sit any way round. "
        "mirror: the forearm's frame of the other arm's landmarks calibration (--from), for a forearm "
        "cluster that is the same and mounted as its mirror image, checked: the cluster's shape, and a "
        "landmark of this arm (the map's [landmarks], any of them; the lateral epicondyle is enough) where "
        "the other arm's frame puts it, which also says which marker matches which on a symmetric plate; "
        "the hand's frame from this arm's neutral frames. "
        'A left arm (side = "left" in the map, or --side left) is mirrored into a right arm: its angles keep '
        "their anatomical signs.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--static",
        required=True,
        help="marker file of the neutral posture: a static trial, or any trial with --frames",
    )
    p.add_argument(
        "--frames",
        metavar="LIST",
        help="frames of --static in the neutral posture, 0-based: 0-9, 41,76,220 (default: all); the "
        "landmarks are averaged over them too",
    )
    p.add_argument(
        "--method",
        choices=["auto", "landmarks", "neutral", "functional", "movements", "mirror"],
        default="auto",
        help="auto (default): movements if --movement is given, functional if --motion is, mirror if --from "
        "is, landmarks if the map names them, else neutral",
    )
    p.add_argument(
        "--from",
        dest="mirror_from",
        metavar="JSON",
        help="mirror method: the other arm's calibration (from its landmarks; same session, same clusters)",
    )
    p.add_argument(
        "--motion",
        metavar="FILE",
        help="functional method: a marker file where the wrist bends through flexion-extension and "
        "deviation together (circles, or a task), the forearm's rotation held",
    )
    p.add_argument("--motion-frames", metavar="LIST", help="frames of --motion to fit (default: all)")
    p.add_argument(
        "--landmarks",
        metavar="FILE",
        help="marker file holding the landmarks with the forearm's markers (default: --static), all its "
        "frames used",
    )
    p.add_argument(
        "--movement",
        action="append",
        default=[],
        metavar="COORD=FILE",
        help="a movement of that coordinate alone (movements method: at least two coordinates)",
    )
    p.add_argument("--side", choices=["right", "left"], help="the arm (default: the map's side, else right)")
    p.add_argument("--map", metavar="TOML", help="marker map, optionally with [landmarks] (see map-template)")
    p.add_argument("-o", "--output", required=True, help="calibration JSON to write")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Landmarks and/or neutral frames, or static + single-coordinate movement files -> a
    calibration JSON recording the method, the side and the marker map."""
    from ikid.calibration import (
        calibrate_functional,
        calibrate_mirror,
        calibrate_neutral,
        calibration_info,
        check_landmarks_place_the_hand,
    )
    from ikid.io import MarkerMap, read_markers
    from ikid.io.mapping import MarkerMapWarning, landmark_names

    def _frame_selection(spec: str, n: int, source: str, own_first: int | None = None) -> np.ndarray:
        """Frame numbers (0-based) from "0-9", "41,76,220" or "0-4,10-14"; each within the file.
        ``own_first``: the number the file gives its first frame, when not 0 or 1 (a C3D cut from
        a longer capture: Nexus shows 695 onward), said when a frame is outside."""
        chosen: list[int] = []
        for part in spec.split(","):
            lo, sep, hi = part.strip().partition("-")
            try:
                first, last = int(lo), int(hi) if sep else int(lo)
            except ValueError:
                raise SystemExit(
                    f"ikid: error: --frames {spec!r}: expected frame numbers such as 0-9 or 41,76,220"
                ) from None
            if first > last:
                raise SystemExit(
                    f"ikid: error: --frames {spec!r}: {part.strip()} runs backwards; give the first frame "
                    f"first ({last}-{first})"
                )
            if not 0 <= first <= last < n:
                own = (
                    f"; ikid counts a file's frames from 0, and this one numbers its own from {own_first} "
                    f"(as Nexus shows them): its frames {own_first}-{own_first + n - 1} are "
                    f"--frames 0-{n - 1}"
                    if own_first is not None
                    else ""
                )
                raise SystemExit(
                    f"ikid: error: --frames {spec!r}: {part.strip()} is outside frames 0-{n - 1} of "
                    f"{source}{own}"
                )
            chosen += range(first, last + 1)
        repeated = sorted({f for f in chosen if chosen.count(f) > 1})
        if repeated:
            # A frame given twice would count twice: its noise as if measured twice.
            raise SystemExit(
                f"ikid: error: --frames {spec!r}: frame {', '.join(map(str, repeated[:5]))} given more than "
                "once; name each frame once"
            )
        return np.array(sorted(chosen), np.int64)

    movement_files = [spec.partition("=")[2] or None for spec in args.movement]
    _refuse_over_inputs(
        [args.output],
        [args.static, args.landmarks, args.motion, args.map, args.mirror_from, *movement_files],
        given=args.output,
    )
    mapping = MarkerMap.load(args.map) if args.map else MarkerMap.identity()
    side = args.side or mapping.side
    static = read_markers(args.static)
    chosen = (
        _frame_selection(args.frames, len(static), args.static, _own_first(static)) if args.frames else None
    )
    forearm_landmarks = None
    if mapping.forearm_cluster:
        # A forearm cluster with one hand marker: its anatomical points, measured in the
        # cluster's frame where the landmarks are seen, make the virtual wrist bar and elbow.
        source = read_markers(args.landmarks) if args.landmarks else static
        where = chosen if (chosen is not None and not args.landmarks) else slice(None)
        forearm_landmarks = _forearm_landmarks(mapping, source, where)
        mapping = mapping.with_forearm_landmarks(forearm_landmarks["points_m"])
    neutral = static.frames(mapping)
    try:
        ikid.check_marker_units(neutral)
    except ikid.IkidError as e:
        raise type(e)(_naming(args.static, e)) from None
    flat = mapping.flat_segments(neutral)
    swapped = mapping.swapped_across_segments(neutral)
    if flat or swapped:
        raise ikid.InputError(f"{args.static}: " + "; ".join(flat + ([swapped] if swapped else [])))
    # Over the whole file (a static trial shows little; a task trial shows a marker across a joint).
    for problem in mapping.stretched_segments(neutral):
        warnings.warn(f"{args.static}: {problem}", MarkerMapWarning, stacklevel=1)
    if chosen is not None:
        neutral = neutral[chosen]
    method = args.method
    if method == "auto":
        method = (
            "movements"
            if args.movement
            else "functional"
            if args.motion
            else "mirror"
            if args.mirror_from
            else ("landmarks" if mapping.landmarks else "neutral")
        )
    if method != "movements" and args.movement:
        raise SystemExit(f"ikid: error: --movement is for --method movements, not {method}")
    if (method == "functional") != bool(args.motion):
        raise SystemExit(
            "ikid: error: --method functional needs --motion FILE (a movement mixing flexion and deviation)"
            if method == "functional"
            else f"ikid: error: --motion is for --method functional, not {method}"
        )
    if (method == "mirror") != bool(args.mirror_from):
        raise SystemExit(
            "ikid: error: --method mirror needs --from JSON (the other arm's landmarks calibration)"
            if method == "mirror"
            else f"ikid: error: --from is for --method mirror, not {method}"
        )
    if args.motion_frames and not args.motion:
        raise SystemExit("ikid: error: --motion-frames selects frames of --motion; give --motion FILE")
    provenance: dict = {"static": args.static, "frames": args.frames}
    if method == "movements":
        if side != "right":
            raise SystemExit(
                "ikid: error: the movements method measures right arms only; calibrate a left arm from "
                "landmarks or neutral frames"
            )
        movements = {}
        for spec in args.movement:
            coord, sep, path = spec.partition("=")
            if not sep or coord not in ikid.coordinate_names():
                raise SystemExit(
                    f"ikid: error: --movement {spec!r}: expected COORDINATE=FILE, COORDINATE one of "
                    f"{', '.join(ikid.coordinate_names())}"
                )
            movements[coord] = read_markers(path).frames(mapping)
        cal = ikid.calibrate(neutral, movements)
        provenance["movements"] = dict(s.partition("=")[::2] for s in args.movement)
    elif method == "landmarks":
        source = read_markers(args.landmarks) if args.landmarks else static
        where = chosen if (chosen is not None and not args.landmarks) else slice(None)
        points = np.concatenate(
            [source.marker(lab, mapping.up) for lab in mapping.landmark_labels_in_order(source)], axis=1
        )[where]
        beside = neutral if source is static else source.frames(mapping)[where]
        hand_labels = mapping.hand_landmark_labels_in_order(source)
        hand_points = (
            None
            if hand_labels is None
            else np.concatenate([source.marker(lab, mapping.up) for lab in hand_labels], axis=1)[where]
        )
        if hand_points is None and mapping.one_hand_marker:
            # A one-marker hand's frame is its marker and the styloid line (as Plug-in Gait's):
            # the landmarks it stands for make the calibration read its direction, not zero.
            columns = np.concatenate(
                [source.marker(lab, mapping.up) for lab in mapping.labels_in_ikid_order(source)], axis=1
            )
            columns = mapping.anatomical_forearm(mapping.fit_clusters(source, columns))
            hand_points = ikid._native.one_marker_hand_landmarks(columns)[where]
        if not mapping.one_hand_marker:  # its forearm's markers are its landmarks
            check_landmarks_place_the_hand(neutral, points, beside, args.landmarks or args.static)
        with _about_the_static_trial(args.static, mapping, static.frames(mapping), static.rate_hz):
            cal = calibrate_neutral(
                neutral, points, landmark_frames=beside, side=side, hand_landmarks=hand_points
            )
        if hand_labels is None and mapping.one_hand_marker:
            _check_one_marker_neutral(cal, mapping, args.static)
        provenance["landmarks"] = args.landmarks or args.static
    elif method == "mirror":
        source = read_markers(args.landmarks) if args.landmarks else static
        where = chosen if (chosen is not None and not args.landmarks) else slice(None)
        named = mapping.landmarks
        absent = [
            f"{named[k]} ({k})" for k in landmark_names() if k in named and named[k] not in source.labels
        ]
        if absent:
            raise ikid.InputError(
                f"{source.source or args.static}: landmark label(s) {', '.join(absent)} not found; the file "
                f"has {', '.join(source.labels) or 'no labels'}"
            )
        nan = np.full((len(source), 3), np.nan)
        points = np.concatenate(
            [source.marker(named[k], mapping.up) if k in named else nan for k in landmark_names()], axis=1
        )[where]
        beside = neutral if source is static else source.frames(mapping)[where]
        seen = np.isfinite(points).any()
        cal = calibrate_mirror(
            args.mirror_from,
            neutral,
            points if seen else None,
            landmark_frames=beside if seen else None,
            side=side,
        )
        provenance["mirror_from"] = args.mirror_from
        # The other arm's size (from its landmarks): this arm's torques scale with it.
        other = (calibration_info(args.mirror_from).get("report") or {}).get("landmarks") or {}
        if other.get("length_scale") is not None:
            provenance["mirror_length_scale"] = float(other["length_scale"])
        provenance["landmarks"] = args.landmarks or args.static
    elif method == "functional":
        motion = read_markers(args.motion)
        moving = motion.frames(mapping)
        if args.motion_frames:
            moving = moving[
                _frame_selection(args.motion_frames, len(moving), args.motion, _own_first(motion))
            ]
        cal = calibrate_functional(neutral, moving, side=side)
        provenance["motion"] = args.motion
        provenance["motion_frames"] = args.motion_frames
    else:
        with _about_the_static_trial(args.static, mapping, static.frames(mapping), static.rate_hz):
            cal = calibrate_neutral(neutral, side=side)
    from ikid.calibration import marker_distances

    ikid.save_calibration(
        cal,
        args.output,
        marker_map=mapping,
        forearm_landmarks=forearm_landmarks,
        # The markers' layout as calibrated: a trial laid out otherwise is refused (another session).
        marker_distances=marker_distances(neutral, mapping.one_hand_marker),
        hand_point_m=_hand_point_distance(static, mapping, chosen),
        **provenance,
    )
    r = cal.report or {}
    spread = r.get("neutral_spread_deg", 0.0)
    used = r.get("neutral_frames", len(neutral))
    noise, uncertainty = r.get("neutral_noise_deg", 0.0), r.get("neutral_uncertainty_deg", 0.0)
    details = [
        f"{used} of {len(neutral)} neutral frames used (spread {spread:.1f}°, marker noise "
        f"{noise:.1f}° a frame, neutral posture ± {uncertainty:.2f}°)"
    ]
    if chosen is not None and (own := _own_first(static)) is not None:
        # Frames given in the file's own numbers would be other frames: which ones were taken.
        details.insert(
            0,
            f"--frames {args.frames} counted from 0: {args.static}'s own frames "
            f"{own + int(chosen.min())}-{own + int(chosen.max())}",
        )
    if r.get("movements"):
        details.append(
            "movements: "
            + ", ".join(
                f"{k} {v['range_deg']:.0f}° ({100 * v['single_axis_share']:.1f} % one axis)"
                for k, v in r["movements"].items()
            )
            + f"; axis skew {r.get('axis_skew_deg', 0):.2f}°"
        )
    if r.get("functional"):
        fn = r["functional"]
        details.append(
            f"functional fit over {fn['frames']} frames: flexion {fn['flexion_range_deg']:.0f}°, deviation "
            f"{fn['deviation_range_deg']:.0f}°, pronation held at {-fn['supination_held_deg']:.0f}° "
            f"(residual {fn['residual_deg']:.1f}° RMS beside {fn['noise_deg']:.1f}° of marker noise)"
        )
    if r.get("mirror"):
        mi = r["mirror"]
        checked = ", ".join(f"{k} {v['mm']:.0f} mm ({v['deg']:.1f}°)" for k, v in mi["landmarks"].items())
        details.append(
            f"forearm mirrored from the {mi['from']} arm's calibration ({args.mirror_from}): cluster within "
            f"{mi['cluster_mm']:.1f} mm of its mirror image over {mi['frames']} frames"
            + (f"; {checked} from where it puts it" if checked else "; no landmark of this arm checked it")
            + (
                f" (the {mi['other_pairings']} other pairings of the markers the cluster's shape allows: "
                f"{mi['next_pairing_deg']:.0f}° or more)"
                if mi["other_pairings"] and mi["next_pairing_deg"] is not None
                else ""
            )
        )
    if forearm_landmarks is not None:
        details.append(
            f"forearm cluster's anatomical points from the landmarks in {forearm_landmarks['frames']} frames "
            f"(spread {forearm_landmarks['spread_mm']:.1f} mm RMS)"
        )
    if r.get("landmarks"):
        lm = r["landmarks"]
        if lm.get("hand"):
            source_of_hand = (
                "its one marker and the styloid line" if mapping.one_hand_marker else "its landmarks"
            )
            details.append(
                f"hand frame from {source_of_hand} ({lm['hand']['frames']} frames; the neutral frames read "
                f"{lm['hand']['neutral_offset_deg']:.1f}° from zero)"
            )
        details.append(
            f"landmarks: forearm axis {lm['long_axis_mm']:.0f} mm, styloids "
            f"{lm['styloid_span_mm']:.0f} mm apart at {lm['styloid_axis_deg']:.0f}° to it, seen in "
            + "/".join(str(n) for n in lm["frames"].values())
            + " frames"
        )
    print(f"{cal!r}; {'; '.join(details)} -> {args.output}")
    return 0


@contextlib.contextmanager
def _about_the_static_trial(static: str, mapping, frames: np.ndarray, rate_hz: float) -> Iterator[None]:
    """A calibration's error from the static trial's frames, in the lab's terms: named after
    that file, each marker it counts ("missing: MC2 in 697") with the label the map gives it;
    frames that are not held still are answered with the stillest ones the file has."""
    try:
        yield
    except ikid.IkidError as e:
        labelled = re.sub(
            rf"\b({'|'.join(ikid.marker_names())}) in (\d+)",
            lambda m: f"{m[1]} ({mapping.labels.get(m[1], m[1])!r}) in {m[2]}",
            _message(e),
        )
        if "holds one posture" in labelled and (still := _stillest_frames(frames, rate_hz)) is not None:
            first, last, spread = still
            labelled += (
                f" (the stillest {last - first + 1} frames of this trial: --frames {first}-{last}, the wrist "
                f"within {spread:.1f}° there; use them if the wrist is in its neutral posture)"
            )
        raise type(e)(_naming(static, type(e)(labelled))) from None


def _stillest_frames(frames: np.ndarray, rate_hz: float) -> tuple[int, int, float] | None:
    """The 0.1 s (at least 5 frames) of complete ``frames`` over which the wrist's angles (the
    body model's reading: offsets from another placement are constant, so stillness reads
    true) move least: ``(first, last, largest distance from their mean, degrees)``; None if the
    file has no such run."""
    width = max(5, round(0.1 * rate_hz))
    whole = np.isfinite(frames).all(axis=1)
    if whole.sum() < width:
        return None
    q = np.full((len(frames), 3), np.nan)
    try:
        q[whole] = ikid.reference_ik(frames[whole])
    except ikid.IkidError:
        return None
    windows = np.lib.stride_tricks.sliding_window_view(q, width, axis=0)  # (n - width + 1, 3, width)
    spread = np.abs(windows - windows.mean(axis=2, keepdims=True)).max(axis=(1, 2))  # NaN: incomplete
    if not np.isfinite(spread).any():
        return None
    first = int(np.nanargmin(spread))
    return first, first + width - 1, float(np.degrees(spread[first]))


def _hand_point_distance(static, mapping, chosen) -> float | None:
    """A one-marker hand's marker's distance from the wrist over the neutral frames ``chosen``
    of ``static`` (a trial's must keep it: ``marker_checks.check_hand_point``); None for a
    hand of three markers."""
    if not mapping.one_hand_marker:
        return None
    from ikid.io.marker_checks import hand_point_distance

    columns = np.concatenate(
        [static.marker(lab, mapping.up) for lab in mapping.labels_in_ikid_order(static)], axis=1
    )
    columns = mapping.anatomical_forearm(mapping.fit_clusters(static, columns), check=False)
    return hand_point_distance(columns[chosen] if chosen is not None else columns)


def _forearm_landmarks(mapping, source, where) -> dict:
    """A forearm cluster's anatomical points (radial and ulnar styloid, mid-epicondyles) in the
    technical frame of its three markers, from the frames of ``source`` (``where``) that see
    the landmarks and the cluster: their median, with how many frames and how far they spread.
    Refused with fewer than the neutral frames a calibration needs."""
    from ikid.io.mapping import landmark_names

    columns = np.concatenate(
        [source.marker(lab, mapping.up) for lab in mapping.labels_in_ikid_order(source)], axis=1
    )
    three = mapping.fit_clusters(source, columns)[:, :9]
    local = ikid._native.points_in_technical_frame(three, mapping.forearm_landmark_points(source), 3)[where]
    local = local[np.isfinite(local).all(axis=1)]
    least = ikid._native.MIN_NEUTRAL_FRAMES
    if len(local) < least:
        named = ", ".join(mapping.landmarks[k] for k in landmark_names())
        raise ikid.InputError(
            f"{source.source}: the forearm's landmarks ({named}) and its markers are seen together in "
            f"{len(local)} of the frames given; the forearm cluster's anatomical points are measured over "
            f"at least {least}: record a static trial with the styloid and epicondyle markers (or their "
            "probed points) on"
        )
    points = np.median(local, axis=0)
    spread = float(np.sqrt(np.mean(np.sum((local - points).reshape(len(local), 3, 3) ** 2, axis=2))))
    return {
        "in_frame_of": [mapping.labels[m] for m in ("RSP", "USP", "FAP")],
        "points_m": points.reshape(3, 3).tolist(),
        "points": ["radial_styloid", "ulnar_styloid", "mid_epicondyles"],
        "frames": len(local),
        "spread_mm": 1e3 * spread,
    }


def _own_first(data) -> int | None:
    """The number a C3D gives its first frame (its header's, 1-based) when the capture was cut
    from a longer one (not 0 or 1), else None."""
    first = data.metadata.get("first_frame")  # 0-based, as the C3D reader gives it
    return int(first) + 1 if first else None


#: How far from zero a one-marker hand may read at the neutral frames, degrees. Its angles are
#: the marker's direction in the forearm (not zeroed at the static posture, as Plug-in Gait's),
#: so what it reads there every angle carries. Plug-in Gait's FIN over the third metacarpal:
#: 14-15° on the real recording (both arms; a subject's rest is not the anatomical zero); a
#: wheelchair glove's marker off the hand's axis 64° (then e_f 49° and ad_ab 40° on average
#: through propulsion, status 0, before this limit); a thigh marker labelled as the hand 108°.
ONE_MARKER_NEUTRAL_MAX_DEG = 30.0


def _check_one_marker_neutral(cal, mapping, static: str) -> None:
    """Refuse a one-marker hand that reads far from zero at the neutral frames
    (:data:`ONE_MARKER_NEUTRAL_MAX_DEG`): the marker is not where its direction is the hand's,
    or the trial is not neutral, and every angle would carry the offset."""
    hand = ((cal.report or {}).get("landmarks") or {}).get("hand") or {}
    offset = hand.get("neutral_offset_deg")
    if offset is None or offset <= ONE_MARKER_NEUTRAL_MAX_DEG:
        return
    label = mapping.label_of(ikid._native.HAND_POINT[0])
    raise ikid.InputError(
        f"{static}: the hand's one marker {label!r} ({ikid._native.HAND_POINT[0]}) reads the hand "
        f"{offset:.0f}° from zero at the neutral frames (over {ONE_MARKER_NEUTRAL_MAX_DEG:g}°): its angles "
        "are that marker's direction from the wrist, so every one would be off by as much. Either it "
        "is not on the back of the hand over the third metacarpal (Plug-in Gait's FIN: a glove's "
        "marker off the hand's axis, or another marker under its label), or these frames are not "
        "the neutral posture. Place it there, give neutral frames (--frames), or record the hand's "
        "landmarks in the static trial ([landmarks] second_metacarpal_head and "
        "fifth_metacarpal_head) so the calibration measures the hand's axis"
    )
