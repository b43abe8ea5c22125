"""POSCTL from MANUAL_CONTROL, as QGroundControl's virtual joystick sends it (x forward, y
right, r yaw, -1000..1000; z throttle 0..1000 with 500 at the centre), against real sitl
and fcu processes in real time (a pilot's seconds are wall-clock seconds)."""

from __future__ import annotations

import math
import threading
import time

import pytest

from common.config.scenario import load_vehicle
from common.wire.mavlink import MAV
from common.wire.modes import MAIN_POSCTL, Mode
from fcu.modes import manual

from .conftest import VEHICLE

M = MAV
pytestmark = pytest.mark.timeout(120)
STREAM_HZ = 25.0


class Sticks:
    """MANUAL_CONTROL at STREAM_HZ from a thread, the values set by the test."""

    def __init__(self, session) -> None:
        self.session = session
        self.values = (0, 0, 500, 0)
        self.running = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        s = self.session
        while self.running:
            x, y, z, r = self.values
            s.send(M.MAVLink_manual_control_message(s.target_system, x, y, z, r, 0))
            time.sleep(1.0 / STREAM_HZ)  # pacing the stream

    def hold(self, seconds: float, x: int = 0, y: int = 0, z: int = 500, r: int = 0) -> None:
        self.values = (x, y, z, r)
        time.sleep(seconds)  # deliberate: a pilot holds the sticks for wall-clock seconds
        self.values = (0, 0, 500, 0)

    def stop(self) -> None:
        self.running = False
        self.thread.join(timeout=2)


