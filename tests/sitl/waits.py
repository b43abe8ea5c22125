"""Waiting for a state rather than for a time: a loaded machine is slow, so a test polls for
what it needs with a generous deadline and says what did not happen when the deadline
passes."""

from __future__ import annotations

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


def run_progressing(argv: Sequence[str], progress: Callable[[], object], what: str, *,
                    stall_s: float = 180.0, poll_s: float = 1.0,
                    **popen: Any) -> subprocess.CompletedProcess[str]:
    """Run `argv` to its end (text output captured) for as long as `progress()` keeps
    changing: a loaded machine makes a lockstep flight slower, never different, so only a
    run that stops progressing for `stall_s` is stopped, with an AssertionError naming
    `what` and the last progress seen."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **popen)
    seen, changed = progress(), time.monotonic()
    while True:
        try:
            out, err = proc.communicate(timeout=poll_s)
            return subprocess.CompletedProcess(argv, proc.returncode, out, err)
        except subprocess.TimeoutExpired:
            now_seen = progress()
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
