"""Summarise a cargo-mutants run (`make mutants`): per file, then the closing line.

Reads `<out>/outcomes.json`. A mutant is *viable* when it compiled (cargo-mutants' "unviable"
ones did not); it is *caught* when a test failed or it hung past the timeout (a hang is a
failing test too). Exits 1 when the score (caught / viable) is below `--min-score`, so a core
change that leaves mutants alive fails the check, and lists the survivors to look at.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="cargo-mutants' output folder (holding outcomes.json)")
    parser.add_argument("--min-score", type=float, default=0.95)
    args = parser.parse_args(argv)
    data = json.loads((args.out / "outcomes.json").read_text(encoding="utf-8"))
    per_file: dict[str, Counter[str]] = {}
    missed: list[str] = []
    for outcome in data["outcomes"]:
        mutant = outcome["scenario"]
        if not isinstance(mutant, dict) or "Mutant" not in mutant:
            continue  # the unmutated baseline
        m = mutant["Mutant"]
        kind = {
            "CaughtMutant": "caught",
            "Timeout": "caught",
            "MissedMutant": "missed",
            "Unviable": "unviable",
        }.get(outcome["summary"])
        if kind is None:
            print(f"mutants: unexpected outcome {outcome['summary']!r} for {m['name']}", file=sys.stderr)
            return 1
        per_file.setdefault(m["file"], Counter())[kind] += 1
        if kind == "missed":
            missed.append(m["name"])
    total = Counter()
    print(f"{'file':40} {'viable':>7} {'caught':>7} {'missed':>7} {'unviable':>9}")
    for file, c in sorted(per_file.items()):
        total += c
        print(f"{file:40} {c['caught'] + c['missed']:7} {c['caught']:7} {c['missed']:7} {c['unviable']:9}")
    for name in missed:
        print(f"missed: {name}")
    viable = total["caught"] + total["missed"]
    score = total["caught"] / viable if viable else 0.0
    print(f"mutants: viable={viable} caught={total['caught']} missed={total['missed']} score={score:.2f}")
    return 0 if viable and score >= args.min_score else 1


if __name__ == "__main__":
    sys.exit(main())
