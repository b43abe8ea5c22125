"""sitl.truth_log.flushed: the simulator's truth log written on every flush, and stopped
(said once, closed) when the disk will not take more, while the world goes on."""

from __future__ import annotations

import errno
from pathlib import Path

from common.config.scenario import load_scenario
from common.logs.ulog import read_topic
from sitl.plant import Plant, initial_state
from sitl.truth_log import TruthLog, flushed

ROOT = Path(__file__).resolve().parents[2]


def _state():
    sc = load_scenario(ROOT / "config" / "scenarios" / "case2_impulse.toml")
    return initial_state(sc, Plant(sc.vehicle, dt_us=1000))


def test_a_flush_writes_what_was_recorded(tmp_path):
    log = TruthLog(tmp_path / "truth.ulg", "case2_impulse")
    log.record(_state())
    assert flushed(log, 0) is log
    _, rows = read_topic(tmp_path / "truth.ulg", "dq_truth")
    assert len(rows) == 1
    log.close()


def test_a_full_disk_stops_the_log_once_with_the_time(tmp_path, capsys):
    log = TruthLog(tmp_path / "truth.ulg", "case2_impulse")
    log.record(_state())
    assert flushed(log, 0) is log

    def full(_data: bytes) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    log._write = full  # the disk fills after the first records
    log.record(_state())
    assert flushed(log, 1_500_000) is None
    assert capsys.readouterr().err == \
        "sitl: truth log stopped at t = 1.500 s: No space left on device\n"
    assert flushed(None, 2_000_000) is None  # nothing more is said
    assert capsys.readouterr().err == ""
    _, rows = read_topic(tmp_path / "truth.ulg", "dq_truth")
    assert len(rows) == 1  # what was written before stays readable
