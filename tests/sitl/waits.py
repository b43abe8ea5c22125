"""Waiting for a state rather than for a time: a loaded machine is slow, so a test polls for
what it needs with a generous deadline and says what did not happen when the deadline
passes."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

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


def flown_to(stack, t_s: float, timeout: float = 60.0):
    """The first LOCAL_POSITION_NED whose time_boot_ms (the flight clock: lockstep time
    stands still until the flight starts) is at least `t_s`."""
    msg = stack.wait_for(["LOCAL_POSITION_NED"], lambda m: m.time_boot_ms >= t_s * 1000.0,
                         timeout)
    assert msg is not None, f"the vehicle's clock did not reach {t_s:g} s in {timeout:g} s"
    return msg
