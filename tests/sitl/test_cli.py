"""Every `gcs` subcommand against real `fcu` and `sitl` processes."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from pymavlink import mavutil

from common.config import load_scenario
from common.links import free_port
from common.mavlink import MAV_CMD_POSE_KEYFRAME
from common.mission_items import MissionItem, local_xy
from fcu.params import SPECS
from gcs.mission_files import format_toml, format_wpl
from gcs.scenario_mission import scenario_mission

from .conftest import PID, ROOT, SCENARIOS, VEHICLE, start, stop

pytestmark = pytest.mark.timeout(180)


@dataclass
class Vehicle:
    connect: str
    logs: Path
    procs: dict

    def gcs(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "gcs.cli", *args, "--connect",
                               self.connect], cwd=ROOT, capture_output=True, text=True,
                              timeout=timeout, check=False)


@pytest.fixture
def vehicle(tmp_path) -> Iterator[Vehicle]:
    """sitl (Case I start: on the ground, lockstep) and fcu sending to a free GCS port."""
    sim, gcs = free_port(), free_port()
    procs = {
        "sitl": start("sitl", ["sitl.node", str(SCENARIOS / "case1_figure8.toml"), "--link",
                               f"udpin:127.0.0.1:{sim}", "--end-time", "600"], tmp_path),
        "fcu": start("fcu", ["fcu.node", "--vehicle", str(VEHICLE), "--gains", str(PID),
                             "--sim", f"udpout:127.0.0.1:{sim}", "--gcs",
                             f"udpout:127.0.0.1:{gcs}"], tmp_path),
    }
    yield Vehicle(f"udpin:127.0.0.1:{gcs}", tmp_path, procs)
    stop(procs)


def test_status_arm_mode_disarm(vehicle):
    """status shows identity and state; arm, mode and disarm report the vehicle's answer."""
    out = vehicle.gcs("status")
    assert out.returncode == 0, out.stderr
    for text in ("MAV_TYPE_HEXAROTOR", "mode: HOLD", "armed: False", "MISSION_INT",
                 "landed: on ground", "health: ok", "position_ned_m: [0.0, 0.0"):
        assert text in out.stdout
    assert vehicle.gcs("arm").stdout.strip() == "arm: MAV_RESULT_ACCEPTED"
    assert "armed: True" in vehicle.gcs("status").stdout
    bad = vehicle.gcs("mode", "ACRO")
    assert bad.returncode == 1 and "unknown mode" in bad.stderr
    assert vehicle.gcs("mode", "MISSION").returncode == 1  # no mission: DENIED
    assert vehicle.gcs("mode", "hold").returncode == 0
    assert vehicle.gcs("disarm").stdout.strip() == "disarm: MAV_RESULT_ACCEPTED"


@pytest.mark.parametrize("fmt", ["wpl", "toml"])
def test_mission_files_round_trip_through_the_vehicle(vehicle, tmp_path, fmt):
    """A mission file uploads and downloads back unchanged, byte for byte, in both formats;
    clear empties the vehicle's mission; a broken file is refused before any upload."""
    items = [*scenario_mission(load_scenario(SCENARIOS / "case1_figure8.toml")),
             MissionItem(4, 1, MAV_CMD_POSE_KEYFRAME, 0, 1, 4.0, 0.125, -0.25, 0.5,
                         local_xy(1.5), local_xy(-2.25), -3.0)]
    text = format_wpl(items) if fmt == "wpl" else format_toml(items)
    src = tmp_path / f"mission.{'waypoints' if fmt == 'wpl' else 'toml'}"
    src.write_text(text)
    up = vehicle.gcs("mission", "upload", str(src))
    assert up.returncode == 0 and "5 items: MAV_MISSION_ACCEPTED" in up.stdout, up.stderr
    back = tmp_path / f"back{src.suffix}"
    assert vehicle.gcs("mission", "download", str(back)).returncode == 0
    assert back.read_text() == text
    shown = vehicle.gcs("mission", "download", "--format", fmt)
    assert shown.stdout == text
    broken = tmp_path / "broken.toml"
    broken.write_text('[[item]]\ntype = "keyframe"\ntime_s = 1.0\n')
    refused = vehicle.gcs("mission", "upload", str(broken))
    assert refused.returncode == 2 and "position_ned_m" in refused.stderr
    assert vehicle.gcs("mission", "download", str(back)).returncode == 0
    assert back.read_text() == text  # the refused file changed nothing
    assert vehicle.gcs("mission", "clear").returncode == 0
    assert vehicle.gcs("mission", "download", "--format", "wpl").stdout == "QGC WPL 110\n"


def test_mission_the_vehicle_cannot_fly_is_refused_with_the_reason(vehicle, tmp_path):
    """A keyframe 2 m away in 0.5 s (about 46 m/s^2 at its peak) is refused at upload, and
    `gcs mission upload` shows the vehicle's reason (the item and the rotor limit); 2 m legs
    at the cruise speed are accepted (the vehicle stretches them)."""
    src = tmp_path / "fast.toml"
    src.write_text('format = "dqflight-mission-1"\n[[item]]\ntype = "keyframe"\n'
                   "time_s = 0.5\nposition_ned_m = [2.0, 0.0, -3.0]\n"
                   "rotvec_ned_frd_rad = [0.0, 0.0, 1.5707963267948966]\n")
    up = vehicle.gcs("mission", "upload", str(src))
    assert up.returncode == 1, up.stdout + up.stderr
    assert "MAV_MISSION_DENIED" in up.stdout and "item 0" in up.stdout, up.stdout
    assert "rad/s" in up.stdout and "lengthen p1" in up.stdout, up.stdout
    legs = tmp_path / "legs.toml"
    legs.write_text('format = "dqflight-mission-1"\n' + "".join(
        f'[[item]]\ntype = "waypoint"\nposition_ned_m = [{x}, 0.0, -3.0]\nhold_s = 0.0\n'
        "yaw_deg = nan\n" for x in (2.0, 4.0, 6.0)))
    ok = vehicle.gcs("mission", "upload", str(legs))
    assert ok.returncode == 0 and "MAV_MISSION_ACCEPTED" in ok.stdout, ok.stdout


