"""A night's batch as a lab runs it (issue #22): `ikid run` over a folder of 200 trials, 10 of
them broken in different ways. 190 are written; each broken one is named in the summary with
its cause; the exit status is non-zero; no file that existed before is touched (the inputs,
last night's outputs of the broken trials, anything else in the output folder); and a second
run over the same folder gives the same outputs byte for byte."""

from __future__ import annotations

import hashlib
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import ikid
from ikid.io import write_c3d, write_trc
from ikid.io.markers import MarkerData

IKID = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"

#: Good trials in the folder, and how long each is (frames at 1 kHz): enough for both models'
#: windows, short enough for 200 files twice in well under a minute on 2 cores.
N_GOOD, N_FRAMES = 190, 300


def _text(path: Path) -> str:
    return path.read_text()


def _truncated(folder: Path, t) -> Path:
    path = write_trc(folder / "b01_truncated.trc", t.time, t.markers, 1000.0)
    text = _text(path)
    path.write_text(text[: text.rindex("\n", 0, len(text) // 2) + 1])  # cut at a line: half the rows
    return path


def _wrong_units(folder: Path, t) -> Path:
    """The common export slip: the Units header says cm, the numbers are still mm."""
    path = write_trc(folder / "b02_wrong_units.trc", t.time, t.markers, 1000.0)
    lines = _text(path).split("\n")
    lines[2] = lines[2].replace("\tmm\t", "\tcm\t")
    path.write_text("\n".join(lines))
    return path


def _missing_marker(folder: Path, t) -> Path:
    m = t.markers.copy()
    m[:, 9:12] = np.nan  # MC2 never seen
    return write_trc(folder / "b03_missing_marker.trc", t.time, m, 1000.0)


def _junk_trc(folder: Path, t) -> Path:
    path = folder / "b04_junk.trc"
    path.write_bytes(np.random.default_rng(4).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    return path


def _directory(folder: Path, t) -> Path:
    path = folder / "b05_directory.trc"
    path.mkdir()
    (path / "inside.txt").write_text("a folder named like a trial\n")
    return path


def _junk_c3d(folder: Path, t) -> Path:
    path = folder / "b06_junk.c3d"
    path.write_bytes(b"\x02P" + np.random.default_rng(6).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    return path


def _empty(folder: Path, t) -> Path:
    path = folder / "b07_empty.trc"
    path.write_bytes(b"")
    return path


def _zeros(folder: Path, t) -> Path:
    """An export that wrote zeros for every marker (a failed reconstruction)."""
    return write_trc(folder / "b08_zeros.trc", t.time, np.zeros_like(t.markers), 1000.0)


def _other_labels(folder: Path, t) -> Path:
    labels = ["R.RadStyl", "R.UlnStyl", "R.Forearm", "R.MCP2", "R.MCP5", "R.HandBase"]  # and no map
    return write_trc(folder / "b09_labels.trc", t.time, t.markers, 1000.0, labels=labels)


def _time_backwards(folder: Path, t) -> Path:
    path = write_trc(folder / "b10_time_backwards.trc", t.time, t.markers, 1000.0)
    lines = _text(path).split("\n")
    first = next(i for i, line in enumerate(lines) if line.startswith("1\t0.000000"))
    row = lines[first + 99].split("\t")  # frame 100 (1-based), at 99 ms
    assert row[:2] == ["100", "0.099000"], row[:2]
    row[1] = "0.050000"  # now at 50 ms, after frame 99 at 98 ms
    lines[first + 99] = "\t".join(row)
    path.write_text("\n".join(lines))
    return path


#: Each broken trial: how it is made, and its cause as the summary must give it.
BROKEN = [
    (_truncated, rf"header says {N_FRAMES} frames, the file has \d+ \(truncated\?\)"),
    (_wrong_units, r"units|unit|mm|cm"),
    (_missing_marker, r"marker MC2 \(label 'MC2'\) is missing in every frame"),
    (_junk_trc, r"not a text file|not a TRC file"),
    (_directory, r"it is a directory; expected"),
    (_junk_c3d, r"not a readable C3D file|header says|truncated"),
    (_empty, r"line 1: not a TRC file"),
    (_zeros, r"the markers spread over 0\.000 m"),
    (_other_labels, r"label\(s\) RSP \(RSP\), .* not found; the file has R\.RadStyl"),
    (_time_backwards, r"time goes from 0\.098 to 0\.05 s at frame 100; it must increase"),
]
UNITS = "b02_wrong_units.trc"


def _snapshot(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (relative name -> SHA-256), folders included as such."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "<dir>"
        for p in sorted(folder.rglob("*"))
    }


def _run(folder: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [IKID, "run", str(folder), "-o", str(out), "--jobs", "2"], capture_output=True, text=True, timeout=600
    )


def test_a_nights_batch_names_every_failed_trial_and_touches_nothing_else(tmp_path):
    base = ikid.simulate("random", seed=7300, duration=0.35)
    assert len(base.time) >= N_FRAMES
    folder, out = tmp_path / "session", tmp_path / "results"
    folder.mkdir()
    out.mkdir()
    time_s, markers = base.time[:N_FRAMES], base.markers[:N_FRAMES]
    for k in range(N_GOOD):
        noisy = markers + np.random.default_rng(k).uniform(-2e-4, 2e-4, markers.shape)  # each its own
        if k % 19 == 0:  # some C3D files among the TRC
            write_c3d(
                folder / f"trial_{k:03d}.c3d",
                MarkerData(tuple(ikid.marker_names()), time_s, noisy.reshape(-1, 6, 3), 1000.0),
            )
        else:
            write_trc(folder / f"trial_{k:03d}.trc", time_s, noisy, 1000.0)

    source = SimpleNamespace(time=time_s, markers=markers)  # the broken trials': the same frames
    broken = {make(folder, source).name: cause for make, cause in BROKEN}
    assert len(broken) == 10
    # Last night's outputs of the broken trials, and a file of the lab's own, in the output folder.
    for name in broken:
        stem = name.rsplit(".", 1)[0]
        (out / f"{stem}.mot").write_text(f"last night's angles of {stem}\n")
        (out / f"{stem}.sto").write_text(f"last night's torques of {stem}\n")
    (out / "notes.txt").write_text("the lab's notes\n")
    inputs_before, outputs_before = _snapshot(folder), _snapshot(out)

    first = _run(folder, out)
    assert "Traceback" not in first.stderr, first.stderr
    assert first.returncode == 2, (first.returncode, first.stderr[-2000:])
    summary = first.stdout[first.stdout.index("files processed") - 8 :]
    failed = dict(re.findall(r"^  (\S+): (.*)$", summary, re.MULTILINE))
    failed = {Path(k).name: v for k, v in failed.items()}
    n_failed = len(failed)
    assert f"{200 - n_failed}/200 files processed, {n_failed} failed:" in summary, summary
    # Every broken trial but the wrong-units one is named, with its cause; no good one is.
    for name, cause in broken.items():
        if name != UNITS:
            assert name in failed, (name, summary)
            assert re.search(cause, failed[name]), (name, failed[name])
    assert set(failed) <= set(broken), failed
    # Each failure was also reported as it happened, on stderr.
    assert first.stderr.count("ikid: error: ") == n_failed, first.stderr

    # 190 written, each a .mot and a .sto; nothing left half-written; nothing else touched.
    outputs = _snapshot(out)
    written = {n for n in outputs if n not in outputs_before}
    good = {f"trial_{k:03d}{ext}" for k in range(N_GOOD) for ext in (".mot", ".sto")}
    units_written = {f"{UNITS[:-4]}.mot", f"{UNITS[:-4]}.sto"} if UNITS not in failed else set()
    assert written == good | (units_written - set(outputs_before)), sorted(written ^ good)[:10]
    assert not [n for n in outputs if n.startswith(".")]  # no temporary file left
    for name, digest in outputs_before.items():
        if name not in units_written:
            assert outputs[name] == digest, f"{name} was changed by a run that could not process it"
    assert _snapshot(folder) == inputs_before  # the inputs are read only

    # The same folder again: the same outputs, byte for byte.
    second = _run(folder, out)
    assert second.returncode == 2 and second.stdout.count("\n  ") == first.stdout.count("\n  ")
    assert _snapshot(out) == outputs

    if UNITS not in failed:
        pytest.xfail(
            "units plausibility check (core): a TRC whose Units header says cm while its numbers are mm "
            "is not refused yet; its outputs were written"
        )
    assert re.search(broken[UNITS], failed[UNITS]), failed[UNITS]


def test_a_folder_names_its_subfolders_of_trials_and_stems_named_twice(tmp_path, capsys):
    # A folder is searched, not its subfolders: trials there were passed by without a word ("1/1
    # files processed"); two inputs of one stem were refused without naming them.
    from ikid.cli import main as cli

    t = ikid.simulate("random", seed=9932, duration=0.3)
    (tmp_path / "lab" / "s02").mkdir(parents=True)
    write_trc(tmp_path / "lab" / "a.trc", t.time, t.markers)
    write_trc(tmp_path / "lab" / "s02" / "b.trc", t.time, t.markers)
    assert cli(["ik", str(tmp_path / "lab"), "-o", str(tmp_path / "out")]) == 0
    sub = str(tmp_path / "lab" / "s02")
    assert f"subfolders are not searched ({sub} hold marker files: name them too)" in capsys.readouterr().err
    (tmp_path / "empty" / "s03").mkdir(parents=True)
    write_trc(tmp_path / "empty" / "s03" / "c.trc", t.time, t.markers)
    assert cli(["ik", str(tmp_path / "empty"), "-o", str(tmp_path / "o4")]) == 2
    assert "subfolders are not searched" in capsys.readouterr().err
    write_trc(tmp_path / "lab" / "s02" / "a.trc", t.time, t.markers)
    assert cli(["ik", str(tmp_path / "lab"), sub, "-o", str(tmp_path / "o5")]) == 2
    err = capsys.readouterr().err
    assert f"several inputs are named a ({tmp_path / 'lab' / 'a.trc'}, {sub}/a.trc)" in err, err
