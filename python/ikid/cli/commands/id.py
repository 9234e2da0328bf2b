"""`ikid id`: angles (.mot) -> wrist torques (.sto)."""

from __future__ import annotations

import argparse
import itertools
import math
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np

import ikid
from ikid import _native
from ikid.cli.common import (
    _check_uncertainty,
    _is_folder,
    _model_file,
    _model_for,
    _named,
    _refuse_over_inputs,
    _stem,
)
from ikid.cli.options import LOWPASS_HZ, SHOULDER_DEG, SUBJECT_LENGTH, SUBJECT_MASS, unchecked_option
from ikid.kinematics import DEFAULT_LOWPASS_HZ


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "id",
        help="angles (.mot) -> wrist torques (.sto)",
        description="Angles -> torques (velocities, accelerations: central differences).\n\n"
        "  ikid id trial.mot -o trial.sto                 # the wrist-id network\n"
        "  ikid id trial.mot -o trial.sto --sd            # ... each torque followed by its SD\n"
        "  ikid id trial.mot -o trial.sto --reference --length-scale 1.1 --mass-scale 1.33",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", metavar="IN", help="angles, OpenSim .mot")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help=".sto to write, or a folder (ending with / or existing): FOLDER/<input name>.sto",
    )
    p.add_argument("--model", default="wrist-id", help="joint-state model (default wrist-id)")
    p.add_argument(
        "--reference",
        action="store_true",
        help="exact Newton-Euler for the subject below instead of the network",
    )
    p.add_argument("--length-scale", type=SUBJECT_LENGTH, help="subject size (--reference only; default 1)")
    p.add_argument(
        "--mass-scale", type=SUBJECT_MASS, help="subject mass factor (--reference only; default 1)"
    )
    p.add_argument(
        "--shoulder-deg", type=SHOULDER_DEG, help="shoulder flexion, degrees (--reference only; default 0)"
    )
    p.add_argument(
        "--resample",
        action="store_true",
        help="resample the angles to the model's rate (cubic Hermite; each stretch between time gaps alone: "
        "nothing is made inside a gap)",
    )
    p.add_argument(
        "--lowpass",
        type=LOWPASS_HZ,
        default=DEFAULT_LOWPASS_HZ,
        metavar="HZ",
        help=f"low-pass the angles at HZ before differencing them (zero-lag 4th-order Butterworth; "
        f"default {DEFAULT_LOWPASS_HZ:g}, as OpenSim's inverse dynamics is run; 0: not filtered). "
        "Unfiltered, angles from noisy markers give mostly implausible torques",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 if any frame was refused or any torque flagged (the ikid_status column)",
    )
    p.add_argument(
        "--sd",
        action="store_true",
        help="follow each torque by its standard deviation, <name>_moment_sd, listed in the header's "
        "ikid_sd line: the model card's uncertainty (studies/net_sigma.py fits it on angles written by "
        "`ikid ik` and measures how well it covers). Rows whose σ is not yet known (the first frames) "
        "are not written; the summary counts them. Not with --reference",
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Angles (.mot) -> torques (.sto): the wrist-id network over (q, q̇, q̈), or the exact
    Newton-Euler reference for a subject (``--reference``). The angles are low-passed and
    differenced (:func:`ikid.kinematics.joint_state_blocks`: central differences, a file is
    offline). The file is read, resampled (``--resample``), filtered and written a block at a
    time: memory does not grow with its length."""
    from ikid.io import mot_blocks, sto_writer
    from ikid.io.resample import resample_stretches
    from ikid.kinematics import gap_edge_s, joint_state_blocks_near_edges, min_stretch_rows, sample_rate
    from ikid.pipeline import check_rate, run_blocks

    subject = [
        f"--{name} {value:g}"
        for name, value in (
            ("length-scale", args.length_scale),
            ("mass-scale", args.mass_scale),
            ("shoulder-deg", args.shoulder_deg),
        )
        if value is not None
    ]
    if subject and not args.reference:
        # Review 7: ignored without --reference, a 45° recording's torques came out as large as
        # the true ones wrong, exit 0, the summary saying "shoulder flexed 0°".
        raise ikid.ArgumentError(
            f"ikid id {' '.join(subject)}: the network (--model {args.model}) gives the torques of the "
            "subject and shoulder pose it was trained for and takes no other; these set the exact "
            "Newton-Euler reference's: add --reference, or leave them out"
        )
    args.length_scale = 1.0 if args.length_scale is None else args.length_scale
    args.mass_scale = 1.0 if args.mass_scale is None else args.mass_scale
    args.shoulder_deg = 0.0 if args.shoulder_deg is None else args.shoulder_deg
    if args.sd and args.reference:
        raise ikid.ArgumentError(
            "ikid id --sd: the exact Newton-Euler reference (--reference) has no standard deviation to "
            "give; leave out one of them"
        )
    if args.resample and args.reference:
        raise ikid.ArgumentError(
            "ikid id --resample: resamples the angles to the network's rate; the exact Newton-Euler "
            "reference (--reference) runs at the file's own rate: leave out --resample"
        )
    output = (
        _named(_stem(args.output, Path(args.input).stem, create=False), ".sto")
        if _is_folder(args.output)
        else Path(args.output)
    )
    _refuse_over_inputs(
        [output], [args.input, None if args.reference else _model_file(args.model)], given=args.output
    )
    lowpass = args.lowpass or None
    least = min_stretch_rows(lowpass)

    def too_few(rows: int) -> ikid.InputError:
        need = (
            "velocities and accelerations" if lowpass is None else f"the {lowpass:g} Hz low-pass (--lowpass)"
        )
        counted = f"{rows} row" + ("" if rows == 1 else "s")
        return ikid.InputError(f"{args.input}: {counted}; at least {least} are needed for {need}")

    blocks = mot_blocks(args.input)
    first = next(blocks, None)
    if first is None or len(first[0]) < 2:
        raise too_few(0 if first is None else len(first[0]))
    # NaN only in a column the header declares not determined (a one-marker hand's s_p).
    undetermined = [
        c for c, nan in zip(ikid.coordinate_names(), np.isnan(first[1]).any(axis=0), strict=True) if nan
    ]
    if undetermined:
        raise ikid.InputError(
            f"{args.input}: {', '.join(undetermined)} not determined (its header's ikid_not_determined: "
            "the markers did not determine it); `ikid id` needs all three angles. `ikid track` on the "
            "markers gives the torques they determine (docs/markersets.md)"
        )
    # The rate of the first block (a file's first 65,536 rows): time gaps are steps over 1.5 of it.
    rate = sample_rate(first[0])
    angles: Iterator[tuple[np.ndarray, np.ndarray]] = _at_one_rate(
        itertools.chain([first], blocks), rate, args.input
    )
    notes = [f"angles low-passed at {lowpass:g} Hz" if lowpass else "angles not low-passed"]
    # The angles' extent as read: radians under a header saying degrees read as a wrist that
    # never leaves ±3.14° (review 7: torques of a still hand, 98 % off, status 0).
    extent = [0.0, math.inf, -math.inf]  # largest |angle|, smallest, largest

    def noted(blocks: Iterator[tuple[np.ndarray, np.ndarray]]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for time_s, q in blocks:
            if np.isfinite(q).any():
                extent[0] = max(extent[0], float(np.nanmax(np.abs(q))))
                extent[1], extent[2] = (
                    min(extent[1], float(np.nanmin(q))),
                    max(extent[2], float(np.nanmax(q))),
                )
            yield time_s, q

    angles = noted(angles)
    model = None
    if not args.reference:
        model = _model_for(args.model, "ikid id --model", ("id",), allow_unchecked=args.allow_unchecked_model)
        if args.sd:
            _check_uncertainty(args.model, model, "ikid id --sd --model")
        if check_rate(model, rate, args.input, args.resample):
            # Each stretch between time gaps alone: no angle is made inside a gap.
            angles = resample_stretches(angles, rate, model.frame_rate_hz)
            notes.insert(
                0, f"angles resampled {rate:g} -> {model.frame_rate_hz:g} Hz (cubic Hermite, --resample)"
            )
            rate = model.frame_rate_hz
    rows = short = implausible_angles = 0
    first_implausible: tuple[float, np.ndarray] | None = None
    # Times of the rows next to a time gap, and next to the file's own ends (their states still
    # settling), flagged restarted; the rows come back in time order, so those before the rows
    # asked about are dropped.
    settling, at_ends = np.empty(0), np.empty(0)

    def near_edges(time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Which of these rows lie next to a time gap, and which next to the file's ends."""
        nonlocal settling, at_ends
        if len(time_s):
            settling, at_ends = settling[settling >= time_s[0]], at_ends[at_ends >= time_s[0]]
        return np.isin(time_s, settling), np.isin(time_s, at_ends)

    restarted = ikid.FRAME_STATUS["restarted"]

    def states() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The joint states of the rows in stretches long enough to filter and difference; the
        rows whose angles no wrist reaches are counted (most of a file: it is refused below)."""
        nonlocal rows, short, implausible_angles, first_implausible, settling, at_ends
        for time_s, state, near_gap, near_end in joint_state_blocks_near_edges(angles, rate, lowpass):
            known = np.all(np.isfinite(state), axis=1)
            settling = np.concatenate([settling, time_s[known & near_gap]])
            at_ends = np.concatenate([at_ends, time_s[known & near_end]])
            rows += len(time_s)
            short += int((~known).sum())
            if known.any():
                bad = _native.joint_status(state[known, :3]) != 0
                implausible_angles += int(bad.sum())
                if first_implausible is None and bad.any():
                    k = int(np.argmax(bad))
                    first_implausible = (float(time_s[known][k]), state[known][k, :3])
                yield time_s[known], state[known]

    def refuse_if_mostly_implausible() -> None:
        """Refuses a file most of whose angles no wrist reaches (far past a coordinate's range,
        or turning the hand over: core ``status::joint_status``): its units or convention are not ikid's,
        and a file of the few rows left would read as a result."""
        used = rows - short
        if first_implausible is None or implausible_angles * 2 <= used:
            return
        t, q = first_implausible
        names = ikid.coordinate_names()
        shown = ", ".join(f"{n} {v:.3g} rad ({math.degrees(v):.0f}°)" for n, v in zip(names, q, strict=True))
        raise ikid.InputError(
            f"{args.input}: the angles of {implausible_angles} of its {used} rows lie where no wrist goes "
            f"(far past a coordinate's range, or turning the hand over; first at {t:g} s, as read: "
            f"{shown}): the file's units (its header's inDegrees) or its convention (zero posture, signs, "
            f"the order {', '.join(names)}) are not ikid's; nothing written"
        )

    lacking = written = 0
    output.parent.mkdir(parents=True, exist_ok=True)
    # The file becomes whole when the block ends, or is not written (an error part-way).
    # Every .sto ikid writes has its ikid_status column, so one reader takes either path's
    # (the reference's rows are all 0: what no wrist gives is left out, not flagged).
    with sto_writer(output, with_status=True, with_sd=args.sd) as write:
        # Rows flagged next to a gap (--strict counts them) and next to the file's ends (every
        # file has those: said, not counted).
        flagged_settling = flagged_ends = 0
        if model is None:
            implausible = 0
            for time_s, state in states():
                tau = _reference(args, state)
                # What no wrist gives is not written as a number (the network's path flags it).
                ok = _native.joint_status(state[:, :3], tau, args.mass_scale) == 0
                implausible += int((~ok).sum())
                gap, end = near_edges(time_s[ok])
                write(time_s[ok], tau[ok], np.where(gap | end, restarted, 0).astype(np.uint16))
                written += int(ok.sum())
                flagged_settling += int(np.count_nonzero(gap & ~end))
                flagged_ends += int(np.count_nonzero(end))
            summary = (
                f"{rows - short} frames, exact Newton-Euler (subject ×{args.length_scale:g} length, "
                f"×{args.mass_scale:g} mass)"
            )
            if implausible:
                notes.append(
                    f"{implausible} rows whose angles or torques no wrist gives (far past a coordinate's "
                    "range, the hand turned over, or past a wrist's torque for the subject's mass), "
                    "not written"
                )
            clean = implausible == 0 and flagged_settling == 0
        else:

            def sink(_frame, time_s, tau, status, sd) -> None:
                nonlocal lacking, written, flagged_settling, flagged_ends
                gap, end = near_edges(time_s)
                status = np.where(gap | end, status | restarted, status).astype(np.uint16)
                if args.sd:
                    # Only rows with a σ: the first frames' (too few to tell the noise) are counted.
                    known = np.all(np.isfinite(sd), axis=1)
                    lacking += int((~known).sum())
                    time_s, tau, status, sd = time_s[known], tau[known], status[known], sd[known]
                    gap, end = gap[known], end[known]
                write(time_s, tau, status, sd if args.sd else None)
                written += len(time_s)
                flagged_settling += int(np.count_nonzero(gap & ~end))
                flagged_ends += int(np.count_nonzero(end))

            run = run_blocks(model, states(), rate_hz=model.frame_rate_hz, source=args.input, on_rows=sink)
            summary, clean = run.summary(), run.clean and flagged_settling == 0
        if rows < least:
            raise too_few(rows)
        refuse_if_mostly_implausible()
        if short:
            notes.append(
                f"{short} rows in stretches between time gaps shorter than {least} rows "
                "(too short to low-pass and difference), not written"
            )
        if flagged_settling:
            notes.append(
                f"{flagged_settling} rows within {gap_edge_s(rate, lowpass):g} s of a time gap flagged "
                "restarted (the low-pass and the differences see the stretch on one side only there: "
                "their torques are less sure)"
            )
        # A .mot holds the hand's angles, not the forearm's pose in the lab: gravity's share of
        # the torques is that of an assumed forearm (review 5: on a real recording id's torques
        # ran opposite to track's, which measures the forearm, with status 0).
        notes.append(
            "gravity as for a still forearm, the elbow straight and the shoulder flexed "
            + (
                f"{args.shoulder_deg:g}° (--shoulder-deg)"
                if model is None
                else f"{', '.join(f'{d:g}' for d in _trained_shoulders(model))}° (as {model.name} "
                "was trained)"
            )
            + ": the angles do not say how the forearm was held; for a recording's torques, "
            "`ikid track` measures it from the forearm's markers"
        )
        if flagged_ends:
            notes.append(
                f"{flagged_ends} rows within {gap_edge_s(rate, lowpass):g} s of the file's first or last "
                "row flagged restarted (as next to a gap: one side only; every file has them, so "
                "--strict does not count them)"
            )
        if lacking:
            notes.append(
                f"{lacking} torque rows without a standard deviation (the first frames), not written"
            )
        summary = ", ".join([summary, *notes])
        if written == 0:
            raise ikid.InputError(f"{args.input}: no frame gave torques: {summary}")
    radians_as_degrees = extent[0] <= math.radians(math.pi) and extent[2] - extent[1] > math.radians(0.5)
    if radians_as_degrees:
        print(
            f"ikid: warning: {args.input}: every angle lies within ±{math.degrees(extent[0]):.3g}° as "
            "read, as radians under a header saying degrees would: if the file is in radians its "
            "header's inDegrees must say no (its torques here are those of a hand hardly moving)",
            file=sys.stderr,
        )
    print(f"{args.input}: {summary} -> {output}")
    if args.strict and not (clean and not short and not radians_as_degrees):
        print(f"ikid: --strict: {args.input} has refused, implausible or flagged frames", file=sys.stderr)
        return 3
    return 0


def _reference(args: argparse.Namespace, state: np.ndarray) -> np.ndarray:
    """The exact Newton-Euler torques of joint states ``(n, 9)`` for ``args``' subject."""
    return ikid.reference_id(
        state[:, :3],
        state[:, 3:6],
        state[:, 6:],
        shoulder_flexion=math.radians(args.shoulder_deg),
        length_scale=args.length_scale,
        mass_scale=args.mass_scale,
    )


def _at_one_rate(blocks, rate_hz: float, source: str) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The blocks, each checked to be at the first block's rate
    (:func:`~ikid.kinematics.sample_rate`): a file that changes rate is refused, not read as
    stretches too short to use."""
    from ikid.kinematics import sample_rate
    from ikid.pipeline import same_rate

    for time_s, q in blocks:
        if len(time_s) > 10 and not same_rate(rate := sample_rate(time_s), rate_hz):
            raise ikid.InputError(
                f"{source}: the rows from {time_s[0]:g} s are at {rate:g} Hz, the first rows at "
                f"{rate_hz:g} Hz: `ikid id` takes a file at one rate (write one file per rate)"
            )
        yield time_s, q


def _trained_shoulders(model) -> list[float]:
    """The shoulder flexions (degrees) a joint-state model's training data held the forearm at
    (its card's provenance), 0 when it does not say."""
    data = (model.card.get("provenance") or {}).get("data") or {}
    return [float(d) for d in data.get("shoulders_deg") or [0.0]]
