"""sitl.truth_log: a state recorded from its truth row is the record of the state itself,
byte for byte; `flushed`: the simulator's truth log written on every flush, and stopped
(said once, closed) when the disk will not take more, while the world goes on."""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.logs.ulog import read_topic
from sitl.plant import Plant, initial_state, state_row
from sitl.truth_log import TruthLog, flushed

ROOT = Path(__file__).resolve().parents[2]


def _state():
    sc = load_scenario(ROOT / "config" / "scenarios" / "case2_impulse.toml")
    return initial_state(sc, Plant(sc.vehicle, dt_us=1000))


def test_a_state_recorded_from_its_row_is_the_same_bytes():
    """Landed and in flight, odd values included (-0.0, a subnormal, NaN, inf): the row's
    bytes after the stamp are the record's fields in order."""
    rng = np.random.default_rng(2)
    s0 = _state()
    states = [s0, s0._replace(landed=True)]
    for k in range(200):
        v = [float(x) for x in rng.normal(0.0, 50.0, 22)]
        v[k % 22] = (-0.0, 5e-324, float("nan"), float("inf"))[k % 4]
        states.append(s0._replace(time_us=1000 * k + 7, p_enu_m=tuple(v[0:3]),
                                  v_enu_m_s=tuple(v[3:6]), q_enu_flu=tuple(v[6:10]),
                                  omega_flu_rad_s=tuple(v[10:13]),
                                  rotor_speed_rad_s=tuple(v[13:19]),
                                  tilt_rad=tuple(v[19:22]) + tuple(v[13:16]),
                                  landed=k % 5 == 0))
    plain, from_row = bytearray(), bytearray()
    a, b = TruthLog(plain, "x"), TruthLog(from_row, "x")
    for s in states:
        a.record(s)
        b.record(s, state_row(s))
    a.close()
    b.close()
    assert bytes(plain) == bytes(from_row)
    s = states[5]
    for bad in (state_row(s)[:-1], state_row(s).astype(np.float32),
                state_row(s._replace(time_us=s.time_us + 1))):
        with pytest.raises(ValueError, match="truth row"):
            b.record(s, bad)


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
