"""Summarise a cargo-mutants run (`make mutants`): per file, then the closing line.

Reads `<out>/outcomes.json`. A mutant is *viable* when it compiled (cargo-mutants' "unviable"
ones did not); it is *caught* when a test failed or it hung past the timeout (a hang is a
failing test too). Exits 1 when the score (caught / viable) is below `--min-score`, so a core
change that leaves mutants alive fails the check, and lists the survivors to look at.

With `--record`, the closing line is also kept beside the outcomes (`<out>/last-run.json`,
with the commit it ran at, the date and what was mutated); `--status` prints that record and
whether `crates/ikid` changed since (what `make check` shows on every run, so a score that
drops, or is not measured after a change to the core, does not go unnoticed; a full
`make mutants` takes hours, so it is not run by `make check` itself).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

#: The record `--record` writes and `--status` reads, in the output folder.
RECORD = "last-run.json"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="cargo-mutants' output folder (holding outcomes.json)")
    parser.add_argument("--min-score", type=float, default=0.95)
    parser.add_argument(
        "--record", metavar="WHAT", help="keep the closing line, the commit and WHAT was mutated"
    )
    parser.add_argument(
        "--status", action="store_true", help="print the last recorded run and whether it is stale"
    )
    args = parser.parse_args(argv)
    if args.status:
        print(status(args.out))
        return 0
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
    line = f"mutants: viable={viable} caught={total['caught']} missed={total['missed']} score={score:.2f}"
    print(line)
    if args.record is not None:
        record = {
            "line": line,
            "per_file": {f: dict(c) for f, c in sorted(per_file.items())},
            "commit": _git("rev-parse", "HEAD"),
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "what": args.record,
        }
        (args.out / RECORD).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return 0 if viable and score >= args.min_score else 1


def _git(*args: str) -> str:
    done = subprocess.run(["git", *args], capture_output=True, text=True, check=False)
    return done.stdout.strip()


def status(out: Path) -> str:
    """The last recorded run's closing line, per file, its commit and date, and whether the
    core (crates/ikid) changed since that commit."""
    path = out / RECORD
    if not path.is_file():
        return f"mutants: no recorded run ({path} missing): run `make mutants` after changing crates/ikid"
    try:
        r = json.loads(path.read_text(encoding="utf-8"))
        line, commit, date, what = r["line"], r["commit"], r["date"], r["what"]
    except (ValueError, KeyError, TypeError) as e:
        return f"mutants: {path} is not a record of a run ({e}): run `make mutants` again"
    files = ", ".join(
        f"{_short(f)} {c.get('caught', 0)}/{c.get('caught', 0) + c.get('missed', 0)}"
        for f, c in r.get("per_file", {}).items()
    )
    head = f"{line} (last `make mutants`: {what}, at {commit[:10]}, {date}; per file caught/viable: {files})"
    changed = _git("log", "--oneline", f"{commit}..HEAD", "--", "crates/ikid") if commit else ""
    if not commit or _git("cat-file", "-t", commit) != "commit":
        return head + "\nmutants: STALE: its commit is not in this repository's history"
    if changed:
        n = len(changed.splitlines())
        return head + f"\nmutants: STALE: crates/ikid changed in {n} commit(s) since; run `make mutants`"
    return head + "\nmutants: current (crates/ikid unchanged since)"


def _short(file: str) -> str:
    """A mutated file's name under the crate's src/, without .rs (`tracker/mod`, `gaps`): the
    stem alone would name calibration/mod.rs and tracker/mod.rs alike."""
    return file.split("src/", 1)[-1].removesuffix(".rs")


if __name__ == "__main__":
    sys.exit(main())
