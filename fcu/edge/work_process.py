"""`ProcessWork`: jobs of `fcu.work` in a worker process beside the control loop (the edge:
a process, a pipe, select), `make_work` for `fcu --work`, and `SideBySide`, the runner of
`fcu.mission.batches` that the worker installs (`install_side_by_side`): a batch kernel's
shares at once, one in the calling thread and the others on a pool of threads the kernels
run on while they hold no GIL."""

from __future__ import annotations

import multiprocessing
import os
import select
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.connection import Connection
from typing import Any

from fcu.mission import batches
from fcu.work import Done, InlineWork, Outcome, Work, run_job

NICE = 10  # the worker's priority below the loop's
MOST_WAYS = 2  # the mission check's shares at once: enough for the 2-core boards in use
POLL_S = 1.0  # wait=True: how often the worker is looked at while its job runs


def _lower(nice: int) -> None:
    try:
        os.nice(nice)
    except OSError:
        pass


class SideBySide:
    """Runs `calls[0]` in the calling thread and the others on `ways - 1` pool threads. The
    pool's threads are made by the thread that makes this runner, and take its priority."""

    def __init__(self, ways: int) -> None:
        self.ways = ways
        self._pool = ThreadPoolExecutor(max_workers=max(1, ways - 1),
                                        thread_name_prefix="fcu-check")

    def __call__(self, calls: Sequence[batches.Call]) -> None:
        futures = [self._pool.submit(call) for call in calls[1:]]
        try:
            if calls:
                calls[0]()
        finally:
            for future in futures:
                future.result()  # every share done (its error raised) before returning


def usable_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def install_side_by_side(most: int = MOST_WAYS) -> int:
    """Install a `SideBySide` of min(most, `usable_cpus()`) ways (none for 1); the ways."""
    ways = min(most, usable_cpus())
    if ways > 1:
        batches.install(SideBySide(ways), ways)
    return ways


def _lower_and_share(nice: int) -> None:
    """Lower the worker by `nice`, then give the mission check's batch kernels their threads
    (`SideBySide`), made now so that they run at the lowered priority too."""
    _lower(nice)
    install_side_by_side()


def _serve(conn: Connection, nice: int) -> None:
    """The worker process: jobs in, outcomes out, until the pipe closes. A warm-up that comes
    first runs at the priority the worker started with (the loop's), in one thread; the
    worker lowers it by `nice` after that, or before its first job if that is no warm-up,
    and from then on the mission check's batch kernels run on two threads."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the FCU's to act on
    lowered = False
    while True:
        try:
            job_id, fn, args, warm_up = conn.recv()
        except (EOFError, OSError):
            return  # the FCU closed the pipe (or is gone)
        if not (warm_up or lowered):
            _lower_and_share(nice)
            lowered = True
        outcome = run_job(fn, args)
        if not lowered:
            _lower_and_share(nice)
            lowered = True
        try:
            conn.send((job_id, outcome))
        except Exception as exc:  # an unpicklable result: said, not lost
            conn.send((job_id, Outcome(None, f"result not sent: {exc}")))


class ProcessWork(Work):
    """Jobs run in one worker process (started on the first job, spawned: nothing of the
    loop's state is inherited), at nice +NICE but for warm-ups before any other job;
    callbacks from `take`."""

    kind = "beside"

    def __init__(self, *, wait: bool = False, nice: int = NICE) -> None:
        super().__init__()
        self.wait = wait
        self.nice = nice
        self._conn: Connection | None = None
        self._proc: Any = None
        self._jobs: dict[int, Done] = {}
        self._next_id = 0
        self.restarts = 0

    @property
    def immediate(self) -> bool:
        return self.wait

    @property
    def pending(self) -> int:
        return len(self._jobs) + len(self._finished)

    def _start(self) -> Connection:
        if self._conn is not None:
            return self._conn
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_serve, args=(child, self.nice), name="fcu-work",
                           daemon=True)
        proc.start()
        child.close()
        self._conn, self._proc = parent, proc
        return parent

    def start(self) -> None:
        """Start the worker now (it is otherwise started by the first job)."""
        self._start()

    def _submit(self, fn: Callable[..., Any], args: tuple[Any, ...], done: Done,
                warm_up: bool) -> None:
        job_id = self._next_id = self._next_id + 1
        self._jobs[job_id] = done
        try:
            self._start().send((job_id, fn, args, warm_up))
        except Exception as exc:  # the pipe is gone (the worker died) or args unpicklable
            self._lost(f"job not sent: {exc}")
        else:
            if self.wait:
                self._wait_for(job_id)
        if self.wait:  # called back before `submit` returns, a failure too (lockstep)
            self.take()

    def filenos(self) -> list[int]:
        return [self._conn.fileno()] if self._conn is not None and self._jobs else []

    def _wait_for(self, job_id: int) -> None:
        """wait=True: for as long as the worker lives (simulated time waits with the loop,
        so a busy machine makes the run slower, never different)."""
        while job_id in self._jobs:
            conn, proc = self._conn, self._proc
            if conn is None or proc is None:
                return
            if select.select([conn.fileno()], [], [], POLL_S)[0]:
                self._receive()
            elif not proc.is_alive():
                self._receive()  # what it sent before it stopped
                if job_id in self._jobs:
                    self._lost(self._exit_reason())

    def _receive(self) -> None:
        conn = self._conn
        while conn is not None and self._jobs and conn.poll(0):
            try:
                job_id, outcome = conn.recv()
            except (EOFError, OSError):
                self._lost(self._exit_reason())
                return
            done = self._jobs.pop(job_id, None)
            if done is not None:
                self._finished.append((done, outcome))

    def _exit_reason(self) -> str:
        proc = self._proc
        if proc is not None:
            proc.join(timeout=1.0)
            return f"the worker stopped (exit code {proc.exitcode})"
        return "the worker stopped"

    def _lost(self, reason: str) -> None:
        """The worker is gone or stuck: fail every job it had, stop it; the next job
        starts another."""
        for done in self._jobs.values():
            self._finished.append((done, Outcome(None, reason)))
        self._jobs.clear()
        self._stop()
        self.restarts += 1

    def take(self) -> int:
        if self._jobs:
            self._receive()
            proc = self._proc
            if self._jobs and proc is not None and not proc.is_alive():
                self._receive()  # what it sent before it stopped
                if self._jobs:
                    self._lost(self._exit_reason())
        return super().take()

    def _stop(self) -> None:
        conn, proc = self._conn, self._proc
        self._conn = self._proc = None
        if conn is not None:
            conn.close()
        if proc is not None:
            proc.join(timeout=1.0)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=1.0)

    def close(self) -> None:
        self._stop()


def make_work(kind: str, *, lockstep: bool) -> Work:
    """`--work`: 'inline' or 'beside' (a worker process; in lockstep it is waited for)."""
    if kind == "inline":
        return InlineWork()
    if kind == "beside":
        return ProcessWork(wait=lockstep)
    raise ValueError(f"--work: expected one of inline, beside, got {kind!r}")
