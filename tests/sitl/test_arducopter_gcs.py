"""The ground station against a real ArduCopter SITL with its own physics (`--model hexa`,
speedup 10), inside a private network namespace (tests/arducopter.py).

`gcs` talks on ArduCopter's default link, TCP 5760; an independent pymavlink observer on
its second link (TCP 5762) records what the vehicle really does (HEARTBEAT custom_mode,
armed, position, landed state), so that no check rests on the CLI's own word. One
ArduCopter serves the whole module, one flight after another.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.arducopter import ROOT, namespace, needs_arducopter, start_arducopter, wait_port

pytestmark = [needs_arducopter, pytest.mark.xdist_group("arducopter")]

GCS_PORT, OBSERVER_PORT = 5760, 5762
CONNECT = ("--connect", f"tcp:127.0.0.1:{GCS_PORT}")
# ArduCopter's own mode numbers (custom_mode)
STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, LAND, POSHOLD, BRAKE = 0, 2, 3, 4, 5, 6, 9, 16, 17


def observe(port: int, out: str) -> None:
    """Record the vehicle's HEARTBEAT, LOCAL_POSITION_NED, GLOBAL_POSITION_INT,
    EXTENDED_SYS_STATE and SYS_STATUS as JSON lines (wall time `t`), on a link of its own."""
    import os

    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", dialect="ardupilotmega",
                                      source_system=250, source_component=190)
    conn.wait_heartbeat(timeout=60)
    M = mavutil.mavlink
    for msg_id in (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
                   M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_SYS_STATUS):
        conn.mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 50_000,
                                   0, 0, 0, 0, 0)
    with open(out, "w", buffering=1) as fh:
        while True:
            msg = conn.recv_match(type=["HEARTBEAT", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT",
                                        "EXTENDED_SYS_STATE", "SYS_STATUS"],
                                  blocking=True, timeout=1.0)
            if msg is None or msg.get_srcSystem() != 1 or msg.get_srcComponent() != 1:
                continue
            rec = {"t": time.time(), "type": msg.get_type()}
            kind = msg.get_type()
            if kind == "HEARTBEAT":
                rec.update(mode=msg.custom_mode, armed=bool(msg.base_mode & 128))
            elif kind == "LOCAL_POSITION_NED":
                rec.update(x=msg.x, y=msg.y, z=msg.z)
            elif kind == "GLOBAL_POSITION_INT":
                rec.update(rel=msg.relative_alt * 1e-3, ms=msg.time_boot_ms)
            elif kind == "EXTENDED_SYS_STATE":
                rec.update(landed=msg.landed_state)
            else:
                rec.update(prearm=bool(msg.onboard_control_sensors_health & 0x10000000))
            fh.write(json.dumps(rec) + "\n")


def intervals(port: int, ids: str) -> None:
    """Print {message id: MESSAGE_INTERVAL.interval_us} for the comma-separated ids, as
    ArduCopter answers MAV_CMD_GET_MESSAGE_INTERVAL on the link at TCP `port`."""
    import os

    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", dialect="ardupilotmega",
                                      source_system=249, source_component=190)
    conn.wait_heartbeat(timeout=30)
    M = mavutil.mavlink
    wanted = [int(i) for i in ids.split(",")]
    for msg_id in wanted:
        conn.mav.command_long_send(1, 1, M.MAV_CMD_GET_MESSAGE_INTERVAL, 0, msg_id,
                                   0, 0, 0, 0, 0, 0)
    got: dict[int, int] = {}
    deadline = time.monotonic() + 10
    while len(got) < len(wanted) and time.monotonic() < deadline:
        msg = conn.recv_match(type="MESSAGE_INTERVAL", blocking=True, timeout=1.0)
        if msg is not None:
            got[msg.message_id] = msg.interval_us
    print(json.dumps(got))


class Copter:
    """The running ArduCopter, the gcs CLI inside its namespace, and the observer's log."""

    def __init__(self, ns, log: Path) -> None:
        self.ns = ns
        self.log = log

    def gcs(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
        return self.ns.gcs(*args, *CONNECT, timeout=timeout)

    def records(self, kind: str, since: float = 0.0) -> list[dict]:
        out = []
        for line in self.log.read_text().splitlines():
            try:
                rec = json.loads(line)
            except ValueError:
                continue  # a line being written
            if rec["type"] == kind and rec["t"] >= since:
                out.append(rec)
        return out

    def wait_for(self, kind: str, cond, timeout: float, since: float = 0.0) -> dict:
        """The first record of `kind` after `since` for which cond(record) holds."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for rec in self.records(kind, since):
                if cond(rec):
                    return rec
            time.sleep(0.1)
        last = self.records(kind, since)[-1:] or ["none"]
        raise AssertionError(f"no {kind} record satisfied the condition in {timeout:g} s; "
                             f"last: {last[0]}")

    def mode_after(self, since: float) -> int:
        """custom_mode of the first HEARTBEAT the observer heard after `since`."""
        return self.wait_for("HEARTBEAT", lambda r: True, 5.0, since)["mode"]


@pytest.fixture(scope="module")
def copter(tmp_path_factory):
    work = tmp_path_factory.mktemp("arducopter")
    # ArduCopter disarms a vehicle left armed on the ground after DISARM_DELAY s of its time:
    # at speedup 10 its default 10 s is 1 s of ours, less than starting the next gcs takes
    slower_disarm = work / "disarm.parm"
    slower_disarm.write_text("DISARM_DELAY 60\n")
    with namespace() as ns:
        start_arducopter(ns, work, model="hexa", speedup=10, defaults=[slower_disarm])
        wait_port(ns, GCS_PORT)
        copter = Copter(ns, work / "observer.jsonl")
        first = ns.gcs("status", *CONNECT, timeout=60)  # ArduCopter starts once 5760 connects
        assert first.returncode == 0, first.stderr
        wait_port(ns, OBSERVER_PORT)
        ns.popen([sys.executable, "-c", "import sys; from tests.sitl.test_arducopter_gcs "
                  "import observe; observe(int(sys.argv[1]), sys.argv[2])",
                  str(OBSERVER_PORT), str(copter.log)], cwd=ROOT)
        deadline = time.monotonic() + 30
        while not copter.log.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        copter.wait_for("SYS_STATUS", lambda r: r["prearm"], 60.0)
        yield copter


def _mode_engaged(copter: Copter, name: str, expected: int) -> int:
    """`gcs mode NAME`: exit 0 with the asked mode engaged (seen by the observer), or exit
    1 with ArduCopter's reason; never exit 0 with another mode. The exit status."""
    out = copter.gcs("mode", name)
    done = time.time()
    seen = copter.mode_after(done)
    if out.returncode == 0:
        assert out.stdout.strip() == f"mode {name.upper()}: MAV_RESULT_ACCEPTED", out.stdout
        assert seen == expected, f"mode {name}: exit 0 but the vehicle is in {seen}"
    else:
        assert out.returncode == 1, (name, out.returncode, out.stderr)
        assert "refused" in out.stdout or "not confirmed" in out.stderr, (out.stdout,
                                                                          out.stderr)
        assert seen != expected or "not confirmed" not in out.stderr
    return out.returncode


@pytest.mark.timeout(120)
def test_status_on_the_default_link(copter):
    """status on TCP 5760 as ArduPilot ships it: mode by ArduCopter's name, health ok on a
    vehicle ready to arm, readiness, position and attitude (asked for), no loss."""
    out = copter.gcs("status", "--json")
    assert out.returncode == 0, out.stderr
    status = json.loads(out.stdout)
    assert status["autopilot"] == "MAV_AUTOPILOT_ARDUPILOTMEGA"
    assert status["mode"] == "STABILIZE"
    assert status["health"] == "ok", status["health"]
    assert status["readiness"]["ready_to_arm"] is True, status["readiness"]
    assert status["readiness"]["ekf"] == "ok", status["readiness"]
    assert len(status["position_ned_m"]) == 3 and len(status["q_ned_frd"]) == 4
    assert status["landed"] == "on ground"
    assert status["link"]["lost"] == 0 and status["link"]["loss_percent"] == 0.0, \
        status["link"]
    assert status["link"]["received"] > 20
    assert not any("ENUM_END" in c for c in status.get("capabilities", []))
    text = copter.gcs("status")
    assert "mode: STABILIZE" in text.stdout and "readiness: ready to arm, EKF ok" in \
        text.stdout, text.stdout
    # what status asked for is given back: the link's streams are off again
    ids = "32,31,1,245"  # LOCAL_POSITION_NED, ATTITUDE_QUATERNION, SYS_STATUS, EXT_SYS_STATE
    after = copter.ns.run([sys.executable, "-c", "import sys; from tests.sitl."
                           "test_arducopter_gcs import intervals; intervals(5760, sys.argv[1])",
                           ids], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert after.returncode == 0, after.stderr
    assert json.loads(after.stdout) == {i: -1 for i in ids.split(",")}, after.stdout


@pytest.mark.timeout(150)
def test_modes_on_the_ground(copter):
    """Each of ArduCopter's own modes and each portable name engages what was asked, or is
    exit 1 with ArduCopter's reason; never exit 0 with another mode. A name ArduCopter
    lacks is exit 2 with its names; TAKEOFF disarmed is exit 1. (ArduCopter 4.7 takes each
    of these modes disarmed on the ground: all exit 0.)"""
    codes = {name: _mode_engaged(copter, name, expected) for name, expected in (
        ("STABILIZE", STABILIZE), ("alt_hold", ALT_HOLD), ("GUIDED", GUIDED),
        ("LOITER", LOITER), ("POSHOLD", POSHOLD), ("BRAKE", BRAKE), ("RTL", RTL),
        ("LAND", LAND), ("AUTO", AUTO), ("HOLD", BRAKE), ("MISSION", AUTO),
        ("POSCTL", POSHOLD), ("OFFBOARD", GUIDED), ("Stabilize", STABILIZE))}
    assert set(codes.values()) == {0}, codes
    bad = copter.gcs("mode", "ALTCTL")  # PX4's name: ArduCopter has no such mode
    assert bad.returncode == 2 and "unknown mode ALTCTL on ArduCopter (one of STABILIZE" \
        in bad.stderr, bad.stderr
    assert "BRAKE" in bad.stderr and "HOLD" in bad.stderr
    disarmed = copter.gcs("mode", "TAKEOFF")
    assert disarmed.returncode == 1 and "not armed" in disarmed.stderr, disarmed.stderr


@pytest.mark.timeout(200)
def test_takeoff_goto_land(copter):
    """gcs takeoff --alt 10 climbs to 10 m; a second takeoff in the air is exit 1; goto 10 m
    north flies GUIDED to within 1 m (a roll there is exit 2); watch shows the mode, the
    readiness and no loss; LAND in the air descends and disarms."""
    assert copter.gcs("mode", "GUIDED").returncode == 0
    armed = copter.gcs("arm")
    assert armed.returncode == 0, armed.stdout + armed.stderr
    t0 = time.time()
    up = copter.gcs("takeoff", "--alt", "10")
    assert up.returncode == 0, up.stdout + up.stderr
    assert "reached:" in up.stdout
    top = copter.wait_for("GLOBAL_POSITION_INT", lambda r: r["rel"] > 9.5, 10.0, t0)
    assert top["rel"] < 11.0
    again = copter.gcs("takeoff")
    assert again.returncode == 1 and "in the air" in again.stderr, again.stderr

    tilted = copter.gcs("goto", "10", "0", "-10", "--roll", "5")
    assert tilted.returncode == 2 and "--roll and --pitch" in tilted.stderr, tilted.stderr
    start = copter.records("LOCAL_POSITION_NED")[-1]
    goal = (start["x"] + 10.0, start["y"], -10.0)
    go = copter.gcs("goto", *(f"{v:.3f}" for v in goal), "--yaw", "0", "--tolerance", "1",
                    "--tolerance-deg", "5", "--timeout", "40")
    assert go.returncode == 0, go.stdout + go.stderr
    where = copter.records("LOCAL_POSITION_NED")[-1]
    assert math.dist((where["x"], where["y"], where["z"]), goal) < 1.0, where
    assert copter.mode_after(time.time()) == GUIDED

    watch = copter.gcs("watch", "--duration", "1.5")
    assert watch.returncode == 0, watch.stderr
    last = watch.stdout.strip().split("\n\n")[-1]
    assert "mode GUIDED" in last and "ARMED" in last, last
    assert "readiness" in last and "loss  0.00 %" in last, last

    t1 = time.time()
    land = copter.gcs("mode", "LAND")
    assert land.returncode == 0, land.stdout + land.stderr
    assert copter.mode_after(time.time()) == LAND
    copter.wait_for("HEARTBEAT", lambda r: not r["armed"], 60.0, t1)
    ground = copter.records("GLOBAL_POSITION_INT")[-1]
    assert ground["rel"] < 0.5, ground


@pytest.mark.timeout(150)
def test_mode_takeoff_then_rtl(copter):
    """gcs arm; gcs mode TAKEOFF climbs to 10 m; HOLD holds there (BRAKE); RTL comes home,
    lands and disarms."""
    assert copter.gcs("mode", "GUIDED").returncode == 0
    assert copter.gcs("arm").returncode == 0  # home is set here, where the last flight landed
    start = copter.records("LOCAL_POSITION_NED")[-1]
    t0 = time.time()
    out = copter.gcs("mode", "TAKEOFF")
    assert out.returncode == 0 and out.stdout.strip() == "mode TAKEOFF: MAV_RESULT_ACCEPTED", \
        out.stdout + out.stderr
    copter.wait_for("GLOBAL_POSITION_INT", lambda r: r["rel"] > 9.5, 20.0, t0)
    hold = copter.gcs("mode", "HOLD")
    assert hold.returncode == 0 and copter.mode_after(time.time()) == BRAKE
    t1 = time.time()
    first = copter.wait_for("GLOBAL_POSITION_INT", lambda r: True, 10.0, t1)
    copter.wait_for("GLOBAL_POSITION_INT", lambda r: r["ms"] >= first["ms"] + 10_000, 60.0,
                    t1)  # it holds for 10 s of the vehicle's clock (1 s of ours at speedup 10)
    held = copter.records("GLOBAL_POSITION_INT", t1)
    assert held and all(9.0 < r["rel"] < 11.0 for r in held), held[-1:]
    t2 = time.time()
    assert copter.gcs("mode", "RTL").returncode == 0
    copter.wait_for("HEARTBEAT", lambda r: not r["armed"], 90.0, t2)
    home = copter.records("LOCAL_POSITION_NED")[-1]
    assert math.hypot(home["x"] - start["x"], home["y"] - start["y"]) < 1.0, (home, start)
    assert abs(home["z"] - start["z"]) < 0.5, (home, start)
