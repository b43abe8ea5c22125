"""`common.process.startup`: a Ctrl-C while kernels load is raised after, never inside numba's
ctypes callbacks (which print it as an ignored exception with a traceback and drop it)."""

from __future__ import annotations

import os
import signal

import pytest

from common.process import startup


@pytest.fixture
def default_sigint():
    """SIGINT at Python's default (pytest-xdist's workers ignore it) for the test."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def test_a_ctrl_c_inside_a_deferred_block_is_raised_when_it_ends(default_sigint):
    reached_end = []
    with pytest.raises(KeyboardInterrupt):
        with startup.sigint_deferred():
            os.kill(os.getpid(), signal.SIGINT)
            reached_end.append(True)  # not interrupted here
    assert reached_end == [True]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_block_without_a_ctrl_c_raises_nothing(default_sigint):
    with startup.sigint_deferred():
        pass
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_program_that_handles_sigint_itself_keeps_its_handler(default_sigint):
    heard = []
    signal.signal(signal.SIGINT, lambda signum, _frame: heard.append(signum))
    with startup.sigint_deferred():
        os.kill(os.getpid(), signal.SIGINT)
    assert heard == [signal.SIGINT]
