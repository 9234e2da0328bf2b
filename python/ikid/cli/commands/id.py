"""`ikid id`: angles (.mot) -> wrist torques (.sto)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

import ikid
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
    p.add_argument("--length-scale", type=SUBJECT_LENGTH, default=1.0, help="subject size (--reference)")
    p.add_argument("--mass-scale", type=SUBJECT_MASS, default=1.0, help="subject mass factor (--reference)")
    p.add_argument(
        "--shoulder-deg", type=SHOULDER_DEG, default=0.0, help="shoulder flexion, degrees (--reference)"
    )
    p.add_argument("--resample", action="store_true", help="resample the angles to the model's rate")
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
    differenced (:func:`ikid.kinematics.joint_states`: central differences, a file is offline)."""
    from ikid.io import read_mot, resample, sto_writer
    from ikid.kinematics import joint_states, min_stretch_rows
    from ikid.pipeline import check_rate, run_model

    if args.sd and args.reference:
        raise ikid.ArgumentError(
            "ikid id --sd: the exact Newton-Euler reference (--reference) has no standard deviation to "
            "give; leave out one of them"
        )
    output = (
        _named(_stem(args.output, Path(args.input).stem, create=False), ".sto")
        if _is_folder(args.output)
        else Path(args.output)
    )
    _refuse_over_inputs(
        [output], [args.input, None if args.reference else _model_file(args.model)], given=args.output
    )
    time_s, q = read_mot(args.input)
    lowpass = args.lowpass or None
    if len(time_s) < min_stretch_rows(lowpass):
        raise ikid.InputError(
            f"{args.input}: {len(time_s)} rows; at least {min_stretch_rows(lowpass)} are needed for "
            + (
                "velocities and accelerations"
                if lowpass is None
                else f"the {lowpass:g} Hz low-pass (--lowpass)"
            )
        )
    rate = 1.0 / float(np.median(np.diff(time_s)))
    model = None
    if not args.reference:
        model = _model_for(args.model, "ikid id --model", ("id",), allow_unchecked=args.allow_unchecked_model)
        if args.sd:
            _check_uncertainty(args.model, model, "ikid id --sd --model")
        if check_rate(model, rate, args.input, args.resample):
            time_s, q = resample(time_s, q, model.frame_rate_hz)
    state = joint_states(q, time_s, lowpass)
    # Stretches between time gaps too short to filter and difference: counted, not written.
    short = ~np.all(np.isfinite(state), axis=1)
    notes = [f"angles low-passed at {lowpass:g} Hz" if lowpass else "angles not low-passed"]
    if short.any():
        notes.append(
            f"{int(short.sum())} rows in stretches between time gaps shorter than "
            f"{min_stretch_rows(lowpass)} rows (too short to low-pass and difference), not written"
        )
    if short.all():
        raise ikid.InputError(f"{args.input}: no frame gave torques: {', '.join(notes)}")
    time_s, state = time_s[~short], state[~short]
    status = sd = None
    if model is None:
        tau = ikid.reference_id(
            state[:, :3],
            state[:, 3:6],
            state[:, 6:],
            shoulder_flexion=math.radians(args.shoulder_deg),
            length_scale=args.length_scale,
            mass_scale=args.mass_scale,
        )
        out_time = time_s
        summary = (
            f"{len(time_s)} frames, exact Newton-Euler (subject ×{args.length_scale:g} length, "
            f"×{args.mass_scale:g} mass)"
        )
        clean = True
    else:
        run = run_model(model, state, time_s, rate_hz=model.frame_rate_hz, source=args.input)
        out_time, tau, summary, status, clean = run.time, run.values, run.summary(), run.status, run.clean
        if args.sd:
            # Only rows with a σ: the first frames' (too few to tell the angles' noise) are counted.
            known = np.all(np.isfinite(run.sd), axis=1)
            out_time, tau, status, sd = out_time[known], tau[known], status[known], run.sd[known]
            if not known.all():
                lacking = int((~known).sum())
                notes.append(
                    f"{lacking} torque rows without a standard deviation (the first frames), not written"
                )
    summary = ", ".join([summary, *notes])
    if len(out_time) == 0:
        raise ikid.InputError(f"{args.input}: no frame gave torques: {summary}")
    output.parent.mkdir(parents=True, exist_ok=True)
    with sto_writer(output, with_status=model is not None, with_sd=args.sd) as write:
        write(out_time, tau, status, sd)
    print(f"{args.input}: {summary} -> {output}")
    if args.strict and not (clean and not short.any()):
        print(f"ikid: --strict: {args.input} has refused, implausible or flagged frames", file=sys.stderr)
        return 3
    return 0
