"""Every `gcs` subcommand against real `fcu` and `sitl` processes."""

from __future__ import annotations

import json
import os
import pty
import select
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
from pymavlink import mavutil

from common.config.scenario import load_scenario
from common.links import free_port
from common.wire.mavlink import MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import MissionItem, local_xy
from fcu.params import SPECS
from gcs.cli.parser import HEARTBEAT_WAIT_S
from gcs.mission_files.toml import format_toml
from gcs.mission_files.wpl import format_wpl
from gcs.run.scenario_mission import scenario_mission

from .conftest import PACE, PID, ROOT, SCENARIOS, VEHICLE, start, stop
from .waits import sched_s, until

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


@contextmanager
def _vehicle(tmp_path: Path) -> Iterator[Vehicle]:
    """sitl (Case I start: on the ground, lockstep paced: `PACE`) and fcu sending to a free
    GCS port."""
    sim, gcs = free_port(), free_port()
    procs = {
        "sitl": start("sitl", ["sitl.node", str(SCENARIOS / "case1_figure8.toml"), "--link",
                               f"udpin:127.0.0.1:{sim}", "--end-time", "600", *PACE], tmp_path),
        "fcu": start("fcu", ["fcu.edge.node", "--vehicle", str(VEHICLE), "--gains", str(PID),
                             "--sim", f"udpout:127.0.0.1:{sim}", "--gcs",
                             f"udpout:127.0.0.1:{gcs}"], tmp_path),
    }
    try:
        # Commands start once the vehicle has its state (the FCU reports attitude then):
        # the processes load their compiled kernels first, slowly on a loaded machine.
        from gcs.vehicle_link.session import Session

        session = Session(f"udpin:127.0.0.1:{gcs}")
        try:
            assert session.recv(["ATTITUDE_QUATERNION"], timeout=60.0) is not None, \
                "the vehicle reports no state"
        finally:
            session.close()
        yield Vehicle(f"udpin:127.0.0.1:{gcs}", tmp_path, procs)
    finally:
        stop(procs)


@pytest.fixture
def vehicle(tmp_path) -> Iterator[Vehicle]:
    """A vehicle of the test's own, for a test that arms, flies or stops it."""
    with _vehicle(tmp_path) as v:
        yield v


# The tests that leave the vehicle on the ground, disarmed in HOLD, share one (their group
# runs on one worker, in the file's order): each uploads its own mission or none.
ON_THE_GROUND = pytest.mark.xdist_group("cli_ground_vehicle")


@pytest.fixture(scope="module")
def ground_vehicle(tmp_path_factory) -> Iterator[Vehicle]:
    """One vehicle for the module's tests that keep it on the ground."""
    with _vehicle(tmp_path_factory.mktemp("ground_vehicle")) as v:
        yield v


def test_status_arm_mode_disarm(vehicle):
    """status shows identity and state, formatted (no Python notation, millimetres);
    arm, mode and disarm report the vehicle's answer, a refusal with its reason."""
    out = vehicle.gcs("status")
    assert out.returncode == 0, out.stderr
    for text in ("MAV_TYPE_HEXAROTOR", "mode: HOLD", "armed: no", "MISSION_INT",
                 "landed: on ground", "health: ok", "position_ned_m: 0.000, 0.000, ",
                 "system: 1 (component 1)", "% lost ("):
        assert text in out.stdout, out.stdout
    for python in ("[", "]", "{", "'", "True", "False"):
        assert python not in out.stdout, out.stdout
    assert vehicle.gcs("arm").stdout.strip() == "arm: MAV_RESULT_ACCEPTED"
    assert "armed: yes" in vehicle.gcs("status").stdout
    bad = vehicle.gcs("mode", "BRAKE")  # ArduCopter's, not PX4's: exit 2 with PX4's names
    assert bad.returncode == 2 and "unknown mode BRAKE on PX4 (one of HOLD, " in bad.stderr
    denied = vehicle.gcs("mode", "MISSION")  # no mission: DENIED, and the vehicle says why
    assert denied.returncode == 1
    assert denied.stdout.strip() == "mode MISSION refused: MAV_RESULT_DENIED: no mission"
    assert vehicle.gcs("mode", "hold").returncode == 0
    assert vehicle.gcs("disarm").stdout.strip() == "disarm: MAV_RESULT_ACCEPTED"


