"""Running one function over many jobs in worker processes, and stopping well.

What `ikid ik`/`ikid run` over a folder need from a pool, and ``concurrent.futures`` does not
give: a worker that dies (the out-of-memory killer's SIGKILL) costs its own job only, named,
and the others go on (a ``ProcessPoolExecutor`` breaks as a whole, failing every job left);
Ctrl-C (SIGINT) and ``kill`` (SIGTERM) take one path that stops every worker, so none is left
behind holding the output pipes, and says which jobs were done.

Each job runs in a process of its own (forked on Linux: no start-up cost), at most ``workers``
at a time, so the parent always knows which job a process was running. Workers ignore SIGINT
(a terminal sends it to the whole process group: only the parent decides) and turn SIGTERM
into an exception, so a worker stopped by the parent removes its temporary files on the way
out (``ikid.io.atomic_outputs``); on Linux a worker is also sent SIGTERM if the parent dies
(``PR_SET_PDEATHSIG``). Results reach the parent as each job ends.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

#: Seconds stopped workers get to remove their temporary files before they are killed.
STOP_GRACE_S = 5.0

#: The signals that stop a batch.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Stopped(BaseException):
    """SIGINT or SIGTERM arrived: the batch (or the command) stops. A ``BaseException``, like
    ``KeyboardInterrupt``, so that no ``except Exception`` swallows it on the way up."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_status(self) -> int:
        """The shell's convention for a process ended by a signal: 128 + its number."""
        return 128 + self.signum


def _raise_stopped(signum: int, frame: object) -> None:
    raise Stopped(signum)


class stop_on_signals:
    """``with stop_on_signals():`` SIGINT and SIGTERM raise :class:`Stopped` in the main thread
    (one cancel path for both), the previous handlers restored after. Off the main thread,
    where Python cannot set handlers, it does nothing."""

    def __enter__(self) -> stop_on_signals:
        self.previous: dict[int, Any] = {}
        try:
            for s in STOP_SIGNALS:
                self.previous[s] = signal.signal(s, _raise_stopped)
        except ValueError:  # not the main thread
            pass
        return self

    def __exit__(self, *exc: object) -> None:
        for s, handler in self.previous.items():
            signal.signal(s, handler)


@dataclass
class Outcome:
    """How a batch ended: ``stopped_by`` the signal's name (``"SIGINT"``) or None if every job
    ran; ``not_done``, the indices of jobs that did not end (never started, or stopped)."""

    stopped_by: str | None = None
    exit_status: int = 0
    not_done: list[int] = field(default_factory=list)


def _die_with_parent() -> None:
    """Linux: ask for SIGTERM when the parent dies, so that a parent killed outright (SIGKILL,
    which no handler sees) leaves no worker behind. Elsewhere nothing (best effort)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):
        pass


def _worker(work: Callable[[Any], Any], job: Any, send: multiprocessing.connection.Connection) -> None:
    """A worker process: one job, its result sent to the parent. SIGINT and SIGTERM arrive
    blocked (the parent's mask around the start) and stay so until the handlers are set."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _raise_stopped)
    _die_with_parent()
    try:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
        if os.getppid() == 1:  # the parent died before the request took effect
            return
        result = work(job)
        send.send(result)
        send.close()
    except Stopped:
        return  # stopped by the parent: temporary files were removed on the way here


def _signal_name(exitcode: int | None) -> str:
    if exitcode is None or exitcode >= 0:
        return f"exit status {exitcode}"
    try:
        name = signal.Signals(-exitcode).name
    except ValueError:
        name = f"signal {-exitcode}"
    hint = ", as the out-of-memory killer does" if -exitcode == signal.SIGKILL else ""
    return f"killed by {name}{hint}"


def run_jobs(
    work: Callable[[Any], Any],
    jobs: Sequence[Any],
    workers: int,
    on_result: Callable[[int, Any], None],
    on_death: Callable[[int, str], None],
) -> Outcome:
    """``work(job)`` for every job, in worker processes, at most ``workers`` at a time, jobs
    started in order. As each ends the parent calls ``on_result(index, result)``, or
    ``on_death(index, how)`` if its process died without a result (``how``: "killed by
    SIGKILL, ..."); both run in the parent, in the order jobs end. ``work`` must return a
    picklable value and catch its own errors.

    SIGINT or SIGTERM in the parent stops every worker (SIGTERM, then SIGKILL after
    :data:`STOP_GRACE_S`), waits for all of them and returns an :class:`Outcome` naming the
    signal and the jobs not done. No worker outlives this call."""
    ctx: Any = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
    running: dict[int, tuple[Any, multiprocessing.connection.Connection]] = {}
    done: set[int] = set()
    next_job = 0
    with stop_on_signals():
        try:
            while next_job < len(jobs) or running:
                while next_job < len(jobs) and len(running) < workers:
                    recv, send = ctx.Pipe(duplex=False)
                    proc = ctx.Process(target=_worker, args=(work, jobs[next_job], send), daemon=True)
                    # Blocked across the start: a signal now reaches neither a half-made worker
                    # nor the parent between "started" and "recorded as running".
                    signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
                    try:
                        proc.start()
                        running[next_job] = (proc, recv)
                    finally:
                        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
                    send.close()  # the worker's end: EOF here once it is gone
                    next_job += 1
                ready = multiprocessing.connection.wait(
                    [c for _, c in running.values()] + [p.sentinel for p, _ in running.values()]
                )
                for index in [i for i, (p, c) in running.items() if c in ready or p.sentinel in ready]:
                    proc, recv = running[index]
                    try:
                        result, got = recv.recv(), True
                    except (EOFError, OSError):
                        result, got = None, False
                    proc.join()
                    recv.close()
                    done.add(index)
                    del running[index]
                    if got:
                        on_result(index, result)
                    else:
                        on_death(index, _signal_name(proc.exitcode))
        except Stopped as stop:
            with _ignoring_signals():
                _stop_all(running)
            running.clear()
            return Outcome(stop.name, stop.exit_status, [i for i in range(len(jobs)) if i not in done])
        finally:
            if running:  # stopped, or an error in the parent itself: no worker is left behind
                with _ignoring_signals():
                    _stop_all(running)
                running.clear()
    return Outcome()


class _ignoring_signals:
    """SIGINT and SIGTERM ignored for the block (a second Ctrl-C does not cut the clean-up short)."""

    def __enter__(self) -> None:
        self.previous = {}
        try:
            for s in STOP_SIGNALS:
                self.previous[s] = signal.signal(s, signal.SIG_IGN)
        except ValueError:
            pass

    def __exit__(self, *exc: object) -> None:
        for s, handler in self.previous.items():
            signal.signal(s, handler)


def _stop_all(running: dict[int, tuple[Any, multiprocessing.connection.Connection]]) -> None:
    """SIGTERM to every running worker, SIGKILL to those still there after the grace period;
    each one joined."""
    for proc, _ in running.values():
        if proc.is_alive():
            proc.terminate()
    deadline = time.monotonic() + STOP_GRACE_S
    for proc, recv in running.values():
        proc.join(max(0.0, deadline - time.monotonic()))
        if proc.is_alive():
            proc.kill()
            proc.join()
        recv.close()
