"""`ikid id`: angles (.mot) -> wrist torques (.sto)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

import ikid
from ikid.cli.common import _is_folder, _model_file, _model_for, _named, _refuse_over_inputs, _stem
from ikid.cli.options import SHOULDER_DEG, SUBJECT_LENGTH, SUBJECT_MASS, unchecked_option


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "id",
        help="angles (.mot) -> wrist torques (.sto)",
        description="Angles -> torques (velocities, accelerations: central differences).\n\n"
        "  ikid id trial.mot -o trial.sto                 # the wrist-id network\n"
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
        "--strict",
        action="store_true",
        help="exit 3 if any frame was refused or any torque flagged (the ikid_status column)",
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Angles (.mot) -> torques (.sto): the wrist-id network over (q, q̇, q̈), or the exact
    Newton-Euler reference for a subject (``--reference``). Velocities and accelerations are
    central differences of the angles (a file is offline: no lag)."""
    from ikid.io import read_mot, resample, write_sto
    from ikid.pipeline import check_rate, run_model

    output = (
        _named(_stem(args.output, Path(args.input).stem, create=False), ".sto")
        if _is_folder(args.output)
        else Path(args.output)
    )
    _refuse_over_inputs(
        [output], [args.input, None if args.reference else _model_file(args.model)], given=args.output
    )
    time_s, q = read_mot(args.input)
    if len(time_s) < 3:
        raise ikid.InputError(
            f"{args.input}: {len(time_s)} rows; at least 3 are needed for velocities and accelerations"
        )
    rate = 1.0 / float(np.median(np.diff(time_s)))
    if args.reference:
        qd = np.gradient(q, time_s, axis=0)
        tau = ikid.reference_id(
            q,
            qd,
            np.gradient(qd, time_s, axis=0),
            shoulder_flexion=math.radians(args.shoulder_deg),
            length_scale=args.length_scale,
            mass_scale=args.mass_scale,
        )
        out_time, summary = (
            time_s,
            f"{len(time_s)} frames, exact Newton-Euler (subject ×{args.length_scale:g} length, "
            f"×{args.mass_scale:g} mass)",
        )
    else:
        model = _model_for(args.model, "ikid id --model", ("id",), allow_unchecked=args.allow_unchecked_model)
        if check_rate(model, rate, args.input, args.resample):
            time_s, q = resample(time_s, q, model.frame_rate_hz)
        qd = np.gradient(q, time_s, axis=0)
        run = run_model(
            model,
            np.concatenate([q, qd, np.gradient(qd, time_s, axis=0)], axis=1),
            time_s,
            rate_hz=model.frame_rate_hz,
            source=args.input,
        )
        if len(run.time) == 0:
            raise ikid.InputError(f"{args.input}: no frame gave torques: {run.summary()}")
        out_time, tau, summary, status = run.time, run.values, run.summary(), run.status
    output.parent.mkdir(parents=True, exist_ok=True)
    path = write_sto(
        output,
        out_time,
        tau,
        status=None if args.reference else status,
    )
    print(f"{args.input}: {summary} -> {path}")
    if args.strict and not args.reference and not run.clean:
        print(f"ikid: --strict: {args.input} has refused, implausible or flagged frames", file=sys.stderr)
        return 3
    return 0
