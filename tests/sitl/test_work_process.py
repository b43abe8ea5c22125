"""The worker process beside the loop (`fcu/edge/work_process.py`): its outcome is the inline
one, a job that raises says why, a worker that dies fails its job and is started again, and
a first warm-up runs at the loop's priority, every other job below it, the mission check's
batch kernels on two threads below it too."""

from __future__ import annotations

import os
import signal
from typing import Any

from common.wire.mavlink import MAV
from fcu.edge.work_process import NICE, ProcessWork
from fcu.mission import batches
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission
from fcu.work import InlineWork, Outcome
from tests.unit.test_mission_protocol import waypoints

M = MAV


def test_a_worker_process_gives_the_inline_result_and_says_why_a_job_failed():
    """Given the mission check of 500 items, then the worker process's outcome equals the
    inline one (exactly); a job that raises comes back with its exception's text, and the
    worker goes on with the next."""
    items = tuple(waypoints(500))
    limits = MissionLimits()
    inline: list[Outcome[Any]] = []
    InlineWork().submit(check_mission, (items, limits, None), inline.append)
    beside: list[Outcome[Any]] = []
    work = ProcessWork(wait=True)
    try:
        work.submit(check_mission, (items, limits, None), beside.append)
        work.submit(int, ("not a number",), beside.append)
        work.submit(check_mission, (items[:3], limits, None), beside.append)
    finally:
        work.close()
    assert beside[0] == inline[0] and inline[0].value[0] == M.MAV_MISSION_ACCEPTED
    assert beside[1].value is None and beside[1].error.startswith("ValueError: invalid")
    assert beside[2].value[0] == M.MAV_MISSION_ACCEPTED
    assert (work.submitted, work.failed) == (3, 1)
    assert [h[0] for h in work.history] == ["check_mission", "int", "check_mission"]


def test_a_worker_that_dies_fails_its_job_with_the_reason_and_is_started_again():
    """Given a worker killed while its job runs, then the job's outcome says the worker
    stopped (with its exit code), and the next job runs in a new worker."""
    import time
    work = ProcessWork()
    got: list[Outcome[Any]] = []
    try:
        work.submit(time.sleep, (30.0,), got.append)
        assert work.pending == 1
        os.kill(work._proc.pid, signal.SIGKILL)
        work._proc.join(timeout=10)
        while not got:
            work.take()
        assert got[0].value is None and "worker stopped (exit code -9)" in got[0].error
        work.wait = True
        work.submit(abs, (-2,), got.append)
        assert got[1] == Outcome(2) and work.restarts == 1 and work.pending == 0
    finally:
        work.close()


def test_a_first_warm_up_runs_at_the_loops_priority_and_every_other_job_below_it():
    """Given a worker whose first job is a warm-up, then it runs at the priority the FCU runs
    at, and every job after it (a warm-up too) at nice +NICE; given a worker whose first job
    is no warm-up, then that job runs at nice +NICE already."""
    loop = os.nice(0)  # os.nice(0): the niceness
    lowered = min(loop + NICE, 19)
    for warm_first, expected in ((True, [loop, lowered, lowered]),
                                 (False, [lowered, lowered, lowered])):
        work = ProcessWork(wait=True)
        got: list[Outcome[Any]] = []
        try:
            work.submit(os.nice, (0,), got.append, warm_up=warm_first)
            work.submit(os.nice, (0,), got.append, warm_up=True)
            work.submit(os.nice, (0,), got.append)
        finally:
            work.close()
        assert [o.value for o in got] == expected, warm_first
    assert lowered > loop


def shares_seen() -> tuple[int, list[int]]:
    """In the worker: how many ways the batch kernels' moves are cut, and the niceness each
    share of a batch runs at (its thread's)."""
    seen: list[int] = []
    batches.run([lambda: seen.append(os.nice(0)) for _ in range(batches.ways())])
    return batches.ways(), sorted(seen)


def test_after_its_warm_up_the_worker_runs_the_checks_shares_on_two_threads_below_the_loop():
    """Given a worker whose first job is a warm-up, then that job runs its shares in one
    thread at the loop's priority, and every later job on min(2, CPUs) threads, each at nice
    +NICE (the threads made after the worker lowered itself)."""
    loop = os.nice(0)
    lowered = min(loop + NICE, 19)
    ways = min(2, len(os.sched_getaffinity(0)))
    work = ProcessWork(wait=True)
    got: list[Outcome[Any]] = []
    try:
        work.submit(shares_seen, (), got.append, warm_up=True)
        work.submit(shares_seen, (), got.append)
        work.submit(shares_seen, (), got.append)
    finally:
        work.close()
    assert [o.value for o in got] == [(1, [loop]), (ways, [lowered] * ways),
                                      (ways, [lowered] * ways)]


def test_a_job_that_cannot_be_sent_fails_before_submit_returns_when_the_loop_waits():
    """Given a worker the loop waits for (lockstep), when a job cannot be sent to it (its
    arguments do not pickle), then its failure is called back before `submit` returns, as
    every result is (it was left for a step boundary that wall time chose), and the next job
    runs on a new worker."""
    work = ProcessWork(wait=True)
    got: list[Outcome[Any]] = []
    try:
        work.submit(len, (lambda: 0,), got.append)
        assert len(got) == 1 and got[0].value is None
        assert got[0].error.startswith("job not sent"), got[0].error
        work.submit(len, ((1, 2),), got.append)
    finally:
        work.close()
    assert got[1] == Outcome(2) and work.restarts == 1
