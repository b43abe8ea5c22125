"""The fast tier's guard (tests/conftest.py): a test outside tests/sitl and tests/docs that
starts a program fails, whichever way it starts it."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys

import pytest

from tests.conftest import ProgramStarted


def test_a_subprocess_is_refused():
    with pytest.raises(ProgramStarted, match="process tier"):
        subprocess.run([sys.executable, "-c", "pass"], check=False)
    with pytest.raises(ProgramStarted):
        os.system("true")


@pytest.mark.parametrize("method", ["fork", "spawn", "forkserver"])
def test_a_worker_process_is_refused(method):
    proc = multiprocessing.get_context(method).Process(target=print)
    with pytest.raises(ProgramStarted):
        proc.start()


def test_the_guard_puts_back_what_it_replaced():
    """After `no_programs` the functions it patched are those it found (here the guard of
    this test's own: the originals come back after the test the same way)."""
    from tests.conftest import no_programs

    before = (subprocess.Popen._execute_child, os.fork, os.system, os.posix_spawn)
    with no_programs():
        assert subprocess.Popen._execute_child is not before[0] and os.fork is not before[1]
    assert (subprocess.Popen._execute_child, os.fork, os.system, os.posix_spawn) == before
