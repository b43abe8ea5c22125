"""Missions in the frames other ground stations plan in, against real `fcu` and `sitl`
processes: a WPL file written by `gcs mission download --frame global` goes up through
MAVProxy's `wp load` and is flown to the intended points; a local-frame WPL file through
MAVProxy is refused with the reason; QGroundControl's .plan and .params files go up and come
back through `gcs`."""

from __future__ import annotations

import json
import math
import queue
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from common.links import free_port
from common.logs.ulog import read_topic
from common.wire.mavlink import MAV
from common.wire.mission_items import HomePosition
from fcu.params import SPECS
from gcs.mission_files import read_mission
from gcs.mission_files.plan import format_plan, parse_plan
from gcs.mission_files.toml import parse_toml
from gcs.mission_files.wpl import parse_wpl
from gcs.vehicle_link.actions import arm
from gcs.vehicle_link.mission_client import download, home_position
from gcs.vehicle_link.params import param_get, param_set

from .conftest import ROOT, Stack, launch, stop
from .waits import flight_wait

M = MAV
pytestmark = pytest.mark.timeout(240)
MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
DATA = ROOT / "tests" / "data"

# The intended points (local NED, m): arbitrary decimals, off MISSION_ITEM_INT's 1e-7 deg grid.
POINTS = [(1.234, -0.987, -2.5), (-0.8765, 1.4321, -3.1), (0.4321, 0.5678, -2.0)]
MISSION_TOML = f"""format = "dqflight-mission-1"

[[item]]
type = "takeoff"
altitude_ned_z_m = -2.5

[[item]]
type = "waypoint"
position_ned_m = {list(POINTS[0])}
hold_s = 4.0

[[item]]
type = "waypoint"
position_ned_m = {list(POINTS[1])}
hold_s = 4.0

[[item]]
type = "loiter"
position_ned_m = {list(POINTS[2])}
time_s = 4.0

[[item]]
type = "land"
"""


@dataclass
class Rig:
    stack: Stack
    cli_connect: str
    mavproxy_port: int
    tmp: Path

    def gcs(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "gcs.cli", *args, "--connect",
                               self.cli_connect], cwd=ROOT, capture_output=True, text=True,
                              timeout=timeout, check=False)


@pytest.fixture
def rig(tmp_path) -> Iterator[Rig]:
    """sitl (mission_tour: on the ground, lockstep) and fcu with three GCS links: the test's
    Session, the `gcs` command line and MAVProxy."""
    cli, mav = free_port(), free_port()
    stack = launch(tmp_path, "mission_tour", fcu_args=(
        "--gcs", f"udpout:127.0.0.1:{cli}", "--gcs", f"udpout:127.0.0.1:{mav}"))
    try:
        yield Rig(stack, f"udpin:127.0.0.1:{cli}", mav, tmp_path)
    finally:
        stack.session.close()
        stop(stack.procs)


