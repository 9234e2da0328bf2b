"""``python -m ikid_training.export --restamp FILE...`` (or ``python -m ikid_training.restamp``):
rewrite old model files through the one writer, adding what their cards lack — the tensor
checksum (files written before checksums are refused by every loader without an opt-in), the
envelope, and with ``--change`` the envelope's ``window_change`` rebuilt from the training data.

It sits above both ``export`` (the writer) and ``train`` (the training data), which import
each other's names only one way: ``train`` imports ``export``; ``export`` runs this module
only as its ``__main__``.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file

from ikid import _native
from ikid_training import CONFIG_DIR
from ikid_training.export import envelope_from_scaling, restamp
from ikid_training.train import load_config, training_window_change


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m ikid_training.export --restamp FILE...``: give model files written before
    envelopes and checksums both, the envelope from their min-max scaling where it allows
    (:func:`envelope_from_scaling`; otherwise only the checksum)."""
    p = argparse.ArgumentParser(prog="python -m ikid_training.export")
    p.add_argument("--restamp", nargs="+", required=True, metavar="FILE")
    p.add_argument(
        "--change",
        action="store_true",
        help="also give the envelope its window_change, from the model's training data rebuilt from its "
        "shipped config (ikid_training/configs/<name>.toml, the same seeds and noise as training)",
    )
    args = p.parse_args(argv)
    for f in args.restamp:
        card = dict(_native.Model.load(Path(f), allow_unchecked=True).card)
        try:
            envelope = card.get("envelope") or envelope_from_scaling(card, load_file(f))
        except ValueError as e:
            print(f"{f}: no envelope ({e}); checksum only")
            envelope = None
        if args.change and envelope is not None:
            change = training_window_change(load_config(CONFIG_DIR / f"{card['name']}.toml"))
            envelope = {**envelope, "window_change": change.tolist()}
            print(f"{f}: window_change {np.round(change, 4).tolist()}")
        model = restamp(f, envelope)
        print(f"{f}: envelope {'yes' if model.card.get('envelope') else 'no'}, checksum {model.has_checksum}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
