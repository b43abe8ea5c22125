"""`gcs goto`: fly to a 6-DoF pose in the autopilot's set-point mode and hold it."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from common.outcome import ATTITUDE_NOT_FLOWN
from common.wire.identity import flies_pose as identity_flies_pose
from common.wire.mavlink import MAV
from gcs.autopilot import ARDUPILOT, PX4, Autopilot, ModeTarget, UnknownMode
from gcs.autopilot import commands as _commands
from gcs.vehicle_link.actions import arm
from gcs.vehicle_link.descent import DescentWatch, Unsafe, watch_for
from gcs.vehicle_link.params import autopilot_version
from gcs.vehicle_link.pose import PoseTarget, SetpointStream, pose_errors
from gcs.vehicle_link.session import GcsError, Session
from gcs.vehicle_link.snapshot import Snapshot

M = MAV


def flies_pose(session: Session) -> bool:
    """Whether the vehicle says it flies position and attitude targets together
    (`common.wire.identity`: this FCU's AUTOPILOT_VERSION). PX4 and ArduPilot do not: to them
    goto sends the position and the yaw alone."""
    ap = _commands.autopilot(session)
    if ap.kind != PX4:
        return False
    ver = autopilot_version(session)
    return ver is not None and identity_flies_pose(ver.flight_custom_version)


def _check_can_fly(session: Session, arm_first: bool) -> None:
    """GcsError at once for a goto the vehicle would not fly: disarmed without `--arm`, or
    an ArduPilot vehicle on the ground (GUIDED does not climb to a position target)."""
    ap = _commands.autopilot(session)
    armed, landed, height = _commands.flight_state(session)
    if not armed and not arm_first:
        raise GcsError("the vehicle is disarmed: arm it first or give --arm")
    if ap.kind == ARDUPILOT:
        on_ground = landed == M.MAV_LANDED_STATE_ON_GROUND if landed not in (
            None, M.MAV_LANDED_STATE_UNDEFINED) else (height is None or height < 0.5)
        if on_ground or not armed:
            raise GcsError(f"{ap.label} is on the ground: GUIDED does not climb to a position "
                           "target (take off first: gcs takeoff)")


class _Listener:
    """What goto hears while it flies: the vehicle's messages into its snapshot and the
    descent watch, and the refusals that end it (its attitude not flown, once our targets
    stream; the set-point mode left, once it was confirmed)."""

    def __init__(self, s: Session, ap: Autopilot, mode: ModeTarget, snap: Snapshot,
                 watch: DescentWatch) -> None:
        self.s, self.ap, self.mode, self.snap, self.watch = s, ap, mode, snap, watch
        self.accepted_at = math.inf  # when the mode was confirmed (monotonic s)
        self.streamed_at = math.inf  # when our targets began (monotonic s)

    def __call__(self, seconds: float, until: Callable[[], bool] | None = None) -> bool:
        """Listen `seconds`, or until `until()` (True then); GcsError on a refusal."""
        s, snap, ap, mode = self.s, self.snap, self.ap, self.mode
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0.0:
            msg = s.recv(None, timeout=min(0.05, left))
            if s.from_autopilot(msg):
                snap.update(msg)
                self.watch.update(msg, time.monotonic())
            # said of our targets, whichever read took it (the mode's confirmation too)
            if (refused := s.text_since(self.streamed_at, ATTITUDE_NOT_FLOWN)) is not None:
                raise GcsError(f"the vehicle does not fly this attitude: {refused}")
            hb = snap.get("HEARTBEAT")
            if hb is not None and snap.heard["HEARTBEAT"] > self.accepted_at and \
                    not ap.same_mode(mode.custom_mode, hb.custom_mode):
                why = f" ({snap.failsafe_text})" if snap.failsafe_text else ""
                raise GcsError(f"the vehicle left {mode.name}: now "
                               f"{ap.mode_name(hb.custom_mode)}{why}")
            if until is not None and until():
                return True
        return False


def goto(session: Session, target: PoseTarget, *, arm_first: bool, tolerance_m: float,
         tolerance_rad: float, timeout: float, hold_s: float, rate_hz: float = 20.0,
         report: Callable[[tuple[float, float]], None] | None = None,
         full_pose: bool | None = None) -> tuple[float, float]:
    """Fly to the pose in the autopilot's set-point mode (`Autopilot.guided_mode`), arming
    if asked, and wait until reached and held for `hold_s`. A vehicle that flies position
    and attitude together (`flies_pose`: this FCU) gets both targets; PX4 and ArduPilot the
    position and yaw alone (SET_POSITION_TARGET_LOCAL_NED: in PX4's OFFBOARD an attitude
    target turns position control off, in ArduPilot's GUIDED it replaces the position
    target), and the attitude error is then the yaw's. PX4 and this FCU need the stream
    before OFFBOARD; ArduPilot takes the targets once in GUIDED. GcsError when refused, not
    confirmed, not reached within `timeout`, when the vehicle leaves the mode meanwhile
    (a failsafe, another ground station), or when it says it holds its attitude instead
    of the target's (this FCU: a tilt would flip), with its reason; Unsafe when it falls
    (`gcs.vehicle_link.descent`): the stream stops and the autopilot's hold mode is
    commanded. On PX4 the pose reached is then held in HOLD (AUTO.LOITER) before the stream
    stops: PX4 takes a stream that stops in OFFBOARD as a failsafe."""
    s = session
    ap = _commands.autopilot(s)
    full = flies_pose(s) if full_pose is None else full_pose
    _check_can_fly(s, arm_first)
    mode = ap.resolve_mode(ap.guided_mode)
    snap = Snapshot()
    listen = _Listener(s, ap, mode, snap,
                       watch_for(s, ap, floor="start", floor_cap_m=-target.p_ned_m[2],
                                  heights="LOCAL_POSITION_NED"))
    stream = SetpointStream(s, target, rate_hz, attitude=full)
    try:
        with stream:
            if ap.kind == PX4:  # PX4 and this FCU need a set-point stream before OFFBOARD
                listen.streamed_at = time.monotonic()
                stream.start()
                listen(0.5)
            # a vehicle arms only once it knows its state: wait for its position
            listen(10.0, until=lambda: snap.get("LOCAL_POSITION_NED") is not None)
            if arm_first and (result := arm(s, True)) != M.MAV_RESULT_ACCEPTED:
                raise GcsError(f"arming refused: {s.describe(result)}")
            _set_mode_or_fail(s, mode)
            listen.streamed_at = min(listen.streamed_at, time.monotonic())
            stream.start()  # ArduPilot: the targets count only once in GUIDED
            listen.accepted_at = time.monotonic()
            snap.failsafe_text = ""  # a failsafe from before does not explain what follows

            def reached() -> bool:
                errs = pose_errors(snap, target, full)
                if report is not None and errs is not None:
                    report(errs)
                return errs is not None and errs[0] <= tolerance_m and \
                    errs[1] <= tolerance_rad

            if not listen(timeout, reached):
                errs = pose_errors(snap, target, full)
                what = "attitude" if full else "yaw"
                where = "no position heard" if errs is None else \
                    f"position error {errs[0]:.3f} m, {what} error " \
                    f"{math.degrees(errs[1]):.2f} deg"
                raise GcsError(f"pose not reached within {timeout:g} s ({where})")
            listen(hold_s)
            held = pose_errors(snap, target, full)
            assert held is not None  # reached: the position and attitude stay in `snap`
            if ap.kind == PX4 and not full:
                # PX4 takes a stream that stops in OFFBOARD as a failsafe (COM_OF_LOSS_T,
                # then COM_OBL_RC_ACT: position mode, which without sticks cannot run):
                # hold the pose reached in its hold mode while the stream still runs
                held_mode, said = _hold(s, ap)
                if not held_mode:
                    raise GcsError(f"reached, but {said}")
            return held
    except Unsafe as exc:
        stream.stop()
        raise Unsafe(f"{str(exc).removeprefix('UNSAFE: ')}; {_hold(s, ap)[1]}") from None


def _hold(session: Session, ap: Autopilot) -> tuple[bool, str]:
    """The autopilot's hold mode (PX4 AUTO.LOITER, ArduCopter BRAKE): whether a HEARTBEAT
    confirmed it, and what came of it in words."""
    try:
        mode = ap.resolve_mode("HOLD")
    except UnknownMode:
        return False, f"{ap.label} has no hold mode: nothing commanded"
    try:
        result = _commands.set_mode(session, mode)
    except (_commands.NotConfirmed, GcsError) as exc:
        return False, f"commanded {mode.name}: {exc}"
    if result != M.MAV_RESULT_ACCEPTED:
        return False, f"commanded {mode.name}: refused ({session.describe(result)})"
    return True, f"commanded {mode.name}: confirmed"


def _set_mode_or_fail(session: Session, mode: ModeTarget) -> None:
    """The mode, confirmed by a HEARTBEAT; GcsError with the vehicle's reason otherwise."""
    try:
        result = _commands.set_mode(session, mode)
    except _commands.NotConfirmed as exc:
        raise GcsError(f"{mode.name} {exc}") from None
    if result != M.MAV_RESULT_ACCEPTED:
        raise GcsError(f"{mode.name} refused: {session.describe(result)}")
