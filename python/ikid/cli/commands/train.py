"""`ikid train`: train a model with ikid-training (imported only when run)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import ikid
from ikid.cli.common import TRAINING_HINT, _refuse_over_inputs, _training_package
from ikid.cli.options import POSITIVE, POSITIVE_INT, _widths


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train a model on a lab's trials (or a config); needs ikid-training",
        description="Train a model: a lab's trials (marker files + same-stem .mot angles [+ .sto torques])\n"
        "through the same pipeline as the shipped models (80/10/10 split per trial, noise and\n"
        "occlusion augmentation, early stopping), exported as .safetensors + .onnx.\n"
        "Needs the training pipeline (torch), a distribution of its own: pip install ./training\n"
        "(from an ikid source checkout).\n\n"
        "  ikid train --data lab/ --map lab.toml --task ik -o models/lab-ik.safetensors\n"
        "  ikid train --data lab/ --task chain --minutes 10 -o models/lab-chain.safetensors\n"
        "  ikid train --config wrist-ik -o out/models    # a shipped config (simulated data)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--data", default=None, metavar="DIR", help="a lab's trials: .c3d/.trc with same-stem .mot (and .sto)"
    )
    p.add_argument("--map", metavar="TOML", help="marker map for the trials (see map-template)")
    p.add_argument(
        "--task",
        choices=sorted(BASE_CONFIG),
        default=None,
        help="ik: angles (default); chain: markers -> torques; id: joint states -> torques",
    )
    p.add_argument("--config", default=None, help="config name or TOML (default: the shipped one for --task)")
    p.add_argument("--rate", type=POSITIVE, default=None, help="resample every trial to this rate (Hz) first")
    p.add_argument("--minutes", type=POSITIVE, default=None, help="training time budget")
    p.add_argument(
        "--window", type=POSITIVE_INT, default=None, help="frames per window (default: the config's)"
    )
    p.add_argument(
        "--hidden", type=_widths, default=None, help="hidden widths, e.g. 128,128 (default: the config's)"
    )
    p.add_argument("--no-onnx", action="store_true", help="skip the ONNX copy")
    p.add_argument("-o", "--output", required=True, help="model file (.safetensors) or output folder")
    p.set_defaults(func=run)


#: The shipped config each task starts from (architecture, window, augmentation, budget).
BASE_CONFIG = {"ik": "wrist-ik", "chain": "wrist-chain", "id": "wrist-id"}


def _config_path(name: str) -> Path:
    """A shipped config's name (``ikid_training/configs``) or a TOML path, by the rule of
    :func:`ikid.load`: a name with no path separator and no ``.toml`` suffix is a shipped
    config, even if a file or folder of that name is in the working directory."""
    shipped_dir = Path(_training_package("ikid train").CONFIG_DIR)
    if ikid.is_model_name(name) and not name.endswith(".toml"):
        shipped = shipped_dir / f"{name}.toml"
        if not shipped.is_file():
            known = sorted(q.stem for q in shipped_dir.glob("*.toml"))
            raise ikid.InputError(
                f"no shipped config {name!r} (shipped: {', '.join(known)}); a config file is given by a "
                "path (with a folder or the .toml suffix)"
            )
        return shipped
    p = Path(name)
    if not p.is_file():
        raise ikid.InputError(f"{p}: no such config file")
    return p


def _training():
    _training_package("ikid train")
    try:
        from ikid_training import train
    except ImportError as e:  # installed without its dependencies (torch)
        raise ikid.InputError(
            f"ikid train needs torch, a dependency of ikid-training ({e}); install it with {TRAINING_HINT}"
        ) from None
    return train


def run(args: argparse.Namespace) -> int:
    train = _training()
    if args.data is None and args.config is None:
        raise ikid.InputError("give --data DIR (a lab's trials) or --config NAME|FILE (a training config)")
    try:
        cfg = train.load_config(_config_path(args.config or BASE_CONFIG[args.task or "ik"]))
    except ValueError as e:  # a config problem, named by load_config
        raise ikid.InputError(str(e)) from None
    if args.task is not None and cfg["model"]["task"] != args.task:
        raise ikid.InputError(
            f"--task {args.task} but config {args.config!r} trains task {cfg['model']['task']!r}; "
            "drop one of them"
        )
    out = Path(args.output)
    if out.suffix == ".safetensors":
        cfg["model"]["name"], out_dir = out.stem, out.parent
    else:
        out_dir = out
    if args.data is not None:
        task = cfg["model"]["task"]
        cfg["data"] = {"lab": str(Path(args.data).resolve())}
        if args.map:
            cfg["data"]["map"] = str(Path(args.map).resolve())
        if args.rate is not None:
            cfg["data"]["rate_hz"] = args.rate
        if out.suffix != ".safetensors" and args.config is None:
            cfg["model"]["name"] = f"lab-{task}"
    if args.minutes is not None:
        cfg["train"]["max_minutes"] = args.minutes
    if args.window is not None:
        cfg["model"]["window"] = args.window
    if args.hidden is not None:
        try:
            cfg["model"]["hidden"] = [int(w) for w in args.hidden.split(",")]
        except ValueError:
            raise ikid.InputError(f"--hidden {args.hidden!r}: expected widths like 128,128") from None
    name = cfg["model"]["name"]
    lab = Path(args.data) if args.data is not None else None
    _refuse_over_inputs(
        [out_dir / f"{name}.safetensors", out_dir / f"{name}.onnx"],
        [
            _config_path(args.config) if args.config else None,
            args.map,
            *(sorted(lab.iterdir()) if lab is not None and lab.is_dir() else []),
        ],
        given=args.output,
    )
    train.run(cfg, out_dir, progress=sys.stderr.isatty(), onnx=not args.no_onnx)
    return 0