@ON_THE_GROUND
def test_status_asks_for_what_is_not_streamed(ground_vehicle):
    """Given a link on which the vehicle no longer streams EXTENDED_SYS_STATE and
    MISSION_CURRENT (SET_MESSAGE_INTERVAL -1), when status runs, then it still shows the
    landed state and the mission: it asks for them (REQUEST_MESSAGE) rather than hoping
    that a 1 Hz stream brings them within its window."""
    from pymavlink.dialects.v20 import common as M

    from gcs.vehicle_link.session import Session

    session = Session(ground_vehicle.connect)
    try:
        session.wait_vehicle(timeout=30.0)
        for msg_id in (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_MISSION_CURRENT):
            assert session.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, -1) == \
                M.MAV_RESULT_ACCEPTED
        quiet = session.recv(["EXTENDED_SYS_STATE", "MISSION_CURRENT"], timeout=2.5)
        assert quiet is None, "the streams did not stop"
    finally:
        session.close()
    for _ in range(3):
        out = ground_vehicle.gcs("status")
        assert out.returncode == 0, out.stderr
        assert "landed: on ground" in out.stdout and "mission: none" in out.stdout, out.stdout


@ON_THE_GROUND
def test_status_json_is_one_document(ground_vehicle):
    """status --json prints one JSON document with float32 values in their shortest form."""
    out = ground_vehicle.gcs("status", "--json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["system"] == 1 and doc["mode"] == "HOLD" and doc["armed"] is False
    assert doc["landed"] == "on ground" and doc["health"] == "ok"
    assert len(doc["position_ned_m"]) == 3 and len(doc["q_ned_frd"]) == 4
    assert all(len(repr(v)) <= 16 for v in doc["q_ned_frd"])  # no 0.10000000149011612
    assert set(doc["link"]) == {"loss_percent", "received", "lost"}


@ON_THE_GROUND
@pytest.mark.parametrize("fmt", ["wpl", "toml"])
def test_mission_files_round_trip_through_the_vehicle(ground_vehicle, tmp_path, fmt):
    """A mission file uploads and downloads back unchanged, byte for byte, in both formats;
    clear empties the vehicle's mission; a broken file is refused before any upload."""
    items = [*scenario_mission(load_scenario(SCENARIOS / "case1_figure8.toml")),
             MissionItem(4, 1, MAV_CMD_POSE_KEYFRAME, 0, 1, 4.0, 0.125, -0.25, 0.5,
                         local_xy(1.5), local_xy(-2.25), -3.0)]
    text = format_wpl(items) if fmt == "wpl" else format_toml(items)
    src = tmp_path / f"mission.{'waypoints' if fmt == 'wpl' else 'toml'}"
    src.write_text(text)
    up = ground_vehicle.gcs("mission", "upload", str(src))
    assert up.returncode == 0 and "5 items: MAV_MISSION_ACCEPTED" in up.stdout, up.stderr
    back = tmp_path / f"back{src.suffix}"
    assert ground_vehicle.gcs("mission", "download", str(back)).returncode == 0
    assert back.read_text() == text
    shown = ground_vehicle.gcs("mission", "download", "--format", fmt)
    assert shown.stdout == text
    broken = tmp_path / "broken.toml"
    broken.write_text('[[item]]\ntype = "keyframe"\ntime_s = 1.0\n')
    refused = ground_vehicle.gcs("mission", "upload", str(broken))
    assert refused.returncode == 2 and "position_ned_m" in refused.stderr
    assert ground_vehicle.gcs("mission", "download", str(back)).returncode == 0
    assert back.read_text() == text  # the refused file changed nothing
    assert ground_vehicle.gcs("mission", "clear").returncode == 0
    assert ground_vehicle.gcs("mission", "download", "--format",
                              "wpl").stdout == "QGC WPL 110\n"


@ON_THE_GROUND
def test_mission_the_vehicle_cannot_fly_is_refused_with_the_reason(ground_vehicle, tmp_path):
    """A keyframe 2 m away in 0.5 s (about 46 m/s^2 at its peak) is refused at upload, and
    `gcs mission upload` shows the vehicle's reason (the item and the rotor limit); 2 m legs
    at the cruise speed are accepted (the vehicle stretches them)."""
    src = tmp_path / "fast.toml"
    src.write_text('format = "dqflight-mission-1"\n[[item]]\ntype = "keyframe"\n'
                   "time_s = 0.5\nposition_ned_m = [2.0, 0.0, -3.0]\n"
                   "rotvec_ned_frd_rad = [0.0, 0.0, 1.5707963267948966]\n")
    up = ground_vehicle.gcs("mission", "upload", str(src))
    assert up.returncode == 1, up.stdout + up.stderr
    assert "MAV_MISSION_DENIED" in up.stdout and "item 0" in up.stdout, up.stdout
    assert "rad/s" in up.stdout and "lengthen p1" in up.stdout, up.stdout
    legs = tmp_path / "legs.toml"
    legs.write_text('format = "dqflight-mission-1"\n' + "".join(
        f'[[item]]\ntype = "waypoint"\nposition_ned_m = [{x}, 0.0, -3.0]\nhold_s = 0.0\n'
        "yaw_deg = nan\n" for x in (2.0, 4.0, 6.0)))
    ok = ground_vehicle.gcs("mission", "upload", str(legs))
    assert ok.returncode == 0 and "MAV_MISSION_ACCEPTED" in ok.stdout, ok.stdout


def test_mission_start_refuses_a_disarmed_vehicle_and_arms_only_with_arm(vehicle, tmp_path):
    """Given an uploaded mission and the vehicle disarmed, `mission start` is refused before
    anything is sent (PX4 would arm on MISSION_START and take off): exit 1, the mode
    unchanged; `mission start --arm` arms, then starts, and the mission flies."""
    src = tmp_path / "case1.toml"
    src.write_text(format_toml(scenario_mission(load_scenario(SCENARIOS /
                                                              "case1_figure8.toml"))))
    assert vehicle.gcs("mission", "upload", str(src)).returncode == 0
    refused = vehicle.gcs("mission", "start")
    assert refused.returncode == 1
    assert "the vehicle is disarmed: arm it first (gcs arm) or give --arm; nothing sent" \
        in refused.stderr, refused.stderr
    status = vehicle.gcs("status").stdout
    assert "mode: MISSION" not in status and "armed: no" in status, status
    started = vehicle.gcs("mission", "start", "--arm")
    assert started.returncode == 0, started.stdout + started.stderr
    assert "arm: MAV_RESULT_ACCEPTED" in started.stdout
    assert "mission start: MAV_RESULT_ACCEPTED" in started.stdout
    until(lambda: "MISSION_STATE_ACTIVE" in vehicle.gcs("status").stdout,
          "the mission active after mission start --arm")
    status = vehicle.gcs("status").stdout
    assert "mode: MISSION" in status and "MISSION_STATE_ACTIVE" in status


@ON_THE_GROUND
def test_parameters(ground_vehicle):
    """param list, get, set; an unstable gain is refused with the vehicle's reason."""
    listing = ground_vehicle.gcs("param", "list")
    assert listing.returncode == 0
    names = [line.split()[0] for line in listing.stdout.splitlines()]
    assert len(names) == len(SPECS) and "DQ_KPR_X" in names and "MIS_ENV_CHK" in names
    assert ground_vehicle.gcs("param", "get", "DQ_KDD_Z").stdout.strip() == "DQ_KDD_Z = 10"
    ok = ground_vehicle.gcs("param", "set", "MIS_CRUISE_SPD", "3.5")
    assert ok.returncode == 0 and "MIS_CRUISE_SPD = 3.5" in ok.stdout
    refused = ground_vehicle.gcs("param", "set", "DQ_KID_Y", "50")
    assert refused.returncode == 1
    assert "violates k_p k_d > k_i" in refused.stdout and "DQ_KID_Y = 0.1" in refused.stdout
    missing = ground_vehicle.gcs("param", "get", "NO_SUCH_PARAM")
    assert missing.returncode == 1 and "parameter NO_SUCH_PARAM: does not exist " \
        "(MAV_PARAM_ERROR_DOES_NOT_EXIST)" in missing.stderr, missing.stderr


def test_goto_reaches_a_six_dof_pose(vehicle):
    """goto arms, switches to OFFBOARD and flies to a tilted pose that it reaches."""
    out = vehicle.gcs("goto", "1", "-2", "-3", "--roll", "20", "--yaw", "60", "--arm",
                      "--tolerance", "0.05", "--tolerance-deg", "1")
    assert out.returncode == 0, out.stderr
    assert "reached" in out.stdout
    status = json.loads(vehicle.gcs("status", "--json").stdout)
    roll, pitch, yaw = status["roll_pitch_yaw_deg"]
    assert abs(roll - 20) < 2 and abs(pitch) < 2 and abs(yaw - 60) < 2


def test_goto_a_roll_that_would_flip_tilts_ends_with_the_vehicles_reason(vehicle):
    """Given the vehicle level at a heading of 60 deg, when goto asks for a 170 deg roll
    there (about the body's forward axis: two tilts would flip half a turn), then the FCU
    holds its attitude and says why, and goto exits 1 at once with that reason instead of
    waiting for a pose that will not come; the vehicle stays level where it was."""
    assert vehicle.gcs("goto", "1", "-2", "-3", "--yaw", "60", "--arm", "--tolerance", "0.05",
                       "--tolerance-deg", "1").returncode == 0
    t0 = time.monotonic()
    out = vehicle.gcs("goto", "1", "-2", "-3", "--roll", "170", "--yaw", "60",
                      "--timeout", "60")
    assert out.returncode == 1, out
    assert "attitude not flown: tilt servo" in out.stderr and "flip" in out.stderr, out.stderr
    assert time.monotonic() - t0 < 30.0
    status = json.loads(vehicle.gcs("status", "--json").stdout)
    roll, pitch, yaw = status["roll_pitch_yaw_deg"]
    assert abs(roll) < 2 and abs(pitch) < 2 and abs(yaw - 60) < 2


@ON_THE_GROUND
def test_watch_in_a_terminal_quits_on_q(ground_vehicle):
    """watch draws a live view in a pseudo-terminal and quits cleanly on q."""
    pid, fd = pty.fork()
    if pid == 0:  # the child: gcs watch on the pty
        os.chdir(ROOT)
        os.environ["TERM"] = "xterm"
        os.execv(sys.executable, [sys.executable, "-m", "gcs.cli", "watch", "--connect",
                                  ground_vehicle.connect])
    screen = b""
    try:
        def drawn() -> bool:  # a vehicle on the ground sends no actuator outputs yet
            return b"mode" in screen and b"HOLD" in screen and b"link" in screen

        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not drawn():
            if select.select([fd], [], [], 0.2)[0]:
                screen += os.read(fd, 65536)
        assert drawn(), screen
        time.sleep(1.0)  # deliberate: a few redraws, so that q comes to a running view
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


@ON_THE_GROUND
def test_log_record_writes_a_readable_tlog(ground_vehicle, tmp_path):
    """log record for 2 s writes a tlog that pymavlink reads back."""
    tlog = tmp_path / "rec.tlog"
    out = ground_vehicle.gcs("log", "record", str(tlog), "--duration", "2")
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


# ------------------------------------------------------------------ input and links


def _cmd(*argv: str, timeout: float = 30.0) -> tuple[subprocess.CompletedProcess, float]:
    """Run `gcs`, `fcu` or `sitl` (python -m); (result, seconds it slept). A refusal "at
    once" is judged by the time its main thread slept, not by the wall clock: a command
    that waits for a vehicle sleeps HEARTBEAT_WAIT_S (10 s) first, while a busy machine
    has taken 10 s of wall time to start a process and refuse, running or queued for a CPU
    (/proc schedstat, read once it has exited, before it is reaped)."""
    module = {"gcs": "gcs.cli", "fcu": "fcu.edge.node", "sitl": "sitl.node"}[argv[0]]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", module, *argv[1:]], cwd=ROOT,
                                stdout=out, stderr=err, text=True)
        try:
            while os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
                if time.monotonic() - t0 > timeout:
                    raise subprocess.TimeoutExpired(proc.args, timeout)
                time.sleep(0.01)
            took = time.monotonic() - t0
            ran_s, queued_s = sched_s(proc.pid, (proc.pid,))  # the exited main thread's
        finally:
            proc.kill()
            proc.wait()
        out.seek(0)
        err.seek(0)
        result = subprocess.CompletedProcess(proc.args, proc.returncode, out.read(), err.read())
    return result, took - ran_s - queued_s


