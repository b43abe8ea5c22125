"""ArduCopter on this plant: `arducopter --model JSON:127.0.0.1` with ArduPilot's copter and
hexa parameters and config/ardupilot/hexa_json.parm beside `sitl
config/scenarios/ardupilot_hexa.toml --protocol ardupilot-json`, both inside a private
network namespace. ArduCopter's EKF3 aligns on the plant's IMU and position, it arms in
GUIDED, takes off to 10 m, flies 10 m north and lands, driven over MAVLink with pymavlink
(`drive`, run inside the namespace as `python -m tests.sitl.test_arducopter_on_plant`);
the flight is judged from the plant's truth.ulg.

The flight is skipped with the reason unless $ARDUCOPTER names the binary
(tests/arducopter.py); the `sitl` process is also tested against a scripted ArduPilot side.
"""

from __future__ import annotations

import json
import math
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from common.links import free_port
from common.logs.ulog import read_topic
from tests.arducopter import ROOT, namespace, needs_arducopter, start_arducopter, stop_group

SCENARIO = ROOT / "config" / "scenarios" / "ardupilot_hexa.toml"
PARAMS = ROOT / "config" / "ardupilot" / "hexa_json.parm"
SPEEDUP = 20  # ArduCopter asks for 20x real time; the pair runs as fast as the slower allows
GUIDED, LAND = 4, 9
ALT_M, NORTH_M = 10.0, 10.0
# read back to show that hexa_json.parm was loaded over ArduPilot's own files
CHECKED_PARAMS = ("FRAME_TYPE", "MOT_PWM_MIN", "MOT_BAT_VOLT_MAX", "ATC_RAT_YAW_P")


# ------------------------------------------------------------------ the MAVLink side


class Copter:
    """ArduCopter over MAVLink: the last message of each kind, the texts and heights seen."""

    def __init__(self, url: str, timeout_s: float) -> None:
        from pymavlink import mavutil

        self.mav = mavutil.mavlink
        self.conn = mavutil.mavlink_connection(url, source_system=245,
                                               dialect="ardupilotmega")
        self.timeout_s = timeout_s
        self.deadline = time.monotonic() + timeout_s
        hb = self.conn.wait_heartbeat(timeout=timeout_s)
        if hb is None:
            raise RuntimeError("no HEARTBEAT from ArduCopter")
        self.sysid, self.compid = hb.get_srcSystem(), hb.get_srcComponent()
        self.out: dict[str, Any] = {"texts": [], "heights": []}
        self.seen: dict[str, Any] = {}

    def pump(self, wait_s: float = 0.2) -> None:
        if time.monotonic() > self.deadline:
            raise TimeoutError(f"flight not done within {self.timeout_s:g} s: {self.out}")
        msg = self.conn.recv_match(blocking=True, timeout=wait_s)
        while msg is not None:
            kind = msg.get_type()
            self.seen[kind] = msg
            if kind == "LOCAL_POSITION_NED":  # EKF3's height, on ArduPilot's clock
                self.out["heights"].append((msg.time_boot_ms, -msg.z))
            if kind == "STATUSTEXT":
                self.out["texts"].append(msg.text)
            msg = self.conn.recv_match(blocking=False)

    def boot_s(self) -> float:
        st = self.seen.get("SYSTEM_TIME")
        return st.time_boot_ms * 1e-3 if st is not None else math.nan

    def until(self, cond: Any, what: str, limit_s: float = 60.0) -> None:
        end = time.monotonic() + limit_s
        while not cond():
            if time.monotonic() > end:
                raise TimeoutError(f"{what} not within {limit_s:g} s; last texts "
                                   f"{self.out['texts'][-5:]}")
            self.pump()

    def command(self, cmd: int, *params: float) -> None:
        p = [*params, *([0.0] * (7 - len(params)))]
        self.conn.mav.command_long_send(self.sysid, self.compid, cmd, 0, *p)

    def mode_is(self, number: int) -> bool:
        h = self.seen.get("HEARTBEAT")
        return h is not None and h.get_srcSystem() == self.sysid and h.custom_mode == number

    def armed(self) -> bool:
        h = self.seen.get("HEARTBEAT")
        return h is not None and bool(h.base_mode & self.mav.MAV_MODE_FLAG_SAFETY_ARMED)

    def set_mode(self, number: int, what: str) -> None:
        self.command(self.mav.MAV_CMD_DO_SET_MODE, self.mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                     number)
        self.until(lambda: self.mode_is(number), what)

    def ekf_ready(self) -> bool:
        mav = self.mav
        need = mav.EKF_PRED_POS_HORIZ_ABS | mav.EKF_POS_HORIZ_ABS | mav.EKF_VELOCITY_HORIZ
        e = self.seen.get("EKF_STATUS_REPORT")
        return e is not None and e.flags & need == need and not e.flags & mav.EKF_UNINITIALIZED

    def there(self) -> bool:
        """At NORTH_M north, ALT_M up, nearly still (the target sent again each time)."""
        mav = self.mav
        ignore = (mav.POSITION_TARGET_TYPEMASK_VX_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_VY_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_VZ_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_AX_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_AY_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_YAW_IGNORE
                  | mav.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)
        p = self.seen["LOCAL_POSITION_NED"]
        self.conn.mav.set_position_target_local_ned_send(
            0, self.sysid, self.compid, mav.MAV_FRAME_LOCAL_NED, ignore, NORTH_M, 0, -ALT_M,
            0, 0, 0, 0, 0, 0, 0, 0)
        return (math.hypot(p.x - NORTH_M, p.y) < 0.3 and abs(p.z + ALT_M) < 0.3
                and math.sqrt(p.vx ** 2 + p.vy ** 2 + p.vz ** 2) < 0.2)


