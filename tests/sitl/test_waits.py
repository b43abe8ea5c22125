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


BUSY = ("import time\n"
        "t = time.process_time()\n"
        "while time.process_time() - t < 2.5:\n"
        "    pass\n"
        "print('done')")


@pytest.mark.parametrize("cpu", [True, False])
def test_a_run_that_only_computes_progresses_by_its_cpu_time(tmp_path, cpu):
    """Given a program that computes for 2.5 s of CPU and writes nothing until its end, and a
    stall limit of 1.5 s, then with `cpu` it runs to its end, and without it is stopped."""
    path = tmp_path / "never"
    argv = [sys.executable, "-c", BUSY]
    if cpu:
        proc = run_progressing(argv, lambda: file_size(path), "busy", stall_s=1.5,
                               poll_s=0.1, cpu=True)
        assert proc.returncode == 0 and proc.stdout == "done\n"
    else:
        with pytest.raises(AssertionError, match=r"busy: no progress for 1\.5 s"):
            run_progressing(argv, lambda: file_size(path), "busy", stall_s=1.5, poll_s=0.1)


def test_a_run_that_stops_progressing_is_stopped_with_the_reason(tmp_path):
    """Given a program that never progresses and a stall limit of 1 s, then it is stopped
    after about 1 s, and the error names the run and the last progress seen."""
    path = tmp_path / "never"
    t0 = time.monotonic()
    with pytest.raises(AssertionError, match=r"stalled: no progress for 1 s \(last: -1\)"):
        run_progressing([sys.executable, "-c", "import time; time.sleep(60)"],
                        lambda: file_size(path), "stalled", stall_s=1.0, poll_s=0.1)
    assert time.monotonic() - t0 < 30.0


def test_a_state_is_waited_for_while_progress_grows_and_not_past_its_budget():
    """Given a progress that grows by 1 each poll, then a state that comes at progress 5 is
    returned, one not reached within a budget of 3 fails naming it, and a progress that
    stands still fails after the stall limit."""
    from .waits import until_progressing

    clock = iter(range(1000))
    seen = [0]

    def progress() -> float:
        seen[0] = next(clock)
        return seen[0]

    assert until_progressing(lambda: seen[0] >= 5, progress, "five", poll_s=0.0)
    with pytest.raises(AssertionError, match=r"never: not within 3 of progress"):
        until_progressing(lambda: False, progress, "never", within=3.0, poll_s=0.0)
    t0 = time.monotonic()
    with pytest.raises(AssertionError, match=r"still: no progress for 0.3 s"):
        until_progressing(lambda: False, lambda: 1.0, "still", stall_s=0.3, poll_s=0.05)
    assert time.monotonic() - t0 < 5.0