def test_mission_start_flies_the_mission(vehicle, tmp_path):
    """mission start then arm (or arm then start) runs the mission."""
    src = tmp_path / "case1.toml"
    src.write_text(format_toml(scenario_mission(load_scenario(SCENARIOS /
                                                              "case1_figure8.toml"))))
    assert vehicle.gcs("mission", "upload", str(src)).returncode == 0
    assert vehicle.gcs("mission", "start").returncode == 0  # MISSION mode, waiting to arm
    assert "MISSION_STATE_NOT_STARTED" in vehicle.gcs("status").stdout
    assert vehicle.gcs("arm").returncode == 0
    time.sleep(1.0)
    status = vehicle.gcs("status").stdout
    assert "mode: MISSION" in status and "MISSION_STATE_ACTIVE" in status


def test_parameters(vehicle):
    """param list, get, set; an unstable gain is refused with the vehicle's reason."""
    listing = vehicle.gcs("param", "list")
    assert listing.returncode == 0
    names = [line.split()[0] for line in listing.stdout.splitlines()]
    assert len(names) == len(SPECS) == 31 and "DQ_KPR_X" in names and "MIS_ENV_CHK" in names
    assert vehicle.gcs("param", "get", "DQ_KDD_Z").stdout.strip() == "DQ_KDD_Z = 10"
    ok = vehicle.gcs("param", "set", "MIS_CRUISE_SPD", "3.5")
    assert ok.returncode == 0 and "MIS_CRUISE_SPD = 3.5" in ok.stdout
    refused = vehicle.gcs("param", "set", "DQ_KID_Y", "50")
    assert refused.returncode == 1
    assert "violates k_p k_d > k_i" in refused.stdout and "DQ_KID_Y = 0.1" in refused.stdout
    missing = vehicle.gcs("param", "get", "NO_SUCH_PARAM")
    assert missing.returncode == 1 and "not answered" in missing.stderr


def test_goto_reaches_a_six_dof_pose(vehicle):
    """goto arms, switches to OFFBOARD and flies to a tilted pose that it reaches."""
    out = vehicle.gcs("goto", "1", "-2", "-3", "--roll", "20", "--yaw", "60", "--arm",
                      "--tolerance", "0.05", "--tolerance-deg", "1")
    assert out.returncode == 0, out.stderr
    assert "reached" in out.stdout
    status = vehicle.gcs("status").stdout
    roll, pitch, yaw = eval(status.split("roll_pitch_yaw_deg: ")[1].splitlines()[0])
    assert abs(roll - 20) < 2 and abs(pitch) < 2 and abs(yaw - 60) < 2


def test_watch_in_a_terminal_quits_on_q(vehicle):
    """watch draws a live view in a pseudo-terminal and quits cleanly on q."""
    pid, fd = pty.fork()
    if pid == 0:  # the child: gcs watch on the pty
        os.chdir(ROOT)
        os.environ["TERM"] = "xterm"
        os.execv(sys.executable, [sys.executable, "-m", "gcs.cli", "watch", "--connect",
                                  vehicle.connect])
    screen = b""
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and b"rotors" not in screen:
            if select.select([fd], [], [], 0.2)[0]:
                screen += os.read(fd, 65536)
        assert b"mode" in screen and b"HOLD" in screen and b"link" in screen
        time.sleep(1.0)
        os.write(fd, b"q")
        deadline = time.monotonic() + 10
        status = None
        while time.monotonic() < deadline and status is None:
            done, code = os.waitpid(pid, os.WNOHANG)
            if done:
                status = code
            elif select.select([fd], [], [], 0.1)[0]:
                try:
                    os.read(fd, 65536)
                except OSError:
                    pass
        assert status is not None and os.waitstatus_to_exitcode(status) == 0
    finally:
        try:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
        except (ChildProcessError, ProcessLookupError):
            pass
        os.close(fd)


def test_log_record_writes_a_readable_tlog(vehicle, tmp_path):
    """log record for 2 s writes a tlog that pymavlink reads back."""
    tlog = tmp_path / "rec.tlog"
    out = vehicle.gcs("log", "record", str(tlog), "--duration", "2")
    assert out.returncode == 0, out.stderr
    log = mavutil.mavlink_connection(str(tlog))
    kinds = set()
    while (msg := log.recv_match()) is not None:
        kinds.add(msg.get_type())
    assert {"HEARTBEAT", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED"} <= kinds


def test_no_vehicle_is_a_clear_error(tmp_path):
    """Nothing on the link: the command says so and exits 1 after --wait."""
    out = subprocess.run([sys.executable, "-m", "gcs.cli", "status", "--connect",
                          f"udpin:127.0.0.1:{free_port()}", "--wait", "1"], cwd=ROOT,
                         capture_output=True, text=True, timeout=30, check=False)
    assert out.returncode == 1 and "no vehicle heartbeat" in out.stderr
