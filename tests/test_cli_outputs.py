"""No command writes over one of its inputs (issue #31 item 1): every writing command refuses an
output that is one of its inputs — the same path, a symbolic link to it or a hard link to it
(the same file after resolving links) — with exit 2 and a message naming both, before it reads
or writes anything; the input stays byte for byte as it was and nothing new appears."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ikid
import ikid.io

IKID = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    """A short simulated trial (t.trc, t.mot, t.sto), a map, a calibration and a lab folder."""
    d = tmp_path_factory.mktemp("over-inputs")
    ikid.simulate("random", seed=31, duration=0.3).save(d / "t")
    (d / "map.toml").write_text(ikid.io.MarkerMap.identity().to_toml())
    cal = ikid.Calibration.from_neutral(ikid.forward_markers(np.zeros((10, 3))))
    ikid.save_calibration(cal, d / "cal.json")
    lab = d / "lab"
    lab.mkdir()
    for ext in (".trc", ".mot"):
        shutil.copyfile(d / f"t{ext}", lab / f"a{ext}")
    return d


def digests(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def run(argv: list[str], cwd: Path, stdin=None, stdout=subprocess.PIPE) -> subprocess.CompletedProcess:
    return subprocess.run(
        [IKID, *argv], cwd=cwd, stdin=stdin, stdout=stdout, stderr=subprocess.PIPE, text=True, timeout=120
    )


def link(d: Path, target: str, name: str, how: str) -> str:
    """``name`` in ``d`` made a symbolic or hard link to ``target`` (or ``target`` itself)."""
    if how == "same":
        return target
    (d / name).unlink(missing_ok=True)
    if how == "symlink":
        (d / name).symlink_to(target)
    else:
        os.link(d / target, d / name)
    return name


#: command line (OUT: the output), the input it must not replace, and how OUT is that input:
#: the input's own name ("same"), or OUT_NAME made a symbolic or a hard link to it. Commands
#: whose output names are derived (``ik``: STEM.mot) are given a link under the derived name.
CASES = {
    "id": (["id", "t.mot", "-o", "OUT"], "t.mot", "o.sto"),
    "id-to-its-model": (["id", "t.mot", "--model", "m.safetensors", "-o", "OUT"], "m.safetensors", "o.sto"),
    "calibrate-neutral": (
        ["calibrate", "--static", "t.trc", "--method", "neutral", "-o", "OUT"],
        "t.trc",
        "c.json",
    ),
    "calibrate-map": (
        ["calibrate", "--static", "t.trc", "--map", "map.toml", "-o", "OUT"],
        "map.toml",
        "c.json",
    ),
    "calibrate-movement": (
        ["calibrate", "--static", "t.trc", "--movement", "ra_wr_e_f=t.mot", "-o", "OUT"],
        "t.mot",
        "c.json",
    ),
    "ik": (["ik", "t.trc", "-o", "OUT"], "t.trc", "o.mot"),
    "ik-calibration": (["ik", "t.trc", "--calibration", "cal.json", "-o", "OUT"], "cal.json", "o.mot"),
    "run-sto": (["run", "t.trc", "--calibration", "cal.json", "-o", "o"], "cal.json", "o.sto"),
    "track-sto": (["track", "t.trc", "--map", "map.toml", "-o", "o"], "map.toml", "o.sto"),
    "report": (["report", "--data", "lab", "--clean-only", "-o", "OUT"], "lab/a.mot", "o.md"),
}
#: Cases whose -o can name the input itself (the others derive their output names from -o).
SAME_NAME = {"id", "id-to-its-model", "calibrate-neutral", "calibrate-map", "calibrate-movement"}


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_an_output_that_is_an_input_is_refused_naming_both(files, tmp_path, case, how):
    argv, target, out_name = CASES[case]
    if how == "same" and case not in SAME_NAME:
        pytest.skip("-o names a stem or a folder here: its outputs are never the input's own name")
    d = tmp_path / "w"
    shutil.copytree(files, d)
    if case == "id-to-its-model":
        shutil.copyfile(Path(ikid.__file__).with_name("models") / "wrist-id.safetensors", d / "m.safetensors")
    out = target if how == "same" else link(d, target, out_name, how)
    before = digests(d)
    r = run([out if a == "OUT" else a for a in argv], d)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    message = r.stderr.strip().splitlines()[-1]
    assert message.startswith("ikid: error: -o "), message
    # Both named: the output and the input it would replace.
    assert out in message and f"is the input {target}" in message, message
    assert "never writes over an input" in message
    assert digests(d) == before  # no input changed, nothing written


def test_map_template_and_stream_refuse_printing_into_their_input(files, tmp_path):
    d = tmp_path / "w"
    shutil.copytree(files, d)
    before = digests(d)
    with open(d / "t.trc", "a") as out:  # ikid map-template t.trc >> t.trc
        r = run(["map-template", "t.trc"], d, stdout=out)
    assert r.returncode == 2 and "standard output is the input t.trc" in r.stderr, r.stderr
    frames = d / "frames.csv"
    frames.write_text("")
    before = digests(d)
    with open(frames) as src, open(frames, "a") as out:  # ikid stream < frames.csv >> frames.csv
        r = run(["stream"], d, stdin=src, stdout=out)
    assert r.returncode == 2 and "standard output is the input" in r.stderr, r.stderr
    assert digests(d) == before


def test_the_same_file_under_another_name_is_allowed_as_output_when_it_is_not_an_input(files, tmp_path):
    """The check looks at files, not names: a different file with the input's name elsewhere
    is an ordinary output (and ``-o FOLDER/`` beside the input still works)."""
    d = tmp_path / "w"
    shutil.copytree(files, d)
    (d / "out").mkdir()
    shutil.copyfile(d / "t.mot", d / "out" / "t.sto")  # an old output, not an input
    r = run(["id", "t.mot", "-o", "out/"], d)
    assert r.returncode == 0, r.stderr
    assert (d / "t.mot").read_bytes() == (files / "t.mot").read_bytes()
    assert ikid.io.read_sto(d / "out" / "t.sto")[1].shape[1] == 3


@pytest.mark.parametrize("case", sorted(CASES))
def test_dash_as_the_output_is_refused_not_written_as_a_file_named_dash(files, tmp_path, case):
    # "-o -" reads elsewhere as standard output; every command here writes whole files instead.
    argv = [a if a not in ("OUT", "o") else "-" for a in CASES[case][0]]
    for name in ("t.trc", "t.mot", "map.toml", "cal.json", "lab"):
        (shutil.copytree if name == "lab" else shutil.copyfile)(files / name, tmp_path / name)
    before = digests(tmp_path)
    done = run(argv, tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("ikid: error: -o -: ikid writes files") and "name a file" in done.stderr
    assert digests(tmp_path) == before and done.stdout == ""
