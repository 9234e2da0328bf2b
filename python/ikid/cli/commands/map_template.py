"""`ikid map-template`: a marker map (TOML) to fill in, listing a file's labels."""

from __future__ import annotations

import argparse

from ikid.cli.common import _refuse_over_inputs, _stdout_fd


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("map-template", help="print a marker map (TOML) to fill in, listing a file's labels")
    p.add_argument("input", nargs="?", help="a .c3d/.trc whose labels to list")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ikid.io import MarkerMap, read_markers

    text = MarkerMap.identity().to_toml()
    if args.input:
        _refuse_over_inputs([_stdout_fd()], [args.input])
        labels = read_markers(args.input).labels
        text = f"# labels in {args.input}: {', '.join(labels)}\n" + text
    print(text, end="")
    return 0