def _one_line_error(out: subprocess.CompletedProcess, code: int, *texts: str) -> None:
    lines = out.stderr.splitlines()
    assert out.returncode == code, (out.returncode, out.stdout, out.stderr)
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    for text in texts:
        assert text in lines[0], lines[0]


SLEPT_MAX_S = HEARTBEAT_WAIT_S / 2  # a refusal at once sleeps far less than the wait
FCU_ARGS = ("--vehicle", str(VEHICLE), "--gains", str(PID))
CASE1 = str(SCENARIOS / "case1_figure8.toml")
BAD_INPUT = [
    # link URLs: MAVSDK's forms parse, bad ones are refused before any wait
    (("gcs", "status", "--connect", "udpin://127.0.0.1:99999"), "port 99999 out of range"),
    (("gcs", "status", "--connect", "udpin:127.0.0.1"), "no port"),
    (("gcs", "status", "--connect", "udpout:127.0.0.1:0"), "port 0 out of range"),
    (("gcs", "status", "--connect", "bogus:1:2"), "unknown link type 'bogus'"),
    (("gcs", "status", "--connect", "serial:/dev/ttyNOPE0:57600"),
     "no such device /dev/ttyNOPE0"),
    (("gcs", "status", "--connect", "serial:/dev/ttyNOPE0"), "expected serial:DEVICE:BAUD"),
    (("gcs", "status", "--connect", f"serial:{CASE1}:57600"), "is not a serial device"),
    (("gcs", "view", "--connect", "tcp://127.0.0.1:70000"), "port 70000 out of range"),
    (("fcu", *FCU_ARGS, "--sim", "udpin://127.0.0.1:99999"), "port 99999 out of range"),
    (("fcu", *FCU_ARGS, "--gcs", "udpout:127.0.0.1"), "no port"),
    (("fcu", *FCU_ARGS, "--gcs", "serial:///dev/ttyNOPE0:57600"), "no such device"),
    (("sitl", CASE1, "--link", "tcpin:127.0.0.1:65536"), "port 65536 out of range"),
    (("sitl", CASE1, "--link", "udp:"), "no port"),
    # arguments, names and files, checked before anything is opened
    (("gcs", "mode", "FOO"), "unknown mode FOO (one of HOLD, "),
    (("gcs", "mode"), "required: name"),
    (("gcs", "status", "--wait", "-1"), "--wait"),
    (("fcu", "--gains", str(PID)), "required: --vehicle"),
    (("gcs", "mission", "upload", "/nonexistent/mission.toml"), "/nonexistent/mission.toml"),
    (("gcs", "status", "--signing-key", "/nonexistent/key"), "/nonexistent/key"),
    (("gcs", "keygen", "/nonexistent/folder/key"), "its folder does not exist"),
    (("gcs", "log", "record", "/nonexistent/folder/x.tlog"),
     "folder /nonexistent/folder does not exist"),
    (("gcs", "log", "record", "/tmp"), "is a folder"),
    (("gcs", "mission", "download", "/nonexistent/folder/m.toml"), "/nonexistent/folder"),
    (("gcs", "run", CASE1, "--out", CASE1), "is not a folder"),
    (("gcs", "report", "/nonexistent/run"), "/nonexistent/run"),
    (("fcu", *FCU_ARGS, "--stats", "/nonexistent/folder/s.json"), "does not exist"),
    (("sitl", CASE1, "--truth-log", "/nonexistent/folder/t.ulg"), "does not exist"),
    (("sitl", CASE1, "--speed-factor", "2", "--realtime"),
     "--speed-factor paces a lockstep (dqflight, px4-hil): not with --realtime"),
    (("sitl", CASE1, "--speed-factor", "2", "--protocol", "ardupilot-json"),
     "not with --protocol ardupilot-json"),
    (("sitl", CASE1, "--speed-factor", "-1"), "--speed-factor -1: a positive number"),
    (("gcs", "router", "--listen", "tcp/127.0.0.1"), "expected PROTO/HOST:PORT"),
]


