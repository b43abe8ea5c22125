"""`gcs goto`: fly to a 6-DoF pose in the autopilot's set-point mode and hold it."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from common.mavlink import MAV
from common.outcome import ATTITUDE_NOT_FLOWN
from gcs.autopilot import ModeTarget
from gcs.autopilot import commands as _commands
from gcs.session import GcsError, Session
from gcs.vehicle_link.actions import arm
from gcs.vehicle_link.pose import PoseTarget, SetpointStream, pose_errors
from gcs.vehicle_link.snapshot import Snapshot

M = MAV


def goto(session: Session, target: PoseTarget, *, arm_first: bool, tolerance_m: float,
         tolerance_rad: float, timeout: float, hold_s: float, rate_hz: float = 20.0,
         report: Callable[[tuple[float, float]], None] | None = None
         ) -> tuple[float, float]:
    """Fly to the pose in the autopilot's set-point mode (`Autopilot.guided_mode`), arming
    if asked, and wait until reached and held for `hold_s`. PX4 and this FCU: stream the
    position and attitude targets, then OFFBOARD (it needs the stream first). ArduPilot:
    GUIDED, then the position and yaw alone (an attitude target would replace the
    position target); the attitude error is then the yaw's. GcsError when refused, not
    confirmed, not reached within `timeout`, when the vehicle leaves the mode meanwhile
    (a failsafe, another ground station), or when it says it holds its attitude instead
    of the target's (this FCU: a tilt would flip), with its reason."""
    s = session
    ap = _commands.autopilot(s)
    full = ap.attitude_targets
    mode = ap.resolve_mode(ap.guided_mode)
    snap = Snapshot()
    accepted_at = math.inf  # when the mode was confirmed (monotonic s)
    streamed_at = math.inf  # when our targets began (monotonic s)

    def listen(seconds: float, until: Callable[[], bool] | None = None) -> bool:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0.0:
            msg = s.recv(None, timeout=min(0.05, left))
            if msg is not None and msg.get_srcSystem() == s.target_system:
                snap.update(msg)
            # said of our targets, whichever read took it (the mode's confirmation too)
            if (refused := s.text_since(streamed_at, ATTITUDE_NOT_FLOWN)) is not None:
                raise GcsError(f"the vehicle does not fly this attitude: {refused}")
            hb = snap.get("HEARTBEAT")
            if hb is not None and snap.heard["HEARTBEAT"] > accepted_at and \
                    not ap.same_mode(mode.custom_mode, hb.custom_mode):
                why = f" ({snap.failsafe_text})" if snap.failsafe_text else ""
                raise GcsError(f"the vehicle left {mode.name}: now "
                               f"{ap.mode_name(hb.custom_mode)}{why}")
            if until is not None and until():
                return True
        return False

    with SetpointStream(s, target, rate_hz, attitude=full) as stream:
        if full:
            streamed_at = time.monotonic()
            stream.start()
            listen(0.5)  # PX4 and this FCU need a setpoint stream before OFFBOARD is accepted
        # a vehicle arms only once it knows its state: wait for its position to be reported
        listen(10.0, until=lambda: snap.get("LOCAL_POSITION_NED") is not None)
        if arm_first and (result := arm(s, True)) != M.MAV_RESULT_ACCEPTED:
            raise GcsError(f"arming refused: {s.describe(result)}")
        _set_mode_or_fail(s, mode)
        streamed_at = min(streamed_at, time.monotonic())
        stream.start()  # ArduPilot: the targets count only once in GUIDED
        accepted_at = time.monotonic()
        snap.failsafe_text = ""  # a failsafe from before does not explain what follows

        def reached() -> bool:
            errs = pose_errors(snap, target, full)
            if report is not None and errs is not None:
                report(errs)
            return errs is not None and errs[0] <= tolerance_m and errs[1] <= tolerance_rad

        if not listen(timeout, reached):
            errs = pose_errors(snap, target, full)
            what = "attitude" if full else "yaw"
            where = "no position heard" if errs is None else \
                f"position error {errs[0]:.3f} m, {what} error {math.degrees(errs[1]):.2f} deg"
            raise GcsError(f"pose not reached within {timeout:g} s ({where})")
        listen(hold_s)
        held = pose_errors(snap, target, full)
        assert held is not None  # reached: the position and attitude heard stay in `snap`
        return held


def _set_mode_or_fail(session: Session, mode: ModeTarget) -> None:
    """The mode, confirmed by a HEARTBEAT; GcsError with the vehicle's reason otherwise."""
    try:
        result = _commands.set_mode(session, mode)
    except _commands.NotConfirmed as exc:
        raise GcsError(f"{mode.name} {exc}") from None
    if result != M.MAV_RESULT_ACCEPTED:
        raise GcsError(f"{mode.name} refused: {session.describe(result)}")