def _telemetry_and_params(c: Copter) -> None:
    """Position and time at their rates; CHECKED_PARAMS read back."""
    mav = c.mav
    for msg_id in (mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mav.MAVLINK_MSG_ID_SYSTEM_TIME,
                   mav.MAVLINK_MSG_ID_EKF_STATUS_REPORT):
        c.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id,
                  20_000 if msg_id == mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED else 100_000)
    c.until(lambda: "SYSTEM_TIME" in c.seen and "LOCAL_POSITION_NED" in c.seen, "telemetry")
    c.out["params"] = {}
    for name in CHECKED_PARAMS:
        c.seen.pop("PARAM_VALUE", None)
        c.conn.mav.param_request_read_send(c.sysid, c.compid, name.encode(), -1)
        c.until(lambda name=name: getattr(c.seen.get("PARAM_VALUE"), "param_id", "") == name,
                f"parameter {name}", 10.0)
        c.out["params"][name] = c.seen["PARAM_VALUE"].param_value


def _arm(c: Copter) -> None:
    """GUIDED, then arm once the EKF is ready (the pre-arm checks pass a little after)."""
    c.set_mode(GUIDED, "GUIDED")
    c.until(c.ekf_ready, "EKF3 position estimate", 60.0)
    c.out["ekf_ready_s"] = c.boot_s()
    last_try = 0.0
    while not c.armed():
        if time.monotonic() - last_try > 1.0:
            c.command(c.mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            last_try = time.monotonic()
        c.pump()
    c.out["armed_s"] = c.boot_s()


def drive(url: str, timeout_s: float) -> dict[str, Any]:
    """Fly ArduCopter over `url`: GUIDED, arm once the EKF lets it, take off to ALT_M, fly
    NORTH_M north, land, wait for the disarm. Returns what it saw, ArduPilot's boot times in
    seconds (its simulated clock)."""
    c = Copter(url, timeout_s)
    _telemetry_and_params(c)
    _arm(c)
    c.command(c.mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, ALT_M)
    c.until(lambda: -c.seen["LOCAL_POSITION_NED"].z > ALT_M - 0.3, "takeoff to 10 m")
    c.out["at_altitude_s"] = c.boot_s()
    c.until(c.there, "10 m north")
    c.out["north_s"] = c.boot_s()
    c.set_mode(LAND, "LAND")
    c.until(lambda: not c.armed(), "landed and disarmed", 90.0)
    c.out["disarmed_s"] = c.boot_s()
    c.out["texts"] = c.out["texts"][-20:]
    return c.out


# ------------------------------------------------------------------ the test


def _truth(path: Path) -> dict[str, np.ndarray]:
    names, rows = read_topic(path, "dq_truth")
    return {name: rows[:, i] for i, name in enumerate(names)}


@pytest.mark.timeout(60)
def test_sitl_process_serves_a_scripted_arducopter(tmp_path: Path) -> None:
    """`sitl --protocol ardupilot-json --end-time 1`: serves a scripted ArduPilot side on
    loopback, stops 1 s of simulated time after the first packet, exit 0, with its stats,
    summary line and truth log."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "sitl.node", str(SCENARIO), "--protocol", "ardupilot-json",
         "--link", f"udpin:127.0.0.1:{port}", "--end-time", "1", "--truth-log",
         str(tmp_path / "truth.ulg"), "--stats", str(tmp_path / "stats.json")],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith(
            f"sitl: serving ardupilot_hexa on udpin:127.0.0.1:{port} (ardupilot-json")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as ap:
            ap.settimeout(2.0)
            n = 0
            with pytest.raises(TimeoutError):  # no answer once the plant has stopped
                while n < 2000:
                    ap.sendto(struct.pack("<HHI16H", 18458, 1200, n, *(1000,) * 16),
                              ("127.0.0.1", port))
                    ap.recv(4096)
                    n += 1
        assert n == 1201  # 1201 steps of 833 us reach 1 s
        assert proc.wait(20) == 0
        out = proc.stdout.read()
    finally:
        stop_group(proc)
    assert "sitl: stopped at t = 1.000 s after 1201 frames at 1200 Hz (833 us steps)" in out
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["steps"] == 1201 and stats["bad_packets"] == 0
    _, rows = read_topic(tmp_path / "truth.ulg", "dq_truth")
    assert len(rows) == 1201 and rows[-1, 0] == 1201 * 833


@needs_arducopter
@pytest.mark.xdist_group("arducopter")
@pytest.mark.timeout(240)
def test_arducopter_flies_on_the_plant(tmp_path: Path) -> None:
    truth_path = tmp_path / "truth.ulg"
    stats_path = tmp_path / "stats.json"
    with namespace() as ns:
        sitl_log = (tmp_path / "sitl.log").open("wb")
        sitl = ns.popen([sys.executable, "-m", "sitl.node", SCENARIO, "--protocol",
                         "ardupilot-json", "--truth-log", truth_path, "--stats", stats_path],
                        cwd=ROOT, stdout=sitl_log, stderr=subprocess.STDOUT)
        sitl_log.close()
        deadline = time.monotonic() + 60
        while b"sitl: serving" not in (tmp_path / "sitl.log").read_bytes():
            assert sitl.poll() is None, (tmp_path / "sitl.log").read_text()
            assert time.monotonic() < deadline, "sitl did not start serving"
            time.sleep(0.05)
        start_arducopter(ns, tmp_path / "ardupilot", model="JSON:127.0.0.1", speedup=SPEEDUP,
                         defaults=[PARAMS])
        done = ns.run([sys.executable, "-m", "tests.sitl.test_arducopter_on_plant",
                       "tcp:127.0.0.1:5760", "150"], cwd=ROOT, capture_output=True,
                      text=True, timeout=180, check=False)
        stop_group(sitl)
    assert done.returncode == 0, done.stdout + done.stderr
    flight = json.loads(done.stdout.strip().splitlines()[-1])
    stats = json.loads(stats_path.read_text())
    print(json.dumps({"flight": flight, "sitl": stats}))
    assert stats["frame_rate_hz"] == 1200 and stats["step_us"] == 833
    assert stats["bad_packets"] == 0 and stats["reboots"] == 0
    ours = dict(line.split()[:2] for line in PARAMS.read_text().splitlines()
                if line.strip() and not line.startswith("#"))
    for name, value in flight["params"].items():
        assert value == pytest.approx(float(ours[name]), rel=1e-6), name

    t = _truth(truth_path)
    up, north, east = t["pz"], t["py"], t["px"]
    # the EKF aligned on the plant's IMU and the vehicle sat on the ground until armed
    assert flight["ekf_ready_s"] < 60.0
    assert float(np.max(up)) > ALT_M - 0.5 and float(np.max(up)) < ALT_M + 1.5
    climb = int(np.argmax(up > ALT_M - 0.5))
    assert math.hypot(north[climb], east[climb]) < 1.0  # took off straight up
    # the descent starts where it was sent: 10 m north, within 1.5 m
    top = np.flatnonzero(up > ALT_M - 1.0)[-1]
    assert math.hypot(north[top] - NORTH_M, east[top]) < 1.5, (north[top], east[top])
    # landed there, softly (the speed at the first contact after the last half metre), and
    # stayed: disarmed, the rotors stopped
    low = np.flatnonzero(up > 0.5)[-1]
    touchdown = low + int(np.argmax(t["landed"][low:] == 1.0))
    assert t["landed"][touchdown] == 1.0 and t["landed"][-1] == 1.0
    assert abs(t["vz"][touchdown - 1]) < 1.0, t["vz"][touchdown - 1]
    assert math.hypot(north[-1] - NORTH_M, east[-1]) < 1.5, (north[-1], east[-1])
    assert all(t[f"rotor{i}"][-1] < 1.0 for i in range(6))
    # EKF3's height within 0.2 m of the truth at equal times (ArduPilot's clock is the
    # plant's: the JSON interface stamps each state), from the EKF's alignment through the
    # touchdown to the disarm
    ms = np.array(flight["heights"], dtype=float)
    keep = (ms[:, 0] >= flight["armed_s"] * 1e3) & (ms[:, 0] <= flight["disarmed_s"] * 1e3)
    when_s, ekf_up = ms[keep, 0] * 1e-3, ms[keep, 1]
    truth_up = np.interp(when_s, t["time_us"] * 1e-6, up)
    height_error = float(np.max(np.abs(ekf_up - truth_up)))
    assert len(when_s) > 500 and height_error < 0.2, height_error
    print(json.dumps({"max_alt_m": float(np.max(up)), "ekf_height_error_m": height_error,
                      "descent_start_error_m": math.hypot(north[top] - NORTH_M, east[top]),
                      "final_error_m": math.hypot(north[-1] - NORTH_M, east[-1]),
                      "touchdown_m_s": float(t["vz"][touchdown - 1])}))


if __name__ == "__main__":
    print(json.dumps(drive(sys.argv[1], float(sys.argv[2]))), flush=True)
