"""`ikid ik`: markers -> wrist angles (.mot); shares :mod:`ikid.cli.process` with `run`."""

from __future__ import annotations

import argparse

from ikid.cli.options import unchecked_option
from ikid.cli.process import process_files, processing_options


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ik",
        help="markers (.c3d/.trc) -> wrist angles (.mot, degrees)",
        description="Markers -> wrist angles.\n\n  ikid ik trial.c3d -o trial.mot --map lab.toml\n"
        "  ikid ik sessions/ -o results/ --resample",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    processing_options(
        p,
        "angle model, shipped name or file (default wrist-ik: the shipped wrist-ik model whose card rate is "
        "the file's, e.g. wrist-ik-100hz; another rate runs on the fastest one (wrist-ik, 1 kHz), resampled, "
        "outputs at the file's frames)",
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """`ikid ik`: see :func:`ikid.cli.process.process_files`."""
    return process_files(args)
