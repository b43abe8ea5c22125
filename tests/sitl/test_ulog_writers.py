"""ULog writers in a process of their own: records that survive SIGKILL of their writer,
and a write that fails (a full disk) stops the log at its last complete record."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np

from common.logs.ulog import Topic, ULogWriter, open_ulog, tail_record

WRITER = """
import sys
from common.logs.ulog import Topic, ULogWriter
t = Topic("row", (("uint64_t", "timestamp"), ("double", "a"), ("double", "b")))
w = ULogWriter(sys.argv[1], [t])
i = 0
while True:
    w.add("row", (i, 2.0 * i, -i))
    i += 1
    if i % 3 == 0:
        w.flush()  # the processes flush once per control period
    if i % 999 == 0:
        print(i, flush=True)
"""


def test_records_survive_sigkill_of_the_writer(tmp_path):
    """Given a writer killed with SIGKILL mid-stream, then pyulog reads every record it had
    flushed, in order, without a torn record, and `tail_record` finds the same last one."""
    path = tmp_path / "killed.ulg"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE,
                            text=True, cwd=os.getcwd())
    try:
        written = 0
        deadline = time.monotonic() + 30
        while written < 30000 and time.monotonic() < deadline:
            written = int(proc.stdout.readline())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    u = open_ulog(path)
    assert not u.file_corruption
    rows = u.get_dataset("row").data
    n = len(rows["timestamp"])
    assert n >= written
    assert np.array_equal(rows["timestamp"], np.arange(n))
    assert np.array_equal(rows["a"], 2.0 * np.arange(n))
    cols, last = tail_record(path, "row")
    assert cols == ("time_us", "a", "b") and last == (n - 1, 2.0 * (n - 1), -(n - 1.0))


FULL_DISK = """
import resource, signal, sys
from common.logs.ulog import Topic, ULogWriter
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))
t = Topic("row", (("uint64_t", "timestamp"), ("double", "a"), ("double", "b")))
w = ULogWriter(sys.argv[1], [t])
for i in range(20_000):
    for _ in range(3):
        w.add("row", (i, 2.0 * i, -i))
    w.flush()
    if w.failed:
        break
w.add("row", (i + 1, 0.0, 0.0))
w.flush()  # after a failure: dropped, never appended after a torn record
w.close()
print(w.failed, i)
"""


def test_a_write_that_fails_stops_the_log_at_its_last_complete_record(tmp_path):
    """A full disk (here the file size limit) in the middle of a flush: the writer says why,
    cuts the torn record off and writes nothing more; pyulog reads every complete record."""
    path = tmp_path / "full.ulg"
    out = subprocess.run([sys.executable, "-c", FULL_DISK, str(path)], capture_output=True,
                         text=True, cwd=os.getcwd(), timeout=60, check=True).stdout.split()
    assert out[0] == "File" and "large" in out  # "File too large"
    u = open_ulog(path)
    assert not u.file_corruption
    rows = u.get_dataset("row").data
    n = len(rows["timestamp"])
    assert 3000 < n and path.stat().st_size <= 100_000
    assert np.array_equal(rows["a"], 2.0 * (np.arange(n) // 3))
    empty = tmp_path / "empty.ulg"
    ULogWriter(empty, [Topic("row", (("uint64_t", "timestamp"), ("double", "a"),
                                     ("double", "b")))]).close()
