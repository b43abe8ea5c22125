"""Waiting for a state rather than for a time: a loaded machine is slow, so a test polls for
what it needs with a generous deadline and says what did not happen when the deadline
passes."""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from pymavlink.dialects.v20 import common as mavlink2

T = TypeVar("T")


def until(value: Callable[[], T], what: str, timeout: float = 60.0,
          poll_s: float = 0.2) -> T:
    """The first truthy `value()`, polled every `poll_s`; AssertionError naming `what` (the
    state waited for) if none comes within `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        got = value()
        if got:
            return got
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {timeout:g} s")
        time.sleep(poll_s)


def until_progressing(value: Callable[[], T], progress: Callable[[], float], what: str, *,
                      within: float | None = None, stall_s: float = 30.0,
                      ceiling_s: float = 1800.0, poll_s: float = 0.2) -> T:
    """The first truthy `value()`, polled every `poll_s` for as long as `progress()` (a
    measure that grows while the run advances: a flight clock, CPU seconds) keeps growing: a
    loaded machine runs slower, never differently, so only a stall is a failure.
    AssertionError naming `what` (the state waited for) when `progress()` has grown by
    `within` since the wait began (the state's budget in the run's own measure: late in
    the flight, not on the wall clock), stands still for `stall_s` of wall time, or
    `ceiling_s` of wall time passes."""
    t0 = time.monotonic()
    start = seen = progress()
    changed = t0
    while True:
        got = value()
        if got:
            return got
        now, at = time.monotonic(), progress()
        if at != seen:
            seen, changed = at, now
        if within is not None and at - start >= within:
            raise AssertionError(f"{what}: not within {within:g} of progress "
                                 f"(from {start:g} to {at:g})")
        if now - changed > stall_s:
            raise AssertionError(f"{what}: no progress for {stall_s:g} s (last: {seen:g})")
        if now - t0 > ceiling_s:
            raise AssertionError(f"{what}: not within the ceiling of {ceiling_s:g} s "
                                 f"(progress from {start:g} to {at:g})")
        time.sleep(poll_s)


def run_progressing(argv: Sequence[str], progress: Callable[[], object], what: str, *,
                    stall_s: float = 180.0, poll_s: float = 1.0, cpu: bool = False,
                    **popen: Any) -> subprocess.CompletedProcess[str]:
    """Run `argv` to its end (text output captured) for as long as `progress()` keeps
    changing: a loaded machine makes a lockstep flight slower, never different, so only a
    run that stops progressing for `stall_s` is stopped, with an AssertionError naming
    `what` and the last progress seen. With `cpu`, the CPU seconds the process has used
    count as progress too (a run that writes nothing until its end: an in-process
    flight)."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **popen)

    def now() -> object:
        return (progress(), cpu_s(proc.pid)) if cpu else progress()

    seen, changed = now(), time.monotonic()
    while True:
        try:
            out, err = proc.communicate(timeout=poll_s)
            return subprocess.CompletedProcess(argv, proc.returncode, out, err)
        except subprocess.TimeoutExpired:
            now_seen = now()
            if now_seen != seen:
                seen, changed = now_seen, time.monotonic()
            elif time.monotonic() - changed > stall_s:
                proc.kill()
                out, err = proc.communicate()
                raise AssertionError(f"{what}: no progress for {stall_s:g} s (last: {seen})"
                                     f"\n{out[-2000:]}{err[-2000:]}") from None


def file_size(path: Path) -> int:
    """A growing file's size (-1 while it does not exist): progress for `run_progressing`."""
    try:
        return path.stat().st_size
    except OSError:
        return -1


def cpu_s(*pids: int) -> float:
    """CPU seconds (user + system) processes `pids` have used so far, 0 for one that has
    ended: progress for `until_progressing` while a process starts up."""
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


def sched_s(pid: int, tids: Sequence[int] | None = None) -> tuple[float, float]:
    """Seconds process `pid`'s threads (all, or those of `tids`) have run so far, and spent
    runnable but queued for a CPU (/proc/PID/task/TID/schedstat): what a starved machine
    gave them, to judge a pace by."""
    ran = queued = 0
    for task in os.listdir(f"/proc/{pid}/task") if tids is None else tids:
        with open(f"/proc/{pid}/task/{task}/schedstat") as f:
            run_ns, wait_ns, _ = f.read().split()
        ran, queued = ran + int(run_ns), queued + int(wait_ns)
    return ran * 1e-9, queued * 1e-9


class FlightClock:
    """The vehicle's flight clock as a test's Session hears it: the latest time_boot_ms of
    the target's messages, in seconds (-1 before any). In lockstep it is simulated time: it
    advances while the flight does, however slowly a loaded machine runs it. Messages read
    by other waits count (pymavlink keeps the latest of each type); with `take_in`,
    calling it also reads (and drops) what has arrived, for waits that read nothing from
    the Session."""

    def __init__(self, session: Any, *, take_in: bool = True) -> None:
        self.session = session
        self.take_in = take_in

    def __call__(self) -> float:
        conn = self.session.conn
        while self.take_in and conn.recv_match(blocking=False) is not None:
            pass
        target = conn.sysid_state.get(self.session.target_system)
        latest = [getattr(m, "time_boot_ms", -1000) for m in
                  (target.messages.values() if target is not None else ())]
        return max(latest, default=-1000) * 1e-3


def flight_wait(stack, types: list[str], predicate: Callable[[Any], bool], what: str, *,
                within_s: float, stall_s: float = 30.0, ceiling_s: float = 1800.0) -> Any:
    """The first message of `types` satisfying `predicate`, waited for while the vehicle's
    flight clock advances: AssertionError naming `what` when `within_s` simulated seconds
    pass without it (the state's budget in the flight's time), or the clock stands still
    for `stall_s` of wall time (or at `ceiling_s`)."""
    return until_progressing(lambda: stack.wait_for(types, predicate, timeout=0.2),
                             FlightClock(stack.session, take_in=False), what, within=within_s,
                             stall_s=stall_s, ceiling_s=ceiling_s, poll_s=0.0)


def flown_to(stack, t_s: float, timeout: float = 60.0):
    """The first LOCAL_POSITION_NED whose time_boot_ms (the flight clock: lockstep time
    stands still until the flight starts) is at least `t_s`."""
    msg = stack.wait_for(["LOCAL_POSITION_NED"], lambda m: m.time_boot_ms >= t_s * 1000.0,
                         timeout)
    assert msg is not None, f"the vehicle's clock did not reach {t_s:g} s in {timeout:g} s"
    return msg


class TlogTail:
    """The messages appended to a growing telemetry log (gcs.vehicle_link.session.Tlog: each message
    after its 8-byte time stamp, written whole) since the last call, read incrementally."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.parser = mavlink2.MAVLink(None)

    def new(self, types: set[str]) -> list[Any]:
        """The messages of `types` written since the last call."""
        if not self.path.exists():
            return []
        with self.path.open("rb") as fh:
            fh.seek(self.offset)
            data = fh.read()
        out, at = [], 0
        while len(data) - at > 8 + 2:
            start = at + 8
            magic, length, flags = data[start], data[start + 1], data[start + 2]
            size = (12 + length + (13 if flags & 1 else 0) if magic == 0xFD else 8 + length)
            if len(data) - start < size:
                break  # not written yet
            msg = self.parser.decode(bytearray(data[start:start + size]))
            if msg.get_type() in types:
                out.append(msg)
            at = start + size
        self.offset += at
        return out