@pytest.mark.parametrize(("argv", "text"), BAD_INPUT, ids=[" ".join(a[:3]) + " " + a[-1][-24:]
                                                           for a, _ in BAD_INPUT])
def test_bad_input_is_one_line_and_exit_2_without_waiting(argv, text):
    """No vehicle anywhere: every bad input is refused without waiting for one, exit 2, one
    stderr line, no traceback (the unknown mode used to wait the heartbeat's 10 s for a
    vehicle, then exit 1; a busy machine has taken 7 s to start and refuse)."""
    out, slept = _cmd(*argv)
    _one_line_error(out, 2, text)
    assert slept < SLEPT_MAX_S, f"{argv} slept {slept:.1f} s"


def test_mission_file_errors_reach_one_line(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text('[[item]]\ntype = "keyframe"\ntime_s = 1.0\n')
    out, slept = _cmd("gcs", "mission", "upload", str(broken), "--connect",
                     f"udpin:127.0.0.1:{free_port()}")
    _one_line_error(out, 2, "position_ned_m")
    assert slept < SLEPT_MAX_S


def test_mavsdk_url_forms_reach_the_link(tmp_path):
    """MAVSDK's spellings open real links: nothing answers, so the wait ends (exit 1)."""
    for url in (f"udpin://127.0.0.1:{free_port()}", f"udp://127.0.0.1:{free_port()}",
                f"udpout://127.0.0.1:{free_port()}"):
        out, _ = _cmd("gcs", "status", "--connect", url, "--wait", "0.5")
        _one_line_error(out, 1, "no vehicle heartbeat")


def test_refused_tcp_connect_is_one_line_exit_1():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, not listening: connects are refused
        for url in (f"tcp:127.0.0.1:{port}", f"tcp://127.0.0.1:{port}"):
            out, slept = _cmd("gcs", "status", "--connect", url)
            _one_line_error(out, 1, f"cannot connect to 127.0.0.1:{port}",
                            "connection refused")
            assert slept < SLEPT_MAX_S
        for argv in (("gcs", "status", "--connect", f"zenoh:mavlink@tcp/127.0.0.1:{port}"),
                     ("sitl", CASE1, "--link", f"zenoh:mavlink@tcp/127.0.0.1:{port}")):
            out, slept = _cmd(*argv)  # no Zenoh router there: the peer is missing, exit 1
            _one_line_error(out, 1, "cannot open a Zenoh session")
            assert slept < SLEPT_MAX_S


def _holder(kind: int, reuse: bool = True) -> socket.socket:
    """Another process's socket on a port (SO_REUSEADDR set, as pymavlink sets it)."""
    s = socket.socket(socket.AF_INET, kind)
    if reuse:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("127.0.0.1", 0))
    if kind == socket.SOCK_STREAM:
        s.listen(1)
    return s


