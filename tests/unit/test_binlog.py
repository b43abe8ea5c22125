"""Binary logs survive SIGKILL of their writer: every complete row is readable."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np

from common.binlog import LogWriter, read_log, write_log

WRITER = """
import sys, time
from common.binlog import LogWriter
w = LogWriter(sys.argv[1], ("time_us", "a", "b"))
i = 0
while True:
    w.write((i, 2.0 * i, -i))
    i += 1
    if i % 1000 == 0:
        print(i, flush=True)
"""


def test_round_trip(tmp_path):
    rows = np.arange(30.0).reshape(10, 3)
    write_log(tmp_path / "a.bin", ("time_us", "x", "y"), rows)
    cols, back = read_log(tmp_path / "a.bin")
    assert cols == ("time_us", "x", "y") and np.array_equal(back, rows)
    w = LogWriter(tmp_path / "b.bin", cols)
    for r in rows:
        w.write(tuple(r))
    w.close()
    assert np.array_equal(read_log(tmp_path / "b.bin")[1], rows)
    assert (tmp_path / "b.bin").stat().st_size == (tmp_path / "a.bin").stat().st_size


def test_rows_survive_sigkill_of_the_writer(tmp_path):
    """Given a writer killed with SIGKILL mid-stream, then the log reads back every row it
    had completed, in order, without a torn or zero row."""
    path = tmp_path / "killed.bin"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE,
                            text=True, cwd=os.getcwd())
    try:
        written = 0
        deadline = time.monotonic() + 30
        while written < 20000 and time.monotonic() < deadline:
            written = int(proc.stdout.readline())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    cols, rows = read_log(path)
    assert cols == ("time_us", "a", "b")
    assert len(rows) >= written
    assert np.array_equal(rows[:, 0], np.arange(len(rows)))
    assert np.array_equal(rows[:, 1], 2.0 * rows[:, 0])
