"""Real-time scheduling for a loop that must keep its period (`fcu --realtime`).

On a shared machine the kernel's fair scheduler lets a control loop that wakes for its
period wait behind every other runnable process of its share: at 500 Hz on two busy cores
that is whole periods lost. Autopilots that run on Linux put their loops in the real-time
class for that reason (PX4's POSIX build and ArduPilot's Linux boards schedule them
SCHED_FIFO). `request_fifo` does the same for the calling thread: it then runs as soon as it
is runnable, ahead of every normal process. Processes it starts afterwards go back to normal
scheduling (SCHED_RESET_ON_FORK), so work beside the loop stays below it. The kernel's
real-time throttling (sched_rt_runtime_us) still leaves the rest of the machine a share.

Only a loop that sleeps between its periods may ask for it: a loop that polls (lockstep)
would keep a core from everything else.

`schedule_loop` also freezes the garbage collector's view of what was built before the loop
(`gc.freeze`): a full collection in flight then walks what the loop made since, not the
whole program (19-63 ms for each full collection, measured in `fcu`), the practice of
Python services with latency targets.
"""

from __future__ import annotations

import gc
import os

from common.process.diagnostics import say

DEFAULT_PRIORITY = 50  # SCHED_FIFO 1..99; PX4's and ArduPilot's loops sit in the middle


def request_fifo(priority: int) -> str:
    """SCHED_FIFO at `priority` (1..99) for the calling thread, children reset to normal;
    '' when granted, else why not (the loop then runs at normal priority). 0: not asked."""
    if priority == 0:
        return "not asked (--rt-priority 0)"
    if not 1 <= priority <= 99:
        raise ValueError(f"real-time priority: expected 0..99, got {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK,
                              os.sched_param(priority))
    except OSError as exc:  # EPERM without CAP_SYS_NICE or RLIMIT_RTPRIO
        return exc.strerror or type(exc).__name__
    return ""


def schedule_loop(prog: str, priority: int) -> None:
    """`request_fifo` for a program's real-time loop, said in one status line (program
    output) either way; the objects built so far frozen out of the garbage collector's full
    collections."""
    gc.collect()
    gc.freeze()
    refused = request_fifo(priority)
    say(f"{prog}: loop scheduled SCHED_FIFO {priority}" if not refused else
        f"{prog}: loop at normal priority: real-time priority {refused}")
