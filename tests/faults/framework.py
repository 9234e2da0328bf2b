"""Probes, their verdicts, and the runner.

Two kinds of probe:

- ``Api``: a function run in a worker process (``python -m faults.worker``), which calls
  ikid's Python API or libikid through ctypes and records problems on a :class:`Verdict`.
  A worker that dies (a signal: a crash in native code) or does not answer within the
  probe's timeout (a hang) is replaced, and the probe it was running fails as a crash.
- ``Cli``: a command run in a subprocess (its own session, killed as a group on timeout),
  optionally with a file size limit (a full disk, SIGXFSZ ignored so writes fail with EFBIG)
  or as an unprivileged user (a read-only folder, when running as root). Files under the
  probe's folders are hashed before and after: a run that failed must leave each byte as it
  was and no new file behind.

Each probe's problems fall in three classes, counted in the summary line: ``silent`` (no
named error and no flag: an error that does not name the file or option, an exit status of
0 where a trial was lost, an implausible output nobody flagged), ``partial_writes`` and
``tracebacks`` (a Python traceback, a crash or a hang). ``passed`` counts probes with none.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import queue
import resource
import select
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

SILENT, PARTIAL, TRACEBACK, HARNESS = "silent", "partial_write", "traceback", "harness"
CATEGORIES = (SILENT, PARTIAL, TRACEBACK, HARNESS)

ROOT = Path(__file__).resolve().parents[2]
PYTHON = ROOT / ".venv" / "bin" / "python"
#: ``ikid`` as its console script runs it (the script itself is replaced while someone
#: reinstalls the wheel; the interpreter is not).
IKID = [PYTHON, "-m", "ikid"]
TESTS = ROOT / "tests"

#: Address space of a CLI probe's process: a huge value that allocates is refused by the
#: kernel (MemoryError) instead of taking the machine.
CLI_MEMORY_BYTES = 6 << 30
NOBODY = 65534
#: prctl(PR_CAPBSET_DROP, cap): root without CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH and
#: CAP_FOWNER obeys a folder's mode bits (a read-only folder stays read-only).
PR_CAPBSET_DROP = 24
DAC_CAPS = (1, 2, 3)
LIBC = ctypes.CDLL(None, use_errno=True)


class Verdict:
    """The problems one probe found (none: it passed)."""

    def __init__(self) -> None:
        self.problems: list[tuple[str, str]] = []

    def add(self, category: str, message: str) -> None:
        self.problems.append((category, " ".join(str(message).split())[:400]))

    def silent(self, message: str) -> None:
        self.add(SILENT, message)

    def partial(self, message: str) -> None:
        self.add(PARTIAL, message)

    def traceback(self, message: str) -> None:
        self.add(TRACEBACK, message)


# --- in-process probes ---------------------------------------------------------------------------


@dataclass
class Api:
    name: str
    fn: Callable[[Verdict], None]
    timeout: float = 40.0


def call(fn: Callable, *args, **kwargs) -> tuple[object, BaseException | None]:
    """``fn(*args, **kwargs)``: its value and no exception, or None and the exception."""
    try:
        return fn(*args, **kwargs), None
    except (Exception, SystemExit) as e:  # noqa: BLE001 - every exception is the probe's to judge
        return None, e


def named_error_classes() -> tuple[type, ...]:
    import ikid

    return (ikid.IkidError, OSError)


def judge_error(v: Verdict, e: BaseException, needles: list[str], what: str = "") -> bool:
    """An exception from an ikid call: a traceback unless it is ikid's (or an OSError), silent
    unless its message contains one of ``needles`` (the file, the option...). True if good."""
    text = f"{type(e).__name__}: {e}"
    if not isinstance(e, named_error_classes()):
        v.traceback(f"{what}raised {text} (not an ikid error: a traceback in the CLI)")
        return False
    if needles and not any(n in str(e) for n in needles):
        v.silent(f"{what}error does not name {needles[0]!r}: {text}")
        return False
    return True


# --- subprocess probes ---------------------------------------------------------------------------


@dataclass
class Run:
    returncode: int | None
    stdout: str
    stderr: str
    seconds: float
    timed_out: bool = False


@dataclass
class Cli:
    name: str
    argv: list[str]
    #: The probe's own folder (created by the corpus, holding its pre-existing outputs).
    cwd: Path
    #: "error": the run must fail with a named error; "either": exit 0 with a plausible output
    #: (``check``), or a named error.
    expect: str = "either"
    #: The error message must contain one of these (the file, the option...).
    names: list[str] = field(default_factory=list)
    stdin: bytes | None = None
    #: Folders whose files must be unchanged (and gain no file) when the run fails; default cwd.
    protect: list[Path] | None = None
    #: A failed run may leave new files (a batch's good trials, a training log); a hidden
    #: temporary file left behind is a partial write all the same.
    new_files_ok: bool = True
    #: Files that may change even when the run fails (a batch's good trials).
    may_change: list[Path] = field(default_factory=list)
    fsize: int | None = None
    #: Folders' mode bits hold even when running as root (see DAC_CAPS).
    as_nobody: bool = False
    timeout: float = 30.0
    #: On exit 0 (and with "either"): checks the outputs are plausible or flagged.
    check: Callable[[Run, Verdict], None] | None = None
    #: On any exit: further checks (a stream's lines, a summary's counts).
    check_any: Callable[[Run, Verdict], None] | None = None
    #: Runs just before the command (a FIFO, a UDP sender...): gets the Popen.
    interact: Callable[[subprocess.Popen], None] | None = None
    #: Whole command instead of ``ikid argv`` (a Python snippet under a file size limit).
    raw: bool = False
    env: dict | None = None


def _snapshot(dirs: list[Path]) -> dict[Path, str]:
    files: dict[Path, str] = {}
    for d in dirs:
        if not d.exists():
            continue
        for root, _, names in os.walk(d):
            for n in names:
                p = Path(root) / n
                if p.is_symlink() or not p.is_file():
                    files[p] = "special"
                    continue
                try:
                    files[p] = hashlib.sha256(p.read_bytes()).hexdigest()
                except OSError:
                    files[p] = "unreadable"
    return files


def _preexec(fsize: int | None, read_only_root: bool) -> Callable[[], None]:
    def setup() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (CLI_MEMORY_BYTES, CLI_MEMORY_BYTES))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        if fsize is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
        if read_only_root and os.geteuid() == 0:
            for cap in DAC_CAPS:
                if LIBC.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
                    os.write(
                        2, b"faults: cannot drop CAP_DAC_OVERRIDE: a read-only folder is writable to root\n"
                    )
                    os._exit(97)

    return setup


def run_cli(p: Cli) -> Run:
    cmd = [str(c) for c in (p.argv if p.raw else [*IKID, *p.argv])]
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", **(p.env or {}))
    env.pop("PYTHONPATH", None)
    t0 = time.monotonic()
    proc = subprocess.Popen(
        cmd,
        cwd=p.cwd,
        stdin=subprocess.PIPE if p.stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_preexec(p.fsize, p.as_nobody),
        start_new_session=True,
        env=env,
    )
    timed_out = False
    try:
        if p.interact is not None:
            p.interact(proc)
        out, err = proc.communicate(p.stdin, timeout=max(1.0, p.timeout - (time.monotonic() - t0)))
    except subprocess.TimeoutExpired:
        timed_out = True
        _kill_group(proc)
        out, err = proc.communicate()
    finally:
        _kill_group(proc)  # children left by the command (a C3D parser, a process pool)
    return Run(
        None if timed_out else proc.returncode,
        out.decode("utf-8", "replace"),
        err.decode("utf-8", "replace"),
        time.monotonic() - t0,
        timed_out,
    )


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else "(nothing on stderr)"


def judge_cli(p: Cli) -> Verdict:
    v = Verdict()
    protect = p.protect if p.protect is not None else [p.cwd]
    before = _snapshot(protect)
    r = run_cli(p)
    if r.timed_out:
        v.traceback(f"hang: no exit within {p.timeout:.0f} s")
    elif r.returncode < 0:
        v.traceback(f"killed by signal {-r.returncode} ({last_line(r.stderr)})")
    elif "Traceback (most recent call last)" in r.stderr:
        v.traceback(f"Python traceback: {last_line(r.stderr)}")
    failed = r.returncode != 0
    if not r.timed_out and r.returncode is not None and r.returncode >= 0:
        if p.expect == "error" and not failed:
            v.silent(f"exit 0, expected a named error (stdout: {last_line(r.stdout)[:150]})")
        elif failed and "Traceback" not in r.stderr:
            message = r.stderr + r.stdout
            if p.names and not any(n in message for n in p.names):
                v.silent(f"exit {r.returncode}, error does not name {p.names[0]!r}: {last_line(r.stderr)}")
        if not failed and p.check is not None and p.expect == "either":
            try:
                p.check(r, v)
            except Exception as e:  # noqa: BLE001 - an unreadable output is the probe's finding
                v.silent(f"exit 0 but the output is not readable: {type(e).__name__}: {e}")
        if p.check_any is not None:
            try:
                p.check_any(r, v)
            except Exception as e:  # noqa: BLE001
                v.silent(f"output check failed: {type(e).__name__}: {e}")
    if failed or r.timed_out:
        after = _snapshot(protect)
        for path, digest in before.items():
            if path in p.may_change:
                continue
            if path not in after:
                v.partial(f"failed run removed {path.name}")
            elif after[path] != digest:
                v.partial(f"failed run changed {path.name}")
        for path in sorted(set(after) - set(before)):
            if path.name.startswith(".") or not p.new_files_ok:
                v.partial(f"failed run left a new file {path.relative_to(p.cwd.parent)}")
    return v


# --- workers for in-process probes ---------------------------------------------------------------


class Worker:
    """``python -m faults.worker CORPUS``: reads probe names on stdin, answers one JSON line each."""

    def __init__(self, corpus: Path, log: Path) -> None:
        self.log = open(log, "ab")  # noqa: SIM115 - lives as long as the worker
        self.proc = subprocess.Popen(
            [str(PYTHON), "-m", "faults.worker", str(corpus)],
            cwd=TESTS,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.log,
            start_new_session=True,
            env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"),
        )
        self.buffer = b""

    def ask(self, name: str, timeout: float) -> dict | str:
        """The probe's result, or why there is none ("crash: ...", "hang: ...")."""
        try:
            self.proc.stdin.write(name.encode() + b"\n")
            self.proc.stdin.flush()
        except BrokenPipeError:
            return self._died()
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                return f"hang: no answer within {timeout:.0f} s"
            ready, _, _ = select.select([fd], [], [], left)
            if ready:
                chunk = os.read(fd, 65536)
                if not chunk:
                    return self._died()
                self.buffer += chunk
        line, _, self.buffer = self.buffer.partition(b"\n")
        return json.loads(line)

    def _died(self) -> str:
        code = self.proc.wait()
        return f"crash: the process died ({f'signal {-code}' if code < 0 else f'exit {code}'})"

    def close(self) -> None:
        _kill_group(self.proc)
        self.proc.wait()
        self.log.close()


