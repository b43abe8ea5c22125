"""Lockstep runs through the three processes: the same flight as in-process, over TCP as
over UDP, paced by the wall clock when asked, and a repeated state answered from store.
(Loss on the simulator link, which changes the timing and not one byte of the flight:
tests/sitl/test_lossy_lockstep.py.)"""

from __future__ import annotations

import dataclasses
import json
import math
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.links import free_port
from common.logs.ulog import read_topic
from common.wire.mavlink import MAV
from common.wire.simlink import (
    HIL_ACTUATOR_CONTROLS_ID,
    Odometry,
    pack_odometry,
    split_frames,
    unpack_actuator_controls,
)
from fcu.reference.trajectory import FigureEight
from gcs.run.process_run import run_processes
from gcs.run.scenario_mission import scenario_mission
from gcs.vehicle_link.mission_client import upload

from .. import reference_runs
from .conftest import ROOT, SCENARIOS, launch, stop
from .waits import file_size, run_progressing, sched_s

M = MAV
CASE1 = SCENARIOS / "case1_figure8.toml"


def _gcs_run(out, *extra):
    """`gcs run` of Case I, waited for while its truth log grows (at a load of 8 on 2 cores
    the 160 s lockstep flight took over 10 minutes: slower, never different)."""
    return run_progressing([sys.executable, "-m", "gcs.cli", "run", str(CASE1), "--out",
                            str(out), *extra], lambda: file_size(out / "truth.ulg"),
                           f"gcs run {CASE1.name}", cwd=ROOT)


def _within(ours: float, ref: float, floor: float) -> bool:
    return abs(ours - ref) <= max(0.05 * abs(ref), floor)


