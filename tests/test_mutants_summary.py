"""`make mutants`' summary and the record `make check` prints (issue #31, item 9): the score of
the last run, its commit, and whether crates/ikid changed since (stale)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import mutants_summary  # noqa: E402


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], capture_output=True, text=True, check=True, cwd=ROOT).stdout.strip()


def _outcomes(tmp_path: Path) -> Path:
    def mutant(file: str, name: str, summary: str) -> dict:
        return {"scenario": {"Mutant": {"file": file, "name": name}}, "summary": summary}

    outcomes = [
        {"scenario": "Baseline", "summary": "Success"},
        mutant("crates/ikid/src/gaps.rs", "a", "CaughtMutant"),
        mutant("crates/ikid/src/gaps.rs", "b", "CaughtMutant"),
        mutant("crates/ikid/src/gaps.rs", "c", "MissedMutant"),
        mutant("crates/ikid/src/stream.rs", "d", "Timeout"),
        mutant("crates/ikid/src/stream.rs", "e", "Unviable"),
    ]
    (tmp_path / "outcomes.json").write_text(json.dumps({"outcomes": outcomes}))
    return tmp_path


def test_a_run_is_scored_recorded_and_shown_current_then_stale(tmp_path, capsys, monkeypatch):
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    monkeypatch.chdir(ROOT)
    out = _outcomes(tmp_path)
    assert "no recorded run" in mutants_summary.status(out)
    # 3 caught (a timeout is a failing test) of 4 viable: 0.75, below 0.95, so exit 1.
    assert mutants_summary.main([str(out), "--record", "gaps stream, shard 0/8"]) == 1
    assert "mutants: viable=4 caught=3 missed=1 score=0.75" in capsys.readouterr().out
    shown = mutants_summary.status(out)
    assert "score=0.75" in shown and "gaps stream, shard 0/8" in shown and "gaps 2/3" in shown
    assert _git("rev-parse", "HEAD")[:10] in shown and "current" in shown
    # Recorded at a commit before the last change to crates/ikid: stale, and says so.
    before = _git("log", "-2", "--format=%H", "--", "crates/ikid").splitlines()[-1]
    record = json.loads((out / mutants_summary.RECORD).read_text())
    (out / mutants_summary.RECORD).write_text(json.dumps(record | {"commit": before}))
    assert "STALE: crates/ikid changed in" in mutants_summary.status(out)


def test_files_of_the_same_name_in_two_modules_are_told_apart(tmp_path, monkeypatch):
    # calibration/mod.rs and tracker/mod.rs: the status line names each by its path under src/.
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    monkeypatch.chdir(ROOT)
    outcomes = [
        {"scenario": {"Mutant": {"file": f"crates/ikid/src/{f}", "name": n}}, "summary": s}
        for f, n, s in [
            ("calibration/mod.rs", "a", "CaughtMutant"),
            ("calibration/mod.rs", "b", "MissedMutant"),
            ("tracker/mod.rs", "c", "CaughtMutant"),
        ]
    ]
    (tmp_path / "outcomes.json").write_text(json.dumps({"outcomes": outcomes}))
    mutants_summary.main([str(tmp_path), "--record", "calibration/* tracker/*"])
    shown = mutants_summary.status(tmp_path)
    assert "calibration/mod 1/2" in shown and "tracker/mod 1/1" in shown, shown