# --- the run -------------------------------------------------------------------------------------


@dataclass
class Outcome:
    name: str
    problems: list[tuple[str, str]]
    seconds: float


def run_all(
    corpus_root: Path, api: list[Api], cli: list[Cli], api_workers: int = 2, cli_threads: int = 2
) -> list[Outcome]:
    outcomes: list[Outcome] = []
    lock = threading.Lock()

    def record(name: str, problems: list, seconds: float) -> None:
        with lock:
            outcomes.append(Outcome(name, problems, seconds))
            if problems:
                text = "; ".join(f"{c}: {m}" for c, m in problems)
                print(f"FAIL {name}: {text}", flush=True)

    todo: queue.Queue[Api] = queue.Queue()
    for probe in api:
        todo.put(probe)

    def api_loop(k: int) -> None:
        worker = None
        log = corpus_root / f"worker-{k}.log"
        while True:
            try:
                probe = todo.get_nowait()
            except queue.Empty:
                break
            if worker is None:
                worker = Worker(corpus_root, log)
            t0 = time.monotonic()
            answer = worker.ask(probe.name, probe.timeout)
            if isinstance(answer, str):
                worker.close()
                worker = None
                tail = last_line(log.read_text(errors="replace")) if log.exists() else ""
                record(probe.name, [(TRACEBACK, f"{answer} ({tail[:200]})")], time.monotonic() - t0)
            else:
                record(probe.name, [tuple(x) for x in answer["problems"]], answer["seconds"])
        if worker is not None:
            worker.close()

    def cli_one(probe: Cli) -> None:
        t0 = time.monotonic()
        try:
            v = judge_cli(probe)
            problems = v.problems
        except Exception as e:  # noqa: BLE001 - a harness bug fails the probe, visibly
            problems = [(HARNESS, f"{type(e).__name__}: {e}")]
        record(probe.name, problems, time.monotonic() - t0)

    threads = [threading.Thread(target=api_loop, args=(k,), daemon=True) for k in range(api_workers)]
    for t in threads:
        t.start()
    # Slow probes first, so the pool does not end on them.
    ordered = sorted(cli, key=lambda p: -p.timeout)
    with ThreadPoolExecutor(max_workers=cli_threads) as pool:
        list(pool.map(cli_one, ordered))
    for t in threads:
        t.join()
    return outcomes


def summary(outcomes: list[Outcome]) -> tuple[str, bool]:
    count = {c: sum(any(p[0] == c for p in o.problems) for o in outcomes) for c in CATEGORIES}
    passed = sum(not o.problems for o in outcomes)
    line = (
        f"faults: probes={len(outcomes)} passed={passed} silent={count[SILENT]} "
        f"partial_writes={count[PARTIAL]} tracebacks={count[TRACEBACK]}"
    )
    ok = passed == len(outcomes) and not (count[SILENT] or count[PARTIAL] or count[TRACEBACK])
    return line, ok


def flush_exit(code: int) -> None:
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
