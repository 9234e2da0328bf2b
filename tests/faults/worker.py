"""A worker process of the fault suite: ``python -m faults.worker CORPUS`` (from ``tests/``).

Reads probe names on stdin and answers each with one JSON line (its problems and time) on
the original stdout; everything else the probe prints (Python, Rust or C) goes to stderr,
which the runner keeps in a log to name a crash."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path


def main() -> None:
    protocol = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # stray prints (and native writes to fd 1) go to stderr
    sys.stdout = sys.stderr
    from faults.corpus import Corpus
    from faults.framework import HARNESS, Verdict
    from faults.suite import api_probes

    corpus = Corpus(Path(sys.argv[1]))
    probes = {p.name: p for p in api_probes(corpus)}
    for line in sys.stdin:
        name = line.strip()
        print(f"--- {name}", file=sys.stderr, flush=True)
        v = Verdict()
        t0 = time.monotonic()
        probe = probes.get(name)
        if probe is None:
            v.add(HARNESS, f"no probe {name!r} in the worker")
        else:
            try:
                probe.fn(v)
            except Exception as e:  # noqa: BLE001 - a harness bug fails the probe, visibly
                import traceback

                traceback.print_exc()
                v.add(HARNESS, f"probe code raised {type(e).__name__}: {e}")
        protocol.write(json.dumps({"problems": v.problems, "seconds": time.monotonic() - t0}) + "\n")
        protocol.flush()


if __name__ == "__main__":
    main()