class MavProxy:
    """MAVProxy (the pip package) without a terminal: commands on stdin once the vehicle is
    online, output collected line by line."""

    def __init__(self, port: int, cwd: Path) -> None:
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        self.proc = subprocess.Popen(
            [sys.executable, str(MAVPROXY), f"--master=udpin:127.0.0.1:{port}", "--no-state"],
            cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._queue.put(line.rstrip("\n"))

    def wait_for(self, pattern: str, timeout: float = 30.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self._queue.get(timeout=0.1)
            except queue.Empty:
                continue
            self.lines.append(line)
            if re.search(pattern, line):
                return line
        raise AssertionError(f"MAVProxy never said {pattern!r}; it said:\n" +
                             "\n".join(self.lines))

    def command(self, text: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=3)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=10)


def _mavproxy_load(rig: Rig, path: Path, answer: str) -> MavProxy:
    mp = MavProxy(rig.mavproxy_port, rig.tmp)
    try:
        mp.wait_for(r"online system 1")
        mp.command(f"wp load {path}")
        mp.wait_for(answer)
    except BaseException:
        mp.close()
        raise
    return mp


def _holds(onboard: Path, min_s: float) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(duration, desired, actual position at its end) of every stretch of at least min_s
    over which the desired position stands still, in NED (from `dq_onboard`, ENU)."""
    cols, rows = read_topic(str(onboard), "dq_onboard")
    c = {k: i for i, k in enumerate(cols)}
    t = rows[:, c["time_us"]] * 1e-6
    enu_to_ned = [1, 0, 2]
    sign = np.array([1.0, 1.0, -1.0])
    p = rows[:, [c["px"], c["py"], c["pz"]]][:, enu_to_ned] * sign
    pd = rows[:, [c["pdx"], c["pdy"], c["pdz"]]][:, enu_to_ned] * sign
    still = np.r_[False, np.all(np.diff(pd, axis=0) == 0.0, axis=1)]
    out, start = [], None
    for k in range(len(t) + 1):
        if k < len(t) and still[k]:
            start = k - 1 if start is None else start
            continue
        if start is not None and t[k - 1] - t[start] >= min_s:
            out.append((t[k - 1] - t[start], pd[k - 1], p[k - 1]))
        start = None
    return out


def _key(item) -> tuple:
    return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in item)


@pytest.mark.timeout(1200)  # a ceiling: the flight is waited for while it advances
def test_global_wpl_through_mavproxy_is_flown_to_the_intended_points(rig):
    """Given a local mission (points off the 1e-7 deg grid), when `gcs mission download
    --frame global` writes it as WPL and MAVProxy's `wp load` uploads that file, then the
    vehicle takes it unchanged (global frame, the file's integers), flies it, and at the end
    of each hold stands within 1 cm of the intended point."""
    src = rig.tmp / "local.toml"
    src.write_text(MISSION_TOML)
    assert rig.gcs("mission", "upload", str(src)).returncode == 0
    wpl = rig.tmp / "mission.waypoints"
    out = rig.gcs("mission", "download", "--frame", "global", str(wpl))
    assert out.returncode == 0, out.stderr
    written = parse_wpl(wpl.read_text())
    assert [it.frame for it in written] == [M.MAV_FRAME_GLOBAL_RELATIVE_ALT] * 5
    assert rig.gcs("mission", "clear").returncode == 0

    mp = _mavproxy_load(rig, wpl, r"MISSION_ACK.*ACCEPTED")
    mp.close()
    s = rig.stack.session
    t, c = s.target_system, s.target_component
    held = download(s.conn, t, c, send=s.send)
    assert [(h.frame, h.command, h.x, h.y, h.z) for h in held] == \
        [(w.frame, w.command, w.x, w.y, w.z) for w in written]

    value, _ = param_set(s, "MIS_CRUISE_SPD", 0.5)  # gentle legs: holds settle in time
    assert value == 0.5
    assert s.command(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_ACCEPTED
    assert arm(s, True) == M.MAV_RESULT_ACCEPTED
    # a budget in the flight's time (the mission flies in 32 s), not in the wall clock's
    flight_wait(rig.stack, ["MISSION_CURRENT"],
                lambda m: m.mission_state == M.MISSION_STATE_COMPLETE,
                "the mission's completion", within_s=90.0)
    stop(rig.stack.procs)  # the onboard log is complete once the FCU has stopped

    holds = _holds(rig.tmp / "onboard.ulg", min_s=3.0)
    for point in POINTS:
        near = [(dur, d, a) for dur, d, a in holds if math.dist(d, point) < 0.01]
        assert near, f"no hold at {point}: holds at {[list(d) for _, d, _ in holds]}"
        _, desired, actual = near[0]
        assert math.dist(actual, point) < 0.01, (point, desired, actual)


def test_local_wpl_through_mavproxy_is_refused_with_the_reason(rig):
    """Given a local-frame WPL file (as the README used to describe them), when MAVProxy
    loads it (x, y scaled by 1e7), then the vehicle answers MAV_MISSION_DENIED and says why
    in a STATUSTEXT that MAVProxy prints, and the previous mission stays."""
    src = rig.tmp / "local.toml"
    src.write_text(MISSION_TOML)
    assert rig.gcs("mission", "upload", str(src)).returncode == 0
    wpl = rig.tmp / "local.waypoints"
    assert rig.gcs("mission", "download", str(wpl)).returncode == 0
    assert {it.frame for it in parse_wpl(wpl.read_text())} == {M.MAV_FRAME_LOCAL_NED}

    mp = _mavproxy_load(rig, wpl, r"MISSION_ACK.*DENIED")
    mp.close()
    # MAVProxy prints each STATUSTEXT chunk on its own "AP:" line
    said = " ".join(" ".join(line.split("AP: ", 1)[1] for line in mp.lines
                             if "AP: " in line).split())
    assert "item 1: x 1234 m, y -987 m, beyond the geofence (1000 m)" in said, said
    assert "scaled by 1e7 (MAVProxy)? use a global frame" in said, said
    s = rig.stack.session
    kept = download(s.conn, s.target_system, s.target_component, send=s.send)
    mission = parse_toml(MISSION_TOML)
    assert [(k.frame, k.x, k.y) for k in kept] == [(i.frame, i.x, i.y) for i in mission]
    assert [k.z for k in kept] == pytest.approx([i.z for i in mission], abs=1e-6)  # float32


def test_qgc_plan_round_trips_through_gcs(rig):
    """Given QGroundControl's plan (tests/data), when `gcs mission upload` sends it and
    `gcs mission download` writes a .plan, then the items come back as they were (global
    frame, same integers), the home is the planned home, and --frame local gives the local
    mission in TOML."""
    plan = DATA / "qgc_mission.plan"
    up = rig.gcs("mission", "upload", str(plan))
    assert up.returncode == 0 and "5 items: MAV_MISSION_ACCEPTED" in up.stdout, up.stderr
    back = rig.tmp / "back.plan"
    out = rig.gcs("mission", "download", str(back))
    assert out.returncode == 0, out.stderr
    sent = read_mission(plan)
    got = parse_plan(back.read_text())
    assert [_key(g) for g in got] == [_key(s) for s in sent]
    s = rig.stack.session
    home = home_position(s.conn, s.target_system, s.target_component, send=s.send)
    assert home == HomePosition(47.397742, 8.545594, 488.0)
    assert back.read_text() == format_plan(got, home)
    assert json.loads(back.read_text())["mission"]["plannedHomePosition"] == list(home)
    again = rig.gcs("mission", "upload", str(back))
    assert again.returncode == 0, again.stdout + again.stderr

    local = rig.tmp / "local.toml"
    assert rig.gcs("mission", "download", "--frame", "local", str(local)).returncode == 0
    types = [line for line in local.read_text().splitlines() if line.startswith("type")]
    # QGC's loiter carries p4 = null (NaN), which the readable loiter has no key for: raw
    assert types == ['type = "takeoff"', 'type = "waypoint"', 'type = "waypoint"',
                     'type = "raw"', 'type = "land"']
    wp = parse_toml(local.read_text())[1]
    assert math.hypot(wp.x_m - 2.2153, wp.y_m - 1.7633) < 0.01 and wp.z == -3.0


def test_params_save_and_load_in_qgc_format(rig):
    """`gcs param save` writes every parameter as QGC does; `gcs param load` sets each one
    of a file and reports the refusals with the vehicle's reason (exit status 1)."""
    saved = rig.tmp / "vehicle.params"
    out = rig.gcs("param", "save", str(saved))
    assert out.returncode == 0 and f"saved {len(SPECS)} parameters" in out.stdout, out.stderr
    text = saved.read_text()
    assert text.startswith("# Onboard parameters for Vehicle 1\n#\n# Stack: ")
    assert "# Vehicle-Id Component-Id Name Value Type\n" in text
    assert "\n1\t1\tMIS_CRUISE_SPD\t2.000000000000000000\t9\n" in text
    edited = rig.tmp / "edited.params"
    edited.write_text(text.replace("MIS_CRUISE_SPD\t2.000000000000000000",
                                   "MIS_CRUISE_SPD\t3.5")
                      .replace("GF_MAX_DIST\t1000.000000000000000000", "GF_MAX_DIST\t0.5"))
    out = rig.gcs("param", "load", str(edited))
    assert out.returncode == 1, out.stdout + out.stderr
    # the vehicle's own reason (its STATUSTEXT) follows the refusal
    assert "GF_MAX_DIST = 0.5: vehicle: GF_MAX_DIST refused: 0.5 not in [1, 100000]" in \
        out.stdout, out.stdout
    assert f"loaded {len(SPECS) - 1} of {len(SPECS)}" in out.stdout, out.stdout
    s = rig.stack.session
    assert param_get(s, "MIS_CRUISE_SPD") == 3.5
    assert param_get(s, "GF_MAX_DIST") == 1000.0
    assert rig.gcs("param", "load", str(saved)).returncode == 0
    assert param_get(s, "MIS_CRUISE_SPD") == 2.0
