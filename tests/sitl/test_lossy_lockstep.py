"""Lockstep through a lossy simulator link: loss, duplication and reordering change the
timing of a run, never its results (README, Lockstep)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.logs.ulog import read_topic
from gcs.run.process_run import run_processes

from ..udp_proxy import Impairment, UdpProxy
from .conftest import SCENARIOS

CASE1 = SCENARIOS / "case1_figure8.toml"


def _lossy_run(scenario, out, seed: int) -> tuple[dict, dict[str, int]]:
    """The run through a proxy on the simulator link that drops 10 % of the datagrams both
    ways, duplicates 5 % and holds 5 % back; its metrics and the proxy's counts. No
    wall-clock limit: a lockstep run whose clock stands still for STALL_S ends (a
    deadlock fails the run), one that advances slowly on a loaded machine is the same
    flight."""
    proxies: list[UdpProxy] = []

    def route(port: int) -> int:
        proxy = UdpProxy(port, Impairment(drop=0.10, duplicate=0.05, reorder=0.05), seed=seed)
        proxies.append(proxy)
        return proxy.port

    try:
        metrics = run_processes(scenario, out, sim_route=route)
    finally:
        for p in proxies:
            p.close()
    return metrics, proxies[0].counts


@pytest.mark.timeout(1800)  # a ceiling: the runs are judged by their progress (STALL_S)
def test_ten_percent_loss_with_duplication_and_reordering_gives_the_same_flight(tmp_path):
    """Case I's first 30 s with 10 % of the simulator link's datagrams dropped both ways,
    5 % duplicated and 5 % held back behind the next ones: no deadlock, and exactly the
    loss-free run's figures, samples, truth log and onboard log (but its step times). (Two
    lockstep runs are one flight: the same bytes whatever the link does to their timing.)"""
    scenario = dataclasses.replace(load_scenario(CASE1), duration_s=30.0)
    t0 = time.monotonic()
    clean = run_processes(scenario, tmp_path / "clean")
    t1 = time.monotonic()
    lossy, counts = _lossy_run(scenario, tmp_path / "lossy", seed=11)
    t2 = time.monotonic()
    print(f"\nclean {t1 - t0:.1f} s, lossy {t2 - t1:.1f} s of wall time; proxy {counts}; "
          f"fcu {lossy['fcu']}")
    assert counts["dropped"] > 1000 and counts["duplicated"] > 500
    assert counts["reordered"] > 500
    assert lossy["status"] == "completed" and lossy["sim_time_s"] == pytest.approx(30.0)
    for key in ("position_error_m", "attitude_error_rad", "samples", "sim_time_s"):
        assert lossy[key] == clean[key], key
    assert lossy["fcu"]["resent_answers"] > 0
    assert (tmp_path / "clean" / "truth.ulg").read_bytes() == \
        (tmp_path / "lossy" / "truth.ulg").read_bytes()
    # the FCU's log: every row, every column but the measured step time
    columns, clean_rows = read_topic(tmp_path / "clean" / "onboard.ulg", "dq_onboard")
    _, lossy_rows = read_topic(tmp_path / "lossy" / "onboard.ulg", "dq_onboard")
    keep = [i for i, c in enumerate(columns) if c != "step_us"]
    assert clean_rows.shape == lossy_rows.shape and len(clean_rows) == 15001
    assert np.array_equal(clean_rows[:, keep], lossy_rows[:, keep])


@pytest.mark.timeout(1800)  # a ceiling: the runs are judged by their progress (STALL_S)
def test_loss_with_sensors_gives_the_same_flight(tmp_path):
    """With a sensor profile (HIL_SENSOR per IMU sample, delayed poses, the estimator's
    alignment before the flight) the same impairments change timing, never results: every
    IMU sample and pose is taken once, whatever is lost, duplicated or held back."""
    from common.config.sensors import resolve_sensor_profile

    scenario = dataclasses.replace(load_scenario(CASE1), duration_s=2.5,
                                   sensors=resolve_sensor_profile("mocap-indoor"))
    clean = run_processes(scenario, tmp_path / "clean")
    lossy, counts = _lossy_run(scenario, tmp_path / "lossy", seed=12)
    assert counts["dropped"] > 200 and counts["duplicated"] > 100 and counts["reordered"] > 100
    assert lossy["status"] == clean["status"] == "completed"
    for key in ("position_error_m", "attitude_error_rad", "estimation_error", "samples",
                "sim_time_s", "alignment_s"):
        assert lossy[key] == clean[key], key
    assert (tmp_path / "clean" / "truth.ulg").read_bytes() == \
        (tmp_path / "lossy" / "truth.ulg").read_bytes()
    columns, clean_rows = read_topic(tmp_path / "clean" / "onboard.ulg", "dq_onboard")
    _, lossy_rows = read_topic(tmp_path / "lossy" / "onboard.ulg", "dq_onboard")
    keep = [i for i, c in enumerate(columns) if c != "step_us"]
    assert np.array_equal(clean_rows[:, keep], lossy_rows[:, keep])
