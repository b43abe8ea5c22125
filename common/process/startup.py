"""A stop asked for while a program starts: Ctrl-C (SIGINT) or SIGTERM recorded, not raised.

Starting `fcu` or `sitl` imports numba and loads or compiles the kernels, which takes seconds
on a busy machine. A KeyboardInterrupt raised then can land inside a callback that numba's
LLVM binding calls through ctypes, which prints "Exception ignored on calling ctypes callback
function" and drops it: the program went on to serve for ever (seen in CI). So from the first
line of the console script until the loop's own handlers take over, the signals only set a
flag, and the program looks at it where it is safe (`stop_requested`) and then says
"<prog>: stopped while starting" and exits 0. A signal the program was started with ignored
(a background job without job control, nohup) stays ignored.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

from common.warm_ups import run_warm_ups_with

_pending: list[int] = []
_Handler = Callable[[int, FrameType | None], Any] | int | signal.Handlers | None
_before: dict[int, _Handler] = {}  # the handlers `guard` replaced


def _record(signum: int, _frame: object) -> None:
    _pending.append(signum)


def guard() -> None:
    """Record SIGINT and SIGTERM from now on (idempotent); SIGINT stays ignored where it was
    ignored at start."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        current = signal.getsignal(signum)
        if current is _record or (signum == signal.SIGINT and current is signal.SIG_IGN):
            continue
        _before[signum] = current
        signal.signal(signum, _record)


def release() -> None:
    """The handlers `guard` replaced put back (a program whose Ctrl-C is a
    KeyboardInterrupt from here on); KeyboardInterrupt at once if a stop was recorded
    meanwhile (one that came between a last look and this call is not lost)."""
    for signum, handler in _before.items():
        signal.signal(signum, handler)
    _before.clear()
    if _pending:
        raise KeyboardInterrupt


def stop_requested() -> bool:
    """A SIGINT or SIGTERM arrived since `guard`."""
    return bool(_pending)


@contextmanager
def sigint_deferred() -> Iterator[None]:
    """A Ctrl-C inside (numba loading or compiling kernels) recorded and raised as
    KeyboardInterrupt when the block ends, not inside numba's ctypes callbacks (which print
    it as an ignored exception with its traceback and drop it). Only where SIGINT is
    Python's default KeyboardInterrupt, in the main thread: a program that guards or handles
    it itself keeps its handler."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    got: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, _frame: got.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if got:
        raise KeyboardInterrupt


_compile_s = [0.0]


def _timed_warm_up(call: Callable[[], object]) -> None:
    t0 = time.perf_counter()
    with sigint_deferred():  # a Ctrl-C meanwhile raised after, not inside numba's callbacks
        call()
    _compile_s[0] += time.perf_counter() - t0


def compile_time_s() -> float:
    """Seconds this process spent in `common.warm_ups.warm_up` (compiling or loading kernels)
    since this module was imported."""
    return _compile_s[0]


# Every program imports this module before its kernels warm up (the console scripts first
# of all, `fcu` and `sitl` at the top of their process modules), so each warm-up from here
# on is timed and shielded from Ctrl-C.
run_warm_ups_with(_timed_warm_up)
