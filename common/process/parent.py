"""Children that end with their parent: `gcs run` starts `sitl` and `fcu` with
`PARENT_ENV` set to its pid, and each child asks the kernel (Linux's PR_SET_PDEATHSIG) for
SIGTERM when that parent dies, so a ground station killed with SIGKILL leaves nothing behind.

Done by the child at start-up rather than in a `preexec_fn`, which is unsafe in a parent
that runs threads. If the parent died before the request, the child stops at once.
"""

from __future__ import annotations

import os
import signal

PARENT_ENV = "DQFLIGHT_PARENT_PID"
PR_SET_PDEATHSIG = 1


def child_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """The environment for a child that must end with this process."""
    out = dict(os.environ if env is None else env)
    out[PARENT_ENV] = str(os.getpid())
    return out


def stop_with_parent() -> None:
    """In a child started with `child_env`: SIGTERM when the parent dies (Linux only)."""
    text = os.environ.get(PARENT_ENV, "")
    if not text.isdigit():
        return
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        return  # not Linux: the children stop when their links go quiet only
    if os.getppid() != int(text):  # the parent is already gone
        os.kill(os.getpid(), signal.SIGTERM)
