"""`ikid run`: markers -> angles (.mot) and torques (.sto); shares :mod:`ikid.cli.process` with
`ik`."""

from __future__ import annotations

import argparse

from ikid.cli.options import unchecked_option
from ikid.cli.process import process_files, processing_options


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="markers -> wrist angles (.mot) and torques (.sto)",
        description="Markers -> angles and torques.\n\n"
        "  ikid run trial.c3d -o out/trial   # out/trial.mot, out/trial.sto",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    processing_options(
        p, "angle model (default wrist-ik: the shipped wrist-ik model for the file's rate, as in `ikid ik`)"
    )
    p.add_argument(
        "--torque-model", default="wrist-chain", help="markers -> torques model (default wrist-chain)"
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """`ikid run`: see :func:`ikid.cli.process.process_files`."""
    return process_files(args)
