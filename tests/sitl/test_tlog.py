"""The `flight.tlog` of a real `gcs run` is a telemetry log that pymavlink's own tools read
to the last byte: `mavlogdump.py` and a plain `mavutil.mavlink_connection` loop agree."""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from pymavlink import mavutil

from .conftest import ROOT

MAVLOGDUMP = Path(sys.executable).parent / "mavlogdump.py"
LINE = re.compile(r"^\S+ \S+: ([A-Z0-9_]+) \{")  # "2026-01-01 12:00:00.00: TYPE {...}"


def _read_directly(path: Path) -> tuple[Counter, int]:
    """Message types and the bytes they account for (8-byte time + frame each)."""
    log = mavutil.mavlink_connection(str(path))
    types: Counter = Counter()
    size = 0
    try:
        while (msg := log.recv_match()) is not None:
            types[msg.get_type()] += 1
            size += 8 + len(msg.get_msgbuf())
    finally:
        log.close()
    return types, size


@pytest.mark.timeout(180)
def test_gcs_run_tlog_is_read_completely_by_mavlogdump(tmp_path):
    """Given `gcs run case1_figure8.toml --duration 5`, when its flight.tlog is read by
    mavlogdump.py and by a mavlink_connection loop, then mavlogdump exits 0 and prints one
    line per message that the loop reads, type by type; the loop's messages account for
    every byte of the file, none is BAD_DATA; HEARTBEAT, ATTITUDE_QUATERNION and
    MISSION_CURRENT are there."""
    out = tmp_path / "run"
    run = subprocess.run([sys.executable, "-m", "gcs.cli", "run",
                          "config/scenarios/case1_figure8.toml", "--duration", "5",
                          "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                         timeout=150, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    tlog = out / "flight.tlog"
    assert tlog.stat().st_size > 0

    # as from a shell: no MAVLINK20 in the environment (this process sets it), so the tool
    # finds the MAVLink 2 framing by itself
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK20"}
    dump = subprocess.run([sys.executable, str(MAVLOGDUMP), str(tlog)], capture_output=True,
                          text=True, timeout=60, check=False, env=env)
    assert dump.returncode == 0, dump.stderr
    lines = dump.stdout.splitlines()
    dumped = Counter(m.group(1) for m in map(LINE.match, lines) if m)
    assert sum(dumped.values()) == len(lines), [x for x in lines if not LINE.match(x)][:5]

    direct, size = _read_directly(tlog)
    assert "BAD_DATA" not in direct
    assert size == tlog.stat().st_size  # every byte is a record: nothing torn or skipped
    assert sum(dumped.values()) == sum(direct.values())
    assert dumped == direct
    for kind in ("HEARTBEAT", "ATTITUDE_QUATERNION", "MISSION_CURRENT"):
        assert direct[kind] > 0, kind

    # the tlog's own framing: 8-byte big-endian wall time in us before each frame
    first_usec = struct.unpack(">Q", tlog.read_bytes()[:8])[0]
    assert first_usec > 1_000_000_000 * 1_000_000  # after 2001: a real wall-clock time
