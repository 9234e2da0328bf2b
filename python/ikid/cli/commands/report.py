"""`ikid report`: score a model on a lab's trials, or the shipped models' full report
(ikid-training, imported only when run)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import ikid
from ikid.cli.common import (
    TRAINING_HINT,
    _is_folder,
    _model_file,
    _model_for,
    _named,
    _refuse_over_inputs,
    _stem,
    _training_package,
)
from ikid.cli.options import unchecked_option
from ikid.io._atomic import atomic_outputs, write_text_atomic


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="score a model on a lab's trials (or the full report of the shipped models)",
        description="Score a model on trials with known angles (or torques): MSE and RMSE per DoF on the\n"
        "last 10 % of each trial and on all frames, clean and with 1 % / 5 % added noise,\n"
        "beside the classical per-frame solution on the same frames.\n\n"
        "  ikid report --model models/lab-ik.safetensors --data lab_test/ --map lab.toml -o lab.md\n"
        "  ikid report -o docs        # the shipped models' report (needs ikid-training,\n"
        "                             # pip install ./training from a source checkout)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--model", default="wrist-ik")
    p.add_argument(
        "--data", default=None, metavar="DIR", help="trials: .c3d/.trc with same-stem .mot (and .sto)"
    )
    p.add_argument("--map", metavar="TOML")
    p.add_argument("--resample", action="store_true", help="resample the trials to the model's rate")
    p.add_argument("--clean-only", action="store_true", help="no added noise levels")
    p.add_argument(
        "-o",
        "--output",
        default=None,
        help="Markdown file (+ .json beside it), or a folder (FOLDER/<model name>.md); for the full "
        "report a folder",
    )
    unchecked_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.data is None:
        _training_package("ikid report without --data (the shipped models' full report)")
        try:
            from ikid_training import report
        except ImportError as e:  # installed without its dependencies (matplotlib)
            raise ikid.InputError(
                f"the full report needs matplotlib, a dependency of ikid-training ({e}); install it "
                f"with {TRAINING_HINT}"
            ) from None
        report.main(["--out", args.output or "docs"])
        return 0
    from ikid import recordings as D
    from ikid.evaluate import evaluate_recordings, markdown

    model = _model_for(
        args.model, "ikid report --model", ("ik", "chain", "id"), allow_unchecked=args.allow_unchecked_model
    )
    out = None
    if args.output:
        out = (
            _named(_stem(args.output, model.name, (".md",), create=False), ".md")
            if _is_folder(args.output)
            else Path(args.output)
        )
        data_files = sorted(Path(args.data).iterdir()) if Path(args.data).is_dir() else []
        _refuse_over_inputs(
            [out, out.with_suffix(".json")],
            [_model_file(args.model), args.map, *data_files],
            given=args.output,
        )
    recs = D.load_lab_recordings(args.data, args.map, model.frame_rate_hz if args.resample else None)
    rates = {r.meta["rate_hz"] for r in recs}
    from ikid.pipeline import check_rate, family_members, same_rate

    if len(rates) == 1 and not args.resample:
        # A family's name (wrist-ik) is its member at the trials' rate, as for `ikid ik`.
        rate = next(iter(rates))
        member = [m for m in family_members(args.model) if same_rate(rate, m.frame_rate_hz)]
        if member and not same_rate(rate, model.frame_rate_hz):
            model = _model_for(
                member[0].name,
                "ikid report --model",
                ("ik", "chain", "id"),
                allow_unchecked=args.allow_unchecked_model,
            )

    for rate in rates:
        check_rate(model, rate, str(args.data), allow_resample=False)
    # Each trial needs what the model is scored against (a torque model: its .sto): a trial
    # without it would make every figure NaN, the table a page of "nan".
    lacking = [
        f"{r.name} ({int((~np.isfinite(t).all(axis=1)).sum())} of {len(t)} rows)"
        for r in recs
        if not np.isfinite(t := D.target(r, model.task)).all()
    ]
    if lacking:
        what = "torques (a same-stem .sto)" if model.task in ("chain", "id") else "angles (a same-stem .mot)"
        raise ikid.InputError(
            f"{args.data}: model {model.name!r} is scored against each trial's {what}; without them: "
            f"{', '.join(lacking[:5])}{' ...' if len(lacking) > 5 else ''}: give those trials theirs, "
            "or leave them out of --data"
        )
    levels = {"clean": 0.0} if args.clean_only else None
    result = evaluate_recordings(model, recs, levels)
    text = f"# ikid report: `{model.name}` on {args.data}\n\n" + markdown(result)
    print(text, end="")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_outputs():  # the report and its numbers replace the old pair together
            write_text_atomic(out, text)
            write_text_atomic(out.with_suffix(".json"), json.dumps(result, indent=1))
        print(f"-> {out}, {out.with_suffix('.json')}")
    return 0
