"""`ikid map-template`: a marker map (TOML) to fill in, listing a file's labels; a shipped set's
map (Plug-in Gait) when the file's labels are that set's."""

from __future__ import annotations

import argparse
import dataclasses

from ikid.cli.common import _refuse_over_inputs, _stdout_fd


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "map-template",
        help="print a marker map (TOML) to fill in, listing a file's labels (Plug-in Gait's recognised)",
        description="Print a marker map to fill in. With a file whose labels are Plug-in Gait's "
        "(WRA, WRB, ELB, "
        "FIN of an arm), the map of that set is printed filled in (docs/markersets.md).",
    )
    p.add_argument("input", nargs="?", help="a .c3d/.trc whose labels to list")
    p.add_argument(
        "--side",
        choices=["right", "left"],
        help="the arm the map is for (default right; for a file with a shipped set's labels of both "
        "arms, the one to map: right if present)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ikid.io import MarkerMap, read_markers

    text = dataclasses.replace(MarkerMap.identity(), side=args.side or "right").to_toml()
    if args.input:
        _refuse_over_inputs([_stdout_fd()], [args.input])
        data = read_markers(args.input)
        labels = data.labels
        known = MarkerMap.recognise(labels, args.side)
        head = f"# labels in {args.input}: {', '.join(labels)}\n"
        if known is not None:
            other = "left" if known.side == "right" else "right"
            head += (
                f"# Plug-in Gait labels: the {known.side} arm as ikid's one-hand-marker set "
                "(docs/markersets.md); "
                f"the {other} arm: --side {other}\n"
            )
            text = known.to_toml()
        elif args.side and MarkerMap.recognise(labels) is not None:
            raise SystemExit(
                f"ikid: error: --side: {args.input} has no Plug-in Gait labels of the {args.side} arm"
            )
        up, up_from = data.lab_up()
        head += f"# up: {up} ({up_from})\n"
        text = head + text
    print(text, end="")
    return 0