def _shaped(sticks: manual.Sticks, seconds: float) -> tuple[float, float, float, float]:
    """Where the FCU's jerk-limited set-point ends (ENU x, y, z, NED yaw) from rest, level
    and facing east, after `sticks` held for `seconds` then centred until still, with the
    limits it fits to the vehicle (`manual.fit_envelope`): it keeps accelerating briefly
    after a release, so a held stick moves it a little more than speed x time."""
    lim = manual.fit_envelope(manual.StickSettings(), load_vehicle(VEHICLE),
                              (1.0, 0.0, 0.0, 0.0))
    sp = manual.start(0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    for k in range(1, 10 * 500):
        sp, _ = manual.advance(sp, k * 2000, sticks if k * 0.002 <= seconds else
                               manual.CENTRED, lim)
    return (*sp.p_enu_m, sp.yaw_ned_rad)


def _latest(stack, kind: str, timeout: float = 2.0):
    """A message of `kind` sent after this call: what is queued is dropped first (a loaded
    machine may have a backlog), then the next one is taken."""
    while stack.session.conn.recv_msg() is not None:  # the queue and the socket, emptied
        pass
    msg = stack.session.recv([kind], timeout=timeout)
    assert msg is not None
    return msg


def _at_rest(stack, timeout: float = 30.0) -> None:
    """Wait until the set-point has stopped (POSITION_TARGET_LOCAL_NED's velocity and
    acceleration zero) and the vehicle with it (under 5 mm/s and 0.01 rad/s of yaw rate),
    after the sticks are centred."""
    deadline = time.monotonic() + timeout
    while True:
        sp = _latest(stack, "POSITION_TARGET_LOCAL_NED")
        p = _latest(stack, "LOCAL_POSITION_NED")
        att = _latest(stack, "ATTITUDE")
        if max(abs(v) for v in (sp.vx, sp.vy, sp.vz, sp.afx, sp.afy, sp.afz)) < 1e-4 and \
                math.hypot(p.vx, p.vy, p.vz) < 0.005 and abs(att.yawspeed) < 0.01:
            return
        assert time.monotonic() < deadline, f"not at rest in {timeout:g} s: {sp} {p} {att}"


def test_posctl_sticks_move_the_vehicle_and_centred_it_holds(rt_stack):
    """Given the vehicle armed on the ground in POSCTL with centred sticks, when the throttle
    is held full up for 1 s, then it climbs as the jerk-limited set-point does (`_shaped`:
    4.5 m; speed_up x 1 s would be 3 m); when the forward stick is held at half for 2 s,
    then it moves along its heading as the set-point does (about V x 2 s, V = MPC_VEL_MANUAL
    times the deflection after the dead zone: 4.74 m) and nowhere else; centred, it holds
    (drift below 2 cm over 2 s); the yaw stick turns it clockwise as far as the set-point;
    when MANUAL_CONTROL stops, it holds (HOLD) after COM_RC_LOSS_T with a failsafe
    message."""
    s = rt_stack.session
    climb = _shaped(manual.Sticks(up=1.0), 1.0)[2]
    forward = _shaped(manual.Sticks(forward=0.5), 2.0)[0]
    turn = math.degrees(_shaped(manual.Sticks(yaw=1.0), 1.0)[3])
    assert forward == pytest.approx(manual.deflection(0.5) * 5.0 * 2.0, rel=0.05)
    sticks = Sticks(s)
    try:
        heard = rt_stack.wait_for(["SYS_STATUS"], lambda m: m.onboard_control_sensors_health
                                  & M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER, 30.0)
        assert heard is not None, "the FCU did not hear the sticks (RC_RECEIVER) in 30 s"
        assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
        base = (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
                | M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED)  # as pymavlink's px4_map["POSCTL"]
        # POSCTL's envelope fit runs in the FCU's worker, below the loop's priority: the FCU
        # answers IN_PROGRESS at once and ACCEPTED when the fit is in; at load 8 a starved
        # worker (spawned, its kernels loaded, then the fit) can outlast gcs's 10 s ceiling
        assert s.command(M.MAV_CMD_DO_SET_MODE, base, MAIN_POSCTL, 0,
                         ceiling_s=120.0) == M.MAV_RESULT_ACCEPTED
        hb = rt_stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                               m.custom_mode == Mode.POSCTL.custom_mode)
        assert hb is not None and hb.base_mode & M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED

        sticks.hold(1.0, z=1000)  # full throttle: climb at MPC_Z_VEL_MAX_UP
        _at_rest(rt_stack)
        p0 = _latest(rt_stack, "LOCAL_POSITION_NED")
        sp = _latest(rt_stack, "POSITION_TARGET_LOCAL_NED")
        assert p0.z == pytest.approx(-climb, abs=0.3), (p0, sp)
        yaw = _latest(rt_stack, "ATTITUDE").yaw

        sticks.hold(2.0, x=500)  # half forward for 2 s
        _at_rest(rt_stack)  # the jerk-limited braking takes about 2 s
        p1 = _latest(rt_stack, "LOCAL_POSITION_NED")
        dn, de = p1.x - p0.x, p1.y - p0.y
        along = dn * math.cos(yaw) + de * math.sin(yaw)
        across = -dn * math.sin(yaw) + de * math.cos(yaw)
        assert along == pytest.approx(forward, rel=0.05), (dn, de, yaw)
        assert abs(across) < 0.05 and abs(p1.z - p0.z) < 0.05

        samples = []
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            m = s.recv(["LOCAL_POSITION_NED"], timeout=0.1)
            if m is not None:
                samples.append((m.x, m.y, m.z))
        assert len(samples) > 20
        assert max(math.dist(p, samples[0]) for p in samples) < 0.02  # holds

        sticks.hold(1.0, r=1000)  # full yaw right for 1 s: clockwise
        _at_rest(rt_stack)  # the braking takes well under 2 s
        turned = math.degrees(_latest(rt_stack, "ATTITUDE").yaw - yaw)
        assert (turned + 180.0) % 360.0 - 180.0 == pytest.approx(turn, abs=8.0)

        sticks.stop()  # the pilot's link goes: HOLD after COM_RC_LOSS_T (0.5 s)
        lost = time.monotonic()
        text = rt_stack.wait_for(["STATUSTEXT"], lambda m: "manual control lost" in m.text)
        assert text is not None and time.monotonic() - lost >= 0.4
        hb = rt_stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                               m.custom_mode == Mode.HOLD.custom_mode)
        assert hb is not None and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    finally:
        sticks.stop()
