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

_pending: list[int] = []


def _record(signum: int, _frame: object) -> None:
    _pending.append(signum)


def guard() -> None:
    """Record SIGINT and SIGTERM from now on (idempotent); SIGINT stays ignored where it was
    ignored at start."""
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, _record)
    signal.signal(signal.SIGTERM, _record)


def stop_requested() -> bool:
    """A SIGINT or SIGTERM arrived since `guard`."""
    return bool(_pending)