@pytest.mark.timeout(3600)  # a ceiling: the run is judged by its progress (_gcs_run)
@pytest.mark.xdist_group(reference_runs.GROUP)
def test_case1_through_processes_matches_in_process(tmp_path):
    """Given `gcs run case1_figure8.toml` (lockstep, UDP), then the mission completes and the
    errors are within 5 % (or 1 mm / 0.1 mrad) of the in-process run; the FCU's desired
    trajectory for the uploaded mission equals the in-process Case I trajectory."""
    out = tmp_path / "run"
    proc = _gcs_run(out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["mission_completed"] is True and m["lockstep"] is True
    assert m["transport"] == "udp" and m["status"] == "completed"
    assert m["sim_time_s"] == pytest.approx(160.0)
    ref = reference_runs.case1_metrics()
    for stat in ("max", "mean", "rmse"):
        assert _within(m["position_error_m"][stat], ref["position_error_m"][stat], 1e-3)
        assert _within(m["attitude_error_rad"][stat], ref["attitude_error_rad"][stat], 1e-4)

    columns, onboard = read_topic(out / "onboard.ulg", "dq_onboard")
    assert len(onboard) == 80001
    traj = FigureEight(load_scenario(CASE1).trajectory)
    idx = [columns.index(c) for c in ("pdx", "pdy", "pdz", "qdw", "qdx", "qdy", "qdz",
                                      "vdx", "vdy", "vdz", "wdx", "wdy", "wdz")]
    worst = 0.0
    for row in onboard:
        r = traj.sample(row[0] * 1e-6)
        expected = (*r.p_enu_m, *r.q_enu_flu, *r.v_enu_m_s, *r.omega_flu_rad_s)
        worst = max(worst, float(np.max(np.abs(row[idx] - expected))))
    assert worst < 1e-9
    assert (out / "flight.tlog").stat().st_size > 10_000


def test_repeated_state_gets_the_stored_answer(tmp_path):
    """A state the FCU has answered is answered again with the same bytes, without a new
    control step; a stale state is not answered; time stands still until the flight starts."""
    sim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sim.bind(("127.0.0.1", 0))
    sim.settimeout(0.5)
    stack = launch(tmp_path, sitl=False, sim_port=sim.getsockname()[1])
    try:
        s = stack.session

        def frame(t_us):
            odo = Odometry(t_us, (-1.0, 0.0, -2.0), (math.sqrt(0.5), 0, 0, math.sqrt(0.5)),
                           (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            return pack_odometry(odo, 0, 1, 200)

        def state(t_us):
            sim.sendto(frame(t_us), fcu_addr[0])

        def answer():
            try:
                while True:
                    data, _ = sim.recvfrom(65535)
                    frames, _ = split_frames(data)
                    for f in frames:
                        if f.msg_id == HIL_ACTUATOR_CONTROLS_ID:
                            return f.raw
            except TimeoutError:
                return None

        # The FCU's simulator link is udpout towards us from an ephemeral port that it
        # prints at start-up; states go there, answers come back to us.
        fcu_addr = [None]
        deadline = time.monotonic() + 5
        while fcu_addr[0] is None and time.monotonic() < deadline:
            for line in stack.log("fcu").splitlines():
                if "sim port" in line:
                    fcu_addr[0] = ("127.0.0.1", int(line.rsplit(" ", 1)[1]))
            time.sleep(0.05)
        assert fcu_addr[0] is not None, stack.log("fcu")
        state(0)
        assert answer() is None  # disarmed, flight not started: simulated time stands still
        sc = load_scenario(SCENARIOS / "case2_impulse.toml")
        result = upload(s.conn, s.target_system, s.target_component, scenario_mission(sc),
                        send=s.send)
        assert result == M.MAV_MISSION_ACCEPTED
        assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        assert s.command(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_ACCEPTED
        state(0)
        first = answer()
        assert first is not None
        state(0)
        again = answer()
        assert again == first  # byte for byte, sequence number included
        state(2000)
        second = answer()
        assert second is not None and second != first
        t = unpack_actuator_controls(split_frames(second)[0][0].payload).time_usec
        assert t == 2000
        state(0)  # stale
        assert answer() is None
        # A state and its re-send in one read (a TCP stream coalesces them under load):
        # stepped once, so both answers are the same bytes, sequence number included.
        sim.sendto(frame(4000) * 2, fcu_addr[0])
        third, fourth = answer(), answer()
        assert third is not None and third == fourth
        assert unpack_actuator_controls(split_frames(third)[0][0].payload).time_usec == 4000
    finally:
        stack.session.close()
        stop(stack.procs)
        sim.close()


def test_control_port_argument_is_validated():
    """A wrong link URL is refused at start-up with a clear message."""
    proc = subprocess.run([sys.executable, "-m", "fcu.edge.node", "--vehicle",
                           str(ROOT / "config/vehicles/hexa_tilted.toml"), "--gains",
                           str(ROOT / "config/gains/pid_eq30.toml"), "--sim",
                           f"udpx:127.0.0.1:{free_port()}"], cwd=ROOT, capture_output=True,
                          text=True, timeout=30, check=False)
    assert proc.returncode == 2 and "udpx" in proc.stderr


def test_tcp_simulator_link_flies_the_same_run(tmp_path):
    """The simulator link over TCP (stream framing) gives the figures of the UDP run."""
    scenario = dataclasses.replace(load_scenario(CASE1), duration_s=6.0)
    udp = run_processes(scenario, tmp_path / "udp")
    tcp = run_processes(scenario, tmp_path / "tcp", transport="tcp")
    assert tcp["transport"] == "tcp" and tcp["status"] == "completed"
    for key in ("position_error_m", "attitude_error_rad", "samples", "sim_time_s"):
        assert tcp[key] == udp[key]


def test_udp_rtt_is_measured_between_the_two_processes(tmp_path):
    """Given a lockstep run through processes over UDP, then metrics.json has the simulator
    link's round trip as timed between the FCU and the SITL before the flight: every
    TIMESYNC probe answered by the SITL process (some late on a busy machine: they are
    counted, not timed), at most the probes asked for within the probe's 1 s, a median
    that is positive, finite and below 100 ms with a spread (measured, not a constant), and
    the step's wall time and its ratio to that round trip beside it."""
    from gcs.run.process_run import RTT_PROBES

    scenario = dataclasses.replace(load_scenario(CASE1), duration_s=2.0)
    m = run_processes(scenario, tmp_path / "run")
    assert m["status"] == "completed"
    rtt = m["fcu"]["sim_rtt"]
    assert 100 <= rtt["samples"] <= RTT_PROBES and rtt["lost"] == 0
    # the other process answered every probe sent
    assert m["sitl"]["timesync_answers"] == rtt["samples"] + rtt["late"]
    assert m["udp_rtt_us"] == m["link_rtt_us"] == rtt["median_us"]
    # in microseconds: a loopback round trip is tens of them idle, milliseconds on a machine
    # starved for CPU, never 0.1 s (what nanoseconds taken for microseconds would give)
    assert math.isfinite(m["udp_rtt_us"]) and 0.0 < m["udp_rtt_us"] < 100_000.0
    assert 0.0 < rtt["p10_us"] <= m["udp_rtt_us"] <= rtt["p90_us"]
    assert rtt["p10_us"] < rtt["p90_us"]
    assert m["step_wall_us"] == pytest.approx(m["wall_time_s"] / m["samples"] * 1e6)
    assert m["step_per_rtt"] == pytest.approx(m["step_wall_us"] / m["udp_rtt_us"])
    for proc, stages in (("fcu", ("wait", "rx", "step", "tx", "log", "housekeeping")),
                         ("sitl", ("wait", "rx", "plant", "pack", "send", "log"))):
        got = m["step_stages_us"][proc]
        assert set(got) == set(stages) and all(v >= 0.0 for v in got.values())
    saved = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert saved["udp_rtt_us"] == m["udp_rtt_us"]
    # Both processes loaded their kernels before their loops ran, and say how long it took.
    assert 0.0 < m["fcu"]["compile_time_s"] < 120.0 and 0.0 < m["sitl"]["compile_time_s"]
    assert m["compile_time_s"] == m["fcu"]["compile_time_s"] + m["sitl"]["compile_time_s"]


def _sim_per_wall(stack, wall_s: float) -> tuple[float, float]:
    """Simulated seconds per wall second over `wall_s`, and the simulated seconds, from the
    FCU's ATTITUDE_QUATERNION (stamped with the flight clock, simulated time in
    lockstep)."""
    points = []
    end = time.monotonic() + wall_s
    while time.monotonic() < end:
        msg = stack.session.recv(["ATTITUDE_QUATERNION"], timeout=1.0)
        if msg is not None:
            points.append((time.monotonic(), msg.time_boot_ms * 1e-3))
    (w0, t0), (w1, t1) = points[0], points[-1]
    return (t1 - t0) / (w1 - w0), t1 - t0


@pytest.mark.parametrize("factor", [1.0, 2.0])
def test_speed_factor_paces_the_lockstep_by_the_wall_clock(tmp_path, factor):
    """Given `sitl --speed-factor X` (dqflight), when Case II's mission flies, then simulated
    time runs at X times the wall clock's pace, no faster, and neither process spins while
    it waits.

    No faster is strict: at most 1.02 X. The pace is judged against the CPU the two
    processes got (/proc schedstat): simulated time runs at 0.8 X or more, or, on a machine
    too busy for that, the processes were running or queued for a CPU for at least 0.8 of
    the wall time: a starved run is slow because it waited for a CPU, a wrongly paced one
    (a factor inverted or applied twice) because it slept. Neither spins: together they
    ran for well under the two cores a free-running lockstep takes (a starved machine
    gives them less, never more)."""
    stats = tmp_path / "sitl_stats.json"
    stack = launch(tmp_path, sitl_args=("--end-time", "3600", "--speed-factor", f"{factor:g}",
                                        "--stats", str(stats)))
    try:
        s = stack.session
        mission = scenario_mission(load_scenario(SCENARIOS / "case2_impulse.toml"))
        assert upload(s.conn, s.target_system, s.target_component, mission, send=s.send) == 0
        assert s.command(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1) == MAV.MAV_RESULT_ACCEPTED
        assert s.command(MAV.MAV_CMD_MISSION_START) == MAV.MAV_RESULT_ACCEPTED
        _sim_per_wall(stack, 0.5)  # under way
        sched0 = {name: sched_s(p.pid) for name, p in stack.procs.items()}
        t0 = time.monotonic()
        rate, sim_s = _sim_per_wall(stack, 3.0)
        wall_s = time.monotonic() - t0
        sched = {name: np.subtract(sched_s(p.pid), sched0[name])
                 for name, p in stack.procs.items()}
    finally:
        stack.session.close()
        stop(stack.procs)
    busy = sum(ran + queued for ran, queued in sched.values()) / wall_s
    print(f"\nx{factor:g}: {rate:.3f} of the wall clock, busy {busy:.2f}; {sched}")
    assert rate <= 1.02 * factor, rate
    assert sim_s > 0.0, "simulated time stood still"
    assert rate >= 0.8 * factor or busy >= 0.8, \
        f"{rate:.3f} x real time, the processes busy for {busy:.2f} of the wall time"
    cores = sum(ran for ran, _ in sched.values()) / wall_s
    assert cores < 1.0, f"{cores:.2f} cores at {factor:g} x real time"
    # the wait for the wall clock is not the plant's time (a period is 2 ms / X)
    assert json.loads(stats.read_text())["stage_us"]["plant"] < 500.0

