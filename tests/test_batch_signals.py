"""A batch that is stopped, or loses a worker, stops well (issue #31 item 2).

`ikid run DIR -o OUT --jobs 2` on a few 8 s simulated trials, in a session of its own: Ctrl-C
(SIGINT to the whole process group, as a terminal sends it) and `kill PID` (SIGTERM to the
parent alone) end it with 128 + the signal's number, no traceback, no process of the batch
left, no partial or temporary file, and a listing of the files done and not done with the
command that resumes; that command finishes the rest and leaves the done ones as they were. A
worker killed with SIGKILL (as the out-of-memory killer does) fails its own file, named; the
others are written; exit 2. Every test ends by itself within its timeouts (well under 60 s).
"""

from __future__ import annotations

import hashlib
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import ikid

IKID = shutil.which("ikid", path=str(Path(sys.executable).parent)) or "ikid"
N_TRIALS = 8
#: Longest a test waits for anything (a first result, the batch's end).
WAIT_S = 40.0

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc for the workers")


@pytest.fixture(scope="module")
def trials(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("batch-signals") / "in"
    d.mkdir()
    ikid.simulate("random", seed=77, duration=8.0).save(d / "t00")
    for suffix in (".npz", ".mot", ".sto"):
        (d / f"t00{suffix}").unlink()
    for k in range(1, N_TRIALS):
        shutil.copyfile(d / "t00.trc", d / f"t{k:02d}.trc")
    return d


class Batch:
    """`ikid run IN -o OUT --jobs 2` in its own session (so its process group is its own)."""

    def __init__(self, cwd: Path, extra: tuple[str, ...] = ()) -> None:
        self.cwd = cwd
        self.stdout = cwd / "stdout.txt"
        self.stderr = cwd / "stderr.txt"
        self.argv = ["run", "in", "-o", "out", "--jobs", "2", *extra]
        with open(self.stdout, "wb") as out, open(self.stderr, "wb") as err:
            self.proc = subprocess.Popen(
                [IKID, *self.argv], cwd=cwd, stdout=out, stderr=err, start_new_session=True
            )
        self.pgid = self.proc.pid

    def wait_for_results(self, n: int) -> None:
        """Until ``n`` files are reported on stdout."""
        deadline = time.monotonic() + WAIT_S
        while len(self.results()) < n:
            assert self.proc.poll() is None, f"the batch ended first: {self.read()}"
            assert time.monotonic() < deadline, f"no {n} results within {WAIT_S:.0f} s: {self.read()}"
            time.sleep(0.05)

    def results(self) -> list[str]:
        return re.findall(r"^in/(t\d\d)\.trc: \d+/\d+ frames", self.stdout.read_text(), re.M)

    def workers(self) -> list[int]:
        """The batch's worker processes now (children of the parent, from /proc)."""
        found = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    stat = (entry / "stat").read_text()
                except OSError:
                    continue
                if int(stat.rsplit(")", 1)[1].split()[1]) == self.proc.pid:
                    found.append(int(entry.name))
        return found

    def wait_for_workers(self) -> list[int]:
        """The workers running now, waiting for one if the batch is between two files."""
        deadline = time.monotonic() + WAIT_S
        while not (found := self.workers()):
            assert self.proc.poll() is None, f"the batch ended first: {self.read()}"
            assert time.monotonic() < deadline, f"no worker within {WAIT_S:.0f} s"
            time.sleep(0.01)
        return found

    def end(self) -> tuple[int, str, str]:
        try:
            code = self.proc.wait(timeout=WAIT_S)
        finally:
            if self.proc.poll() is None:  # never leave a hung batch behind the test
                os.killpg(self.pgid, signal.SIGKILL)
                self.proc.wait()
        out, err = self.read()
        return code, out, err

    def read(self) -> tuple[str, str]:
        return self.stdout.read_text(), self.stderr.read_text()

    def group_left(self) -> bool:
        """True if any process of the batch's group survives it."""
        try:
            os.killpg(self.pgid, 0)
        except ProcessLookupError:
            return False
        return True


def digests(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def setup(tmp_path: Path, trials: Path) -> Path:
    shutil.copytree(trials, tmp_path / "in")
    return tmp_path


def listed(err: str, what: str) -> list[str]:
    m = re.search(rf"^  {what}: (.*)$", err, re.M)
    assert m, err
    return [] if m.group(1) == "none" else [Path(f).stem for f in m.group(1).split(", ")]


def check_stopped(batch: Batch, code: int, err: str, sig: signal.Signals) -> tuple[list[str], list[str]]:
    """The common verdict on a stopped batch; returns the files done and not done."""
    assert code == 128 + sig, (code, err)
    assert "Traceback" not in err, err
    assert not batch.group_left(), "a process of the batch outlived it"
    assert f"ikid: stopped by {sig.name}:" in err, err
    done, not_done = listed(err, "done"), listed(err, "not done")
    assert sorted(done + not_done) == [f"t{k:02d}" for k in range(N_TRIALS)], err
    assert done and not_done, err
    # Outputs for the files done, whole; nothing for the others; no temporary file anywhere.
    out = batch.cwd / "out"
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{s}{x}" for s in done for x in (".mot", ".sto"))
    for name in done:
        assert len(ikid.io.read_sto(out / f"{name}.sto")[0]) > 0
    return done, not_done


def resume(batch: Batch, err: str, done: list[str]) -> None:
    """The printed command resumes: the done files skipped (their outputs untouched), the rest
    written, exit 0."""
    m = re.search(r"^  to resume: (ikid .*)$", err, re.M)
    assert m, err
    argv = shlex.split(m.group(1))
    assert argv[1:] == [*batch.argv, "--resume"], argv
    before = digests(batch.cwd / "out")
    r = subprocess.run([IKID, *argv[1:]], cwd=batch.cwd, capture_output=True, text=True, timeout=WAIT_S * 2)
    assert r.returncode == 0, r.stderr
    for name in done:
        assert f"in/{name}.trc: skipped (--resume" in r.stdout, r.stdout
    after = digests(batch.cwd / "out")
    assert {k: after[k] for k in before} == before
    assert len(after) == 2 * N_TRIALS


def test_ctrl_c_stops_every_worker_lists_what_was_done_and_resumes(trials, tmp_path):
    batch = Batch(setup(tmp_path, trials))
    batch.wait_for_results(1)
    batch.wait_for_workers()
    os.killpg(batch.pgid, signal.SIGINT)  # what a terminal's Ctrl-C does
    code, _, err = batch.end()
    done, _ = check_stopped(batch, code, err, signal.SIGINT)
    resume(batch, err, done)


def test_kill_of_the_parent_stops_its_workers_too(trials, tmp_path):
    batch = Batch(setup(tmp_path, trials))
    batch.wait_for_results(1)
    workers = batch.wait_for_workers()
    batch.proc.send_signal(signal.SIGTERM)  # `kill PID`: the parent alone
    code, _, err = batch.end()
    check_stopped(batch, code, err, signal.SIGTERM)
    for pid in workers:
        assert not Path(f"/proc/{pid}").exists(), f"worker {pid} outlived the batch"


def test_a_worker_killed_by_the_kernel_fails_its_file_only(trials, tmp_path):
    batch = Batch(setup(tmp_path, trials))
    os.kill(batch.wait_for_workers()[0], signal.SIGKILL)  # as the out-of-memory killer does
    code, out, err = batch.end()
    assert code == 2, (code, err)
    assert "Traceback" not in err
    assert not batch.group_left()
    died = re.findall(
        r"^ikid: error: in/(t\d\d)\.trc: the process working on it died \(killed by SIGKILL", err, re.M
    )
    assert len(died) == 1, err
    assert f"{N_TRIALS - 1}/{N_TRIALS} files processed, 1 failed:" in out, out
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == sorted(
        f"t{k:02d}{x}" for k in range(N_TRIALS) for x in (".mot", ".sto") if f"t{k:02d}" != died[0]
    )