@pytest.mark.parametrize("who", ["gcs udpin", "gcs udpin://", "gcs tcpin", "fcu --gcs",
                                 "fcu --sim", "sitl --link", "sitl tcpin", "gcs router"])
def test_busy_port_is_refused_never_shared(who):
    """A port another process holds is an error naming it, never silently shared."""
    kind = socket.SOCK_STREAM if "tcp" in who or "router" in who else socket.SOCK_DGRAM
    with _holder(kind) as held:
        port = held.getsockname()[1]
        argv = {
            "gcs udpin": ("gcs", "status", "--connect", f"udpin:127.0.0.1:{port}"),
            "gcs udpin://": ("gcs", "status", "--connect", f"udpin://127.0.0.1:{port}"),
            "gcs tcpin": ("gcs", "status", "--connect", f"tcpin:127.0.0.1:{port}"),
            "fcu --gcs": ("fcu", *FCU_ARGS, "--gcs", f"udpin:127.0.0.1:{port}"),
            "fcu --sim": ("fcu", *FCU_ARGS, "--sim", f"udpin:127.0.0.1:{port}"),
            "sitl --link": ("sitl", CASE1, "--link", f"udpin:127.0.0.1:{port}"),
            "sitl tcpin": ("sitl", CASE1, "--link", f"tcpin:127.0.0.1:{port}"),
            "gcs router": ("gcs", "router", "--listen", f"tcp/127.0.0.1:{port}"),
        }[who]
        out, slept = _cmd(*argv)
    _one_line_error(out, 2, f"127.0.0.1:{port} is in use by another process")
    assert slept < SLEPT_MAX_S


