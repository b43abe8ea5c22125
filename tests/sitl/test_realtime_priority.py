"""The real-time loops' scheduling (`common/process/realtime.py`): in real time `fcu` and `sitl` put
their loops in SCHED_FIFO (fcu above sitl) where the system grants it, say so, and leave the
FCU's worker process at normal scheduling below them; `--rt-priority 0` and lockstep keep
normal scheduling; where it is refused the loop says why and flies at normal priority."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import ROOT, launch, stop
from .waits import until


def _granted() -> bool:
    """Whether this machine lets a process of ours into SCHED_FIFO (root, CAP_SYS_NICE or
    RLIMIT_RTPRIO), asked of a child so that this process stays as it is."""
    code = ("from common.process.realtime import request_fifo; import sys; "
            "sys.exit(bool(request_fifo(1)))")
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT).returncode == 0


def _policy(pid: int) -> tuple[int, int]:
    """(policy, priority) of a process's main thread, the reset-on-fork flag left out."""
    return (os.sched_getscheduler(pid) & ~os.SCHED_RESET_ON_FORK,
            os.sched_getparam(pid).sched_priority)


def _worker(pid: int) -> int | None:
    """The FCU's worker process (`fcu.edge.work_process`, a multiprocessing spawn) once it has
    lowered its own priority, else None."""
    tasks = Path(f"/proc/{pid}/task")
    for child in (int(c) for t in tasks.iterdir() for c in (t / "children").read_text().split()):
        cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
        if b"spawn_main" in cmdline and os.getpriority(os.PRIO_PROCESS, child) > \
                os.getpriority(os.PRIO_PROCESS, pid):
            return child
    return None


def test_real_time_loops_run_fifo_fcu_above_sitl_and_the_worker_below(tmp_path):
    """Given sitl and fcu in real time with their default priorities, when the loop runs
    (the FCU reports attitude), then where SCHED_FIFO is granted fcu's loop is FIFO 50,
    sitl's FIFO 49 and the FCU's worker process at normal scheduling (SCHED_OTHER); where
    it is refused both run at normal scheduling and say why."""
    granted = _granted()
    s = launch(tmp_path, "case1_figure8", realtime=True)
    try:
        fcu, sitl = s.procs["fcu"].pid, s.procs["sitl"].pid
        said = until(lambda: "fcu: loop" in s.log("fcu") and "sitl: loop" in s.log("sitl"),
                     "both loops said how they are scheduled", timeout=30.0)
        assert said
        worker = until(lambda: _worker(fcu), "the FCU's worker process at its nice", 30.0)
        if granted:
            assert _policy(fcu) == (os.SCHED_FIFO, 50)
            assert os.sched_getscheduler(fcu) & os.SCHED_RESET_ON_FORK  # children: normal
            assert _policy(sitl) == (os.SCHED_FIFO, 49)
            assert "fcu: loop scheduled SCHED_FIFO 50" in s.log("fcu")
            assert "sitl: loop scheduled SCHED_FIFO 49" in s.log("sitl")
        else:
            assert _policy(fcu)[0] == _policy(sitl)[0] == os.SCHED_OTHER
            assert "fcu: loop at normal priority: real-time priority " in s.log("fcu")
        assert _policy(worker)[0] == os.SCHED_OTHER
    finally:
        s.session.close()
        stop(s.procs)


@pytest.mark.parametrize("realtime, fcu_args", [(True, ("--rt-priority", "0")), (False, ())])
def test_lockstep_and_rt_priority_0_keep_normal_scheduling(tmp_path, realtime, fcu_args):
    """Given `--rt-priority 0` in real time, or lockstep (whose loop polls), then fcu's
    loop keeps normal scheduling."""
    s = launch(tmp_path, "case1_figure8", realtime=realtime, fcu_args=fcu_args,
               sitl_args=("--rt-priority", "0") if realtime else ())
    try:
        assert _policy(s.procs["fcu"].pid)[0] == os.SCHED_OTHER
        assert _policy(s.procs["sitl"].pid)[0] == os.SCHED_OTHER
        if realtime:
            assert "fcu: loop at normal priority: real-time priority not asked" in s.log("fcu")
    finally:
        s.session.close()
        stop(s.procs)


@pytest.mark.parametrize("program", ["fcu.edge.node", "sitl.node"])
def test_a_priority_out_of_range_is_exit_2(program):
    args = ["--vehicle", "config/vehicles/hexa_tilted.toml", "--gains",
            "config/gains/pid_eq30.toml"] if program == "fcu.edge.node" else \
        ["config/scenarios/case1_figure8.toml"]
    proc = subprocess.run([sys.executable, "-m", program, *args, "--realtime",
                           "--rt-priority", "100"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and "--rt-priority: expected 0..99, got 100" in proc.stderr
