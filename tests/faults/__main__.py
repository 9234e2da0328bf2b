"""``python -m faults`` (from ``tests/``; ``make faults``): build the corpus, run every probe,
print one line per failing probe and the summary line last; exit 1 unless every probe passed.

Options: ``--keep`` keeps the corpus folder (printed), ``-k TEXT`` runs only the probes whose
name contains TEXT, ``--list`` prints the probe names."""

from __future__ import annotations

import argparse
import hashlib
import shutil
import sys
import tempfile
import time
import traceback
from pathlib import Path


def digest(folder: Path) -> dict[str, str]:
    return {
        str(p): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.is_symlink()
    }


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m faults")
    parser.add_argument("--keep", action="store_true", help="keep the corpus folder")
    parser.add_argument("-k", dest="select", default=None, help="only probes whose name contains this")
    parser.add_argument("--list", action="store_true", help="list the probes and stop")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes and CLI threads, each")
    args = parser.parse_args()

    from faults import framework
    from faults.framework import HARNESS, Outcome, flush_exit, run_all, summary

    t0 = time.monotonic()
    root = Path(tempfile.mkdtemp(prefix="ikid-faults-")) / "corpus"
    outcomes: list[Outcome] = []
    try:
        from faults.corpus import build
        from faults.suite import api_probes, cli_probes

        corpus = build(root)
        api, cli = api_probes(corpus), cli_probes(corpus)
        if args.select:
            api = [p for p in api if args.select in p.name]
            cli = [p for p in cli if args.select in p.name]
        if args.list:
            for p in [*api, *cli]:
                print(p.name)
            flush_exit(0)
        names = [p.name for p in [*api, *cli]]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise RuntimeError(f"probe names used twice: {dup[:5]}")
        print(
            f"faults: {len(api)} in-process probes, {len(cli)} command probes; corpus {root}"
            f" (built in {time.monotonic() - t0:.1f} s)",
            flush=True,
        )
        before = digest(corpus.base)
        outcomes = run_all(root, api, cli, api_workers=args.jobs, cli_threads=args.jobs)
        changed = sorted(p for p, h in digest(corpus.base).items() if before.get(p) != h)
        if changed:
            outcomes.append(
                Outcome("corpus/inputs-unchanged", [(framework.PARTIAL, f"inputs changed: {changed[:3]}")], 0)
            )
            print(f"FAIL corpus/inputs-unchanged: partial_write: inputs changed: {changed[:3]}", flush=True)
    except BaseException as e:  # noqa: BLE001 - the summary line is printed whatever happened
        traceback.print_exc()
        outcomes.append(Outcome("suite/harness", [(HARNESS, f"{type(e).__name__}: {e}")], 0))
        print(f"FAIL suite/harness: {type(e).__name__}: {e}", flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(root.parent, ignore_errors=True)
    slow = sorted(outcomes, key=lambda o: -o.seconds)[:5]
    print(
        f"faults: {time.monotonic() - t0:.0f} s; slowest: "
        + ", ".join(f"{o.name} {o.seconds:.1f} s" for o in slow)
        + (f"; corpus kept in {root}" if args.keep else ""),
        flush=True,
    )
    line, ok = summary(outcomes)
    print(line, flush=True)
    flush_exit(0 if ok and outcomes else 1)


if __name__ == "__main__":
    sys.exit(main())
