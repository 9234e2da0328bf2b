"""Grid or random search over training configs, driven by a TOML file.

    python -m ikid_training.search training/ikid_training/configs/search-ik.toml --out out/search

The file names a base config and, under ``[search]``, lists of values for dotted keys of it
(``"model.window" = [5, 25, 50]``). ``mode = "grid"`` tries every combination, ``mode =
"random"`` draws ``trials`` of them (seeded by ``seed``). Each trial trains under its own
budget and is ranked by its best validation loss; the test metrics are logged beside it but
never used to choose. Results: ``<out>/<name>/results.jsonl`` and ``results.md``.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import json
import random
import sys
from pathlib import Path
from typing import Any

from ikid_training.train import load_config, run

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


def combinations(space: dict[str, list[Any]], mode: str, trials: int, seed: int) -> list[dict[str, Any]]:
    keys = list(space)
    grid = [dict(zip(keys, values, strict=True)) for values in itertools.product(*(space[k] for k in keys))]
    if mode == "grid":
        return grid
    if mode == "random":
        return random.Random(seed).sample(grid, min(trials, len(grid)))
    raise ValueError(f'[search] mode {mode!r}: use "grid" or "random"')


def with_overrides(cfg: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    cfg = copy.deepcopy(cfg)
    for dotted, value in overrides.items():
        table, _, key = dotted.partition(".")
        if table not in cfg or not key:
            raise ValueError(
                f"search key {dotted!r} must be <table>.<key> of the base config (tables: {list(cfg)})"
            )
        cfg[table][key] = value
    return cfg


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("search", type=Path)
    parser.add_argument("--out", type=Path, default=Path("out/search"))
    args = parser.parse_args()
    with open(args.search, "rb") as f:
        spec = tomllib.load(f)
    base = load_config(args.search.parent / spec["base"])
    s = spec["search"]
    space = {k: v for k, v in s.items() if k not in ("mode", "trials", "seed", "minutes")}
    out = args.out / args.search.stem
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for i, overrides in enumerate(
        combinations(space, s.get("mode", "grid"), s.get("trials", 8), s.get("seed", 0))
    ):
        cfg = with_overrides(base, overrides)
        cfg["model"]["name"] = f"{base['model']['name']}-{i:02d}"
        if "minutes" in s:
            cfg["train"]["max_minutes"] = s["minutes"]
        model, _ = run(cfg, out, progress=False, onnx=False)
        prov = model.card["provenance"]
        row = {
            "trial": i,
            **overrides,
            "best_val_loss": prov["best_val_loss_scaled"],
            "epochs": prov["epochs"],
            **{k: v["mse"] for k, v in model.card["metrics"].items()},
        }
        rows.append(row)
        with open(out / "results.jsonl", "a") as f:
            f.write(json.dumps(row) + "\n")
    rows.sort(key=lambda r: r["best_val_loss"])
    header = list(rows[0])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += [
        "| " + " | ".join(f"{r[h]:.3g}" if isinstance(r[h], float) else str(r[h]) for h in header) + " |"
        for r in rows
    ]
    (out / "results.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
