"""The ``ikid`` command line.

Examples::

    ikid ik trial.c3d -o trial.mot --map lab.toml          # markers -> wrist angles (OpenSim .mot)
    ikid run trial.trc -o out/trial                          # -> out/trial.mot + out/trial.sto (torques)
    ikid ik sessions/ -o results/ --map lab.toml --resample  # a folder, in parallel, with a summary
    ikid map-template trial.c3d > lab.toml                   # start a marker map from a file's labels
    ikid calibrate --static st.c3d --movement ra_wr_e_f=fe.c3d --movement ra_wr_s_p=ps.c3d -o s01.json
    ikid ik trial.c3d -o trial.mot --calibration s01.json    # the subject's own marker placement
    ikid id trial.mot -o trial.sto                           # angles -> torques (wrist-id; or --reference)
    ikid stream --rate 1000 < frames.csv                     # one frame per line in, one result per line out
    ikid stream --rate 100 --udp 9870 --count 10000          # frames as UDP datagrams on 127.0.0.1
    ikid train --data lab/ --map lab.toml --task ik -o models/lab-ik.safetensors
    ikid report --model models/lab-ik.safetensors --data lab_test/ --map lab.toml
    ikid bench --model wrist-ik                              # push latency and batch throughput here
    ikid simulate --protocol thesis --shoulder-deg 45 -o data/thesis_s45
    ikid simulate --protocol random --seed 3 --duration 60 --noise uniform:0.01 -o data/r3
    ikid dataset -o data            # thesis-sized set + the richer random set, in parallel
    ikid demo                       # a fresh trial through the shipped models, errors + latency
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

import ikid
from ikid.cli import batch
from ikid.cli.common import _message
from ikid.io._common import UndeterminedWarning

#: The commands, in the order ``ikid --help`` lists them: name -> module of
#: :mod:`ikid.cli.commands`, each with ``add_parser(sub)`` (its options, ``func=run``) and
#: ``run(args) -> int`` (its exit status). A new command is a module and a line here.
REGISTRY = {
    "simulate": "simulate",
    "dataset": "dataset",
    "ik": "ik",
    "run": "run",
    "track": "track",
    "calibrate": "calibrate",
    "map-template": "map_template",
    "id": "id",
    "stream": "stream",
    "train": "train",
    "report": "report",
    "bench": "bench",
    "demo": "demo",
}


def build_parser() -> argparse.ArgumentParser:
    """The ``ikid`` parser: one subcommand per :data:`REGISTRY` entry."""
    parser = argparse.ArgumentParser(
        prog="ikid", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"ikid {ikid.__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in REGISTRY.values():
        importlib.import_module(f"ikid.cli.commands.{module}").add_parser(sub)
    return parser


#: Warnings printed by this process (a model loaded twice, to check it and to run it, warns once).
_WARNED: set[str] = set()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as the command line prints it: one line, no source location, each once."""
    text = str(message)
    if text not in _WARNED:
        _WARNED.add(text)
        print(f"ikid: warning: {text}", file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    """``ikid ARGS``: the command's exit status. What a user can act on (a bad file, option or
    model; a failed write) is one ``ikid: error:`` line naming it, exit 2; anything else is a bug
    and keeps its traceback. SIGINT (Ctrl-C) and SIGTERM (kill) end every command the same way:
    :class:`ikid.cli.batch.Stopped` raised where the command is, files under way removed on the
    way out (atomic writes), a line saying so, exit 128 + the signal's number; a batch lists what
    it did first (:mod:`ikid.cli.batch`)."""
    parser = build_parser()
    if argv is None:
        argv = sys.argv[1:]
    with batch.stop_on_signals(), warnings.catch_warnings():
        warnings.showwarning = _show_warning
        # The commands leave what the markers do not determine out of their files themselves.
        warnings.filterwarnings("ignore", category=UndeterminedWarning)
        try:
            args = parser.parse_args(argv)
            args.argv = list(argv)
            if getattr(args, "output", None) == "-":
                # Read elsewhere as standard output: ikid writes whole files atomically instead.
                raise ikid.ArgumentError(
                    "-o -: ikid writes files (written whole or not at all, never part of one), not "
                    "standard output; name a file or a folder"
                )
            return args.func(args)
        except (ikid.IkidError, OSError) as e:
            print(f"ikid: error: {_message(e)}", file=sys.stderr)
            return 2
        except batch.Stopped as stop:
            print(
                f"ikid: stopped by {stop.name}; the outputs under way were not written (any old ones are "
                "as they were)",
                file=sys.stderr,
            )
            return stop.exit_status