def test_two_ground_stations_on_one_udpin_port(tmp_path):
    """The second `gcs` on a port the first listens on is told so (it used to share it
    silently, each getting part of the datagrams)."""
    port = free_port()
    first = subprocess.Popen([sys.executable, "-m", "gcs.cli", "status", "--connect",
                              f"udpin:127.0.0.1:{port}", "--wait", "20"], cwd=ROOT,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 15
        while True:  # until the first one holds the port
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                try:
                    probe.bind(("127.0.0.1", port))
                except OSError:
                    break
            assert time.monotonic() < deadline and first.poll() is None
            time.sleep(0.1)
        out, slept = _cmd("gcs", "watch", "--connect", f"udpin:127.0.0.1:{port}")
        _one_line_error(out, 2, f"127.0.0.1:{port} is in use by another process")
        assert slept < SLEPT_MAX_S and first.poll() is None
    finally:
        first.kill()
        first.wait()


def test_refusal_prints_the_vehicles_reason(tmp_path):
    """An FCU without a simulator refuses to arm; `gcs arm` prints the STATUSTEXT that came
    with the COMMAND_ACK, not only MAV_RESULT_DENIED."""
    gcs = free_port()
    procs = {"fcu": start("fcu", ["fcu.edge.node", *FCU_ARGS, "--sim",
                                  f"udpout:127.0.0.1:{free_port()}", "--gcs",
                                  f"udpout:127.0.0.1:{gcs}"], tmp_path)}
    try:
        # the FCU's start-up on a loaded machine can outlast the default 10 s heartbeat wait
        out, _ = _cmd("gcs", "arm", "--connect", f"udpin:127.0.0.1:{gcs}", "--wait", "120",
                      timeout=180.0)
        assert out.returncode == 1, out.stderr
        assert out.stdout.strip() == \
            "arm refused: MAV_RESULT_DENIED: arming refused: no state input", \
            out.stdout + out.stderr
    finally:
        stop(procs)


def _watch_until_alive(watch: subprocess.Popen, at_s: float) -> str:
    """What a piped `gcs watch` printed until a snapshot at `at_s` s or later of its own
    clock (the title's "(  4.0 s)", counted from when it found the vehicle: its start-up
    on a loaded machine does not count) showed a live vehicle on the ground, healthy."""
    assert watch.stdout is not None
    text, frame = "", ""
    for line in watch.stdout:  # snapshots: "system 1   (  t s) ..." lines, then a blank one
        text += line
        frame += line
        if line != "\n":
            continue
        if frame.startswith("system 1 "):
            t_s = float(frame.split("(", 1)[1].split(" s)", 1)[0])
            if t_s >= at_s and "position NED" in frame and "on ground" in frame and \
                    "health        ok" in frame and "LINK LOST" not in frame:
                return text
        frame = ""
    raise AssertionError(f"watch ended before a live snapshot at {at_s:g} s: {text[-2000:]}")


def test_watch_shows_link_lost_when_the_fcu_dies(vehicle):
    """Piped, watch prints plain snapshots: landed state and health while the FCU lives,
    then "LINK LOST for N s" with the values marked stale once it is killed."""
    watch = subprocess.Popen([sys.executable, "-m", "gcs.cli", "watch", "--connect",
                              vehicle.connect, "--rate", "4", "--duration", "9"], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out = _watch_until_alive(watch, 4.0)
        vehicle.procs["fcu"].kill()
        assert watch.stdout is not None and watch.stderr is not None
        out += watch.stdout.read()  # to the end of its 9 s (the pipe's buffered part too)
        err = watch.stderr.read()
        watch.wait(timeout=30)
    finally:
        if watch.poll() is None:
            watch.kill()
            watch.wait()
    assert watch.returncode == 0, err
    assert "\x1b" not in out  # plain text when piped
    frames = out.split("system 1 ")
    alive = [f for f in frames if "LINK LOST" not in f and "position NED" in f]
    assert alive and "on ground" in alive[-1] and "health        ok" in alive[-1]
    assert "[stale]" not in "".join(alive)
    lost = [f for f in frames if "LINK LOST for" in f]
    assert lost, out[-2000:]
    last = lost[-1]
    assert "[stale]" in last and "position NED" in last
    seconds = int(last.split("LINK LOST for ")[1].split(" s")[0])
    assert 3 <= seconds <= 8


def test_every_transport_carries_the_ground_station(tmp_path):
    """One link layer for gcs and fcu: the FCU serves udpin, tcpin and a tcp client link;
    `gcs status` reaches it over udpout://, tcp:// and tcpin (MAVSDK's forms included)."""
    udp, tcpin, tcp = free_port(), free_port(socket.SOCK_STREAM), free_port(socket.SOCK_STREAM)
    procs = {"fcu": start("fcu", ["fcu.edge.node", *FCU_ARGS, "--sim",
                                  f"udpout:127.0.0.1:{free_port()}",
                                  "--gcs", f"udpin://127.0.0.1:{udp}",
                                  "--gcs", f"tcpin:127.0.0.1:{tcpin}",
                                  "--gcs", f"tcp:127.0.0.1:{tcp}"], tmp_path)}
    try:
        deadline = time.monotonic() + 20
        while "fcu: system 1" not in (tmp_path / "fcu.log").read_text():  # links are open
            assert time.monotonic() < deadline and procs["fcu"].poll() is None
            time.sleep(0.1)
        for url in (f"udpout://127.0.0.1:{udp}", f"tcp://127.0.0.1:{tcpin}",
                    f"tcpin:127.0.0.1:{tcp}"):
            out, _ = _cmd("gcs", "status", "--connect", url)
            assert out.returncode == 0, (url, out.stderr, (tmp_path / "fcu.log").read_text())
            assert "MAV_TYPE_HEXAROTOR" in out.stdout and "mode: HOLD" in out.stdout, url
    finally:
        stop(procs)


def test_goto_ends_when_the_vehicle_leaves_offboard(tmp_path):
    """goto streams its set-points from its own thread; when its whole process is paused
    (SIGSTOP) for longer than COM_OF_LOSS_T, the FCU's failsafe holds, and once resumed goto
    exits 1 at once, naming the mode the vehicle is in and the failsafe, instead of waiting
    out its timeout. A second ground station link watches the mode; both processes fly by
    the wall clock (in lockstep the 40 m could be flown before the pause)."""
    import signal

    from common.wire.modes import Mode, decode_custom
    from gcs.vehicle_link.session import Session

    sim, gcs, watch = free_port(), free_port(), free_port()
    procs = {
        "sitl": start("sitl", ["sitl.node", str(SCENARIOS / "case1_figure8.toml"), "--link",
                               f"udpin:127.0.0.1:{sim}", "--realtime"], tmp_path),
        "fcu": start("fcu", ["fcu.edge.node", "--vehicle", str(VEHICLE), "--gains", str(PID),
                             "--sim", f"udpout:127.0.0.1:{sim}", "--realtime", "--gcs",
                             f"udpout:127.0.0.1:{gcs}", "--gcs",
                             f"udpout:127.0.0.1:{watch}"], tmp_path),
    }
    session = Session(f"udpin:127.0.0.1:{watch}")
    try:
        session.wait_vehicle(timeout=60.0)
        assert session.recv(["ATTITUDE_QUATERNION"], timeout=60.0) is not None
        procs["goto"] = subprocess.Popen(
            [sys.executable, "-m", "gcs.cli", "goto", "0", "40", "-3", "--arm", "--timeout",
             "120", "--connect", f"udpin:127.0.0.1:{gcs}"], cwd=ROOT, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True)

        def mode(timeout: float) -> Mode | None:
            hb = session.recv(["HEARTBEAT"], timeout=timeout)
            return decode_custom(hb.custom_mode) if hb is not None else None

        deadline = time.monotonic() + 60.0
        while mode(1.0) != Mode.OFFBOARD:
            assert time.monotonic() < deadline and procs["goto"].poll() is None, \
                procs["goto"].communicate()
        procs["goto"].send_signal(signal.SIGSTOP)
        deadline = time.monotonic() + 10.0
        while mode(1.0) != Mode.HOLD:
            assert time.monotonic() < deadline, "the FCU did not hold without set-points"
        procs["goto"].send_signal(signal.SIGCONT)
        out, err = procs["goto"].communicate(timeout=30.0)
        assert procs["goto"].returncode == 1, out + err
        assert "the vehicle left OFFBOARD: now HOLD (failsafe: offboard setpoints lost: " \
               "HOLD)" in err, err
    finally:
        session.close()
        goto = procs.get("goto")
        if goto is not None and goto.poll() is None:
            goto.send_signal(signal.SIGCONT)
        stop(procs)
