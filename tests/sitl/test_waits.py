"""`run_progressing` (tests/sitl/waits.py): a run is waited for while it progresses, and one
that stops progressing is stopped with the reason."""

from __future__ import annotations

import sys
import time

import pytest

from .waits import file_size, run_progressing

SLOW = ("import sys, time\n"
        "for k in range(8):\n"
        "    open(sys.argv[1], 'a').write('x'); time.sleep(0.4)\n"
        "print('done')")


def test_a_run_slower_than_the_stall_limit_but_progressing_is_waited_for(tmp_path):
    """Given a program that takes 3 s, appending to a file every 0.4 s, and a stall limit of
    1.5 s, then it runs to its end (its output captured)."""
    path = tmp_path / "grows"
    proc = run_progressing([sys.executable, "-c", SLOW, str(path)], lambda: file_size(path),
                           "slow", stall_s=1.5, poll_s=0.1)
    assert proc.returncode == 0 and proc.stdout == "done\n" and file_size(path) == 8


def test_a_run_that_stops_progressing_is_stopped_with_the_reason(tmp_path):
    """Given a program that never progresses and a stall limit of 1 s, then it is stopped
    after about 1 s, and the error names the run and the last progress seen."""
    path = tmp_path / "never"
    t0 = time.monotonic()
    with pytest.raises(AssertionError, match=r"stalled: no progress for 1 s \(last: -1\)"):
        run_progressing([sys.executable, "-c", "import time; time.sleep(60)"],
                        lambda: file_size(path), "stalled", stall_s=1.0, poll_s=0.1)
    assert time.monotonic() - t0 < 30.0
