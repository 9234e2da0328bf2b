"""`ikid track`: markers -> angles and torques with ikid.Tracker and its refiner."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

import ikid
from ikid import _native
from ikid.cli.common import (
    _model_file,
    _model_for,
    _named,
    _naming,
    _refuse_over_inputs,
    _stem,
    _subject_calibration,
    subject_size,
)
from ikid.cli.options import SUBJECT_LENGTH, SUBJECT_MASS, _number, unchecked_option
from ikid.io._atomic import atomic_outputs
from ikid.pipeline import TURNED_OVER_REASON, fill_leading_gaps


def _is_shipped_refiner(refiner: ikid.Model) -> bool:
    """True if ``refiner`` is the shipped ``wrist-track`` (the same tensors, by their checksum):
    the refined σ's shares were measured for it alone."""
    shipped = ikid.load("wrist-track").card.get("tensor_sha256")
    return shipped is not None and refiner.card.get("tensor_sha256") == shipped


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "track",
        help="markers -> angles (.mot) and torques (.sto) with the Kalman tracker + its refiner",
        description="Markers -> wrist angles and torques, causally, with ikid.Tracker: an extended Kalman "
        "filter over the body model that learns each marker coordinate's noise, refined by the shipped "
        "wrist-track network.\n\n"
        "  ikid track trial.c3d -o out/trial --length-scale 1.1 --mass-scale 1.3"
        "   # out/trial.mot, out/trial.sto\n\n"
        "Each angle and torque is followed by its standard deviation (<name>_sd, listed in the "
        "header's ikid_sd line; docs/live.md measures how well it covers), unless a refiner other "
        "than the shipped one is given.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="marker file (.c3d, .trc, .csv)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="output stem: writes STEM.mot and STEM.sto (together); a folder (ending with / or existing): "
        "FOLDER/<input name>.mot, .sto",
    )
    p.add_argument("--map", help="marker map (TOML) from the file's labels to ikid's")
    p.add_argument(
        "--length-scale",
        type=SUBJECT_LENGTH,
        default=None,
        help="subject's segment lengths / the default subject's (default: the calibration's estimate "
        "from its landmarks, else 1)",
    )
    p.add_argument(
        "--mass-scale",
        type=SUBJECT_MASS,
        default=None,
        help="subject's segment masses / the default subject's (default: the cube of the length scale)",
    )
    p.add_argument(
        "--refiner",
        default="auto",
        help="refinement model, shipped name or file; 'none' for the bare filter; 'auto' (default): "
        "the shipped wrist-track family's member at the recording's rate (wrist-track: 1000 Hz), else none "
        "(the summary says which; a refiner at another rate: python -m ikid_training.refine --rate)",
    )
    p.add_argument(
        "--jerk-noise",
        type=_number(gt=0, le=1e12, unit=" rad²/s⁵"),
        default=ikid.DEFAULT_JERK_NOISE,
        help=f"motion model's jerk density, rad²/s⁵ (default {ikid.DEFAULT_JERK_NOISE:g}, "
        "tuned in docs/ekf.md)",
    )
    p.add_argument(
        "--calibration",
        metavar="JSON",
        help="the subject's marker placement (see `ikid calibrate`); without it the body model's placement "
        "is checked against the markers first, and a recording it cannot read is refused",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 if any frame has no estimate or is flagged (the ikid_status column), but the "
        "filter's first estimates, flagged restarted while its rates settle in every file",
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Markers -> angles (.mot) and torques (.sto) with ``ikid.Tracker``: the causal Kalman
    tracker over the body model, for one subject (no network), at the recording's own rate.
    Every row carries its status bits; a row no wrist can give is not written but counted.
    The file is read, tracked and written a block at a time (memory independent of its length;
    the tracker's state carries from block to block)."""
    from contextlib import ExitStack

    from ikid.calibration import map_with_calibration
    from ikid.io import MarkerMap, mot_writer, open_markers, sto_writer
    from ikid.io.markers import check_markers_seen, seen_markers

    stem = _stem(args.output, Path(args.input).stem, create=False)
    refiner_file = None if args.refiner in ("auto", "", "none") else _model_file(args.refiner)
    _refuse_over_inputs(
        [_named(stem, ".mot"), _named(stem, ".sto")],
        [args.input, args.map, args.calibration, refiner_file],
        given=args.output,
    )
    data = open_markers(args.input)
    refiner = None
    if args.refiner == "auto":
        from ikid.pipeline import family_members, same_rate

        # The shipped refiner family's member at the recording's rate, if there is one.
        refiner = next(
            (m for m in family_members("wrist-track") if same_rate(data.rate_hz, m.frame_rate_hz)), None
        )
    elif args.refiner not in ("", "none"):
        refiner = _model_for(
            args.refiner, "ikid track --refiner", ("refine",), allow_unchecked=args.allow_unchecked_model
        )
    mapping = map_with_calibration(MarkerMap.load(args.map), args.calibration) if args.map else None
    first = next(data.blocks(), None)
    if first is None:
        raise ikid.InputError(f"{args.input}: no frames")
    calibration = _subject_calibration(
        first.frames(mapping, whole=False), args.calibration, mapping, args.input
    )
    # Gravity's direction: the torques depend on it (the frames come turned into ikid's +Y up).
    up, up_from = first.lab_up(mapping.up if mapping else None)
    length_scale, mass_scale, size_from = subject_size(
        args.calibration,
        args.length_scale,
        args.mass_scale,
        first.frames(mapping, whole=False),
        str(args.input),
    )
    try:
        tracker = ikid.Tracker(
            length_scale=length_scale,
            mass_scale=mass_scale,
            rate_hz=data.rate_hz,
            jerk_noise=args.jerk_noise,
            refiner=refiner,
            calibration=calibration,
        )
    except ikid.IkidError as e:
        raise type(e)(_naming(args.input, e)) from None
    bits = ikid.FRAME_STATUS
    gap_restarts = bridged = 0
    k: int | None = None  # the first frame with an estimate
    n_frames = kept = lost = turned_over = 0
    counts = dict.fromkeys(bits, 0)
    seen = np.zeros(6, bool)
    flagged_after_start = False
    stem.parent.mkdir(parents=True, exist_ok=True)
    mot, sto = _named(stem, ".mot"), _named(stem, ".sto")
    # Coordinates the markers do not determine (a one-marker hand's s_p) are not written.
    undetermined = mapping.undetermined if mapping else {}
    # The pair replaces the old pair, or neither is replaced.
    with atomic_outputs(), ExitStack() as files:
        # Each value followed by its standard deviation (Tracker.output_sd): the filter's, or for
        # a refined estimate the filter's times the shares measured for the shipped refiner
        # (studies/sigma_coverage.py) — for another refiner nothing measured says (docs/live.md).
        with_sd = refiner is None or _is_shipped_refiner(refiner)
        write_q = files.enter_context(mot_writer(mot, undetermined=undetermined, with_sd=with_sd))
        write_tau = files.enter_context(sto_writer(sto, undetermined=undetermined, with_sd=with_sd))

        def mapped_blocks():
            for block in data.blocks():
                frames = block.frames(mapping, whole=False)
                np.logical_or(seen, seen_markers(frames), out=seen)
                yield block.time, frames

        # A file is whole: the gaps before its first complete frame are filled from the motion
        # after them (fill_leading_gaps), so the tracker starts on the first frame; once it has
        # started it carries through gaps itself.
        complete_seen = False
        # The filter runs at the file's rate, each frame stamped with its time: across a time
        # gap (frames lost) its motion model would bridge the gap as one period (torques 4 N·m
        # off after 0.1 s), so the core restarts it there (Tracker.gap_restarts), keeping what
        # it learned of the subject; its rows wait for the next complete frame.
        for time, frames, filled in fill_leading_gaps(mapped_blocks(), data.rate_hz):
            prefilled = np.zeros(len(frames), bool)
            if not complete_seen:
                complete = np.flatnonzero(~np.isnan(frames).any(axis=1))
                before = int(complete[0]) if len(complete) else len(frames)
                complete_seen = len(complete) > 0
                if filled is not None and before:
                    prefilled[:before] = np.isnan(frames[:before]).any(axis=1) & ~np.isnan(
                        filled[:before]
                    ).any(axis=1)
                    frames = np.where(prefilled[:, None], filled, frames)
            try:
                out = tracker.run(frames, sd=with_sd, times=time)
            except ikid.InputError as e:
                if "tracker never started" in str(e):
                    n_frames += len(frames)  # not (re)started yet: a later block may start it
                    continue
                raise type(e)(_naming(args.input, e)) from None
            except ikid.IkidError as e:
                raise type(e)(_naming(args.input, e)) from None
            status = out["status"] | np.where(prefilled, bits["filled"], 0).astype(out["status"].dtype)
            # Rows with an estimate: from the start on, but for those waiting after a time gap.
            keep = ~np.isnan(out["q"]).any(axis=1)
            first_start = k is None
            if k is None:
                k = n_frames + int(out["start"])
            implausible = keep & (status & bits["implausible"] != 0)
            keep &= ~implausible  # nothing no wrist can do is written as a number
            turned_over += int(np.count_nonzero(implausible & (status & bits["turned_over"] != 0)))
            q_sd, tau_sd = (out["q_sd"][keep], out["tau_sd"][keep]) if with_sd else (None, None)
            write_q(time[keep], out["q"][keep], status[keep], q_sd)
            write_tau(time[keep], out["tau"][keep], status[keep], tau_sd)
            for name, bit in bits.items():
                counts[name] += int(np.count_nonzero(status[keep] & bit))
            after = status[int(out["start"]) :].copy()
            if first_start:
                # The filter's own start: its first LOST_S of estimates are flagged restarted while
                # the velocities and accelerations settle, in every file (review 7: --strict
                # exited 3 on clean markers), as `ikid id` leaves out a file's edges.
                settling = max(math.ceil(_native.LOST_S * data.rate_hz), 3)
                after[:settling] &= ~np.asarray(bits["restarted"], after.dtype)
            flagged_after_start |= bool(after.any())
            n_frames += len(frames)
            kept += int(keep.sum())
            lost += int(implausible.sum())
        gap_restarts, bridged = tracker.gap_restarts, tracker.bridged_frames
        check_markers_seen(seen, mapping or MarkerMap.identity(), args.input)
        if k is None:
            raise ikid.InputError(
                f"{args.input}: none of the {n_frames} frames has every marker present and consistent, "
                "so the tracker never started"
            )
        if kept == 0:  # every estimate implausible: no file that looks like a result
            why = f"; {turned_over} because {TURNED_OVER_REASON}" if turned_over else ""
            raise ikid.InputError(
                f"{args.input}: no frame tracked: the {lost} estimates from frame {k} on are all "
                f"implausible{why}"
            )
    noise_mm = ", ".join(f"{v * 1e3:.2f}" for v in tracker.marker_noise)
    refiner_name = refiner.name if refiner else ""
    how = f"refined by {refiner_name}" if refiner else "not refined"
    placed = "uncalibrated"
    if args.calibration:
        from ikid.calibration import calibration_info

        placed = f"calibrated ({calibration_info(args.calibration)['method']}, {calibration.side} arm)"
    elif calibration is not None:  # a left arm at the body model's placement, mirrored
        placed = f"uncalibrated, {calibration.side} arm mirrored into a right one"
    notes = [f"{n} {name.replace('_', ' ')}" for name, n in counts.items() if n]
    if lost:
        notes.append(f"{lost} implausible (not written)")
    if turned_over:
        notes.append(f"{turned_over} of them because {TURNED_OVER_REASON}")
    if tracker.restarts:
        notes.append(f"{tracker.restarts} restarts after losing the hand")
    if bridged:
        notes.append(
            f"{bridged} lost frames bridged (under {_native.LOST_S * 1e3:g} ms in a row: the filter carried "
            "through them)"
        )
    if gap_restarts:
        notes.append(f"{gap_restarts} restarts after time gaps (frames lost: the filter started again)")
    print(
        f"{args.input}: {kept}/{n_frames} frames tracked from frame {k} "
        f"at {data.rate_hz:g} Hz, subject ×{length_scale:.3g} length, ×{mass_scale:.3g} mass ({size_from}), "
        f"{placed}, {how}, lab up {up} ({up_from}); flagged: {', '.join(notes) or 'none'}; "
        f"hand marker noise learned (mm): {noise_mm}"
        + "".join(f"; {name} not written: {why}" for name, why in undetermined.items())
        + (
            "; each value followed by its standard deviation (_sd)"
            if with_sd
            else f"; no _sd columns (σ is measured for the shipped refiner, not for {refiner_name})"
        )
        + f" -> {mot}, {sto}"
    )
    if args.strict and (k > 0 or flagged_after_start or gap_restarts):
        print(f"ikid: --strict: {args.input} has frames without an estimate or flagged", file=sys.stderr)
        return 3
    return 0
