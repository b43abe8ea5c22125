"""Mode changes and takeoff, each the way the autopilot on the link does them.

A mode change is MAV_CMD_DO_SET_MODE in the autopilot's own encoding; it succeeds only when
a HEARTBEAT heard after the ACCEPTED answer shows the mode asked for (`confirm_mode`): an
autopilot may accept and engage another mode (PX4's encoding read by ArduPilot did), or
leave the mode at once. Takeoff: ArduCopter GUIDED then MAV_CMD_NAV_TAKEOFF with p7 in
metres above home; PX4 (and this project's FCU) MAV_CMD_NAV_TAKEOFF with p7 AMSL (home's
altitude from HOME_POSITION plus the height asked). Only an armed vehicle on the ground
takes off.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from common.wire.mavlink import MAV
from gcs.autopilot.dialect import Autopilot, ModeTarget
from gcs.vehicle_link.patience import MODE, Wait

if TYPE_CHECKING:
    from gcs.vehicle_link.session import Session

M = MAV
# How long a mode change waits for a HEARTBEAT that shows it, at most (`gcs.vehicle_link.patience`:
# a vehicle silent for SILENCE_S meanwhile is given up on sooner).
CONFIRM_S = MODE.ceiling_s
DEFAULT_TAKEOFF_M = 10.0  # gcs takeoff and gcs mode TAKEOFF, metres above home
STATE_S = 2.0  # how long takeoff waits for the landed state it asks for
FRESH_HEARTBEAT_S = 1.5  # a HEARTBEAT this recent tells the armed state without waiting
_GROUND = (M.MAV_LANDED_STATE_ON_GROUND,)
HEIGHTS = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT")  # what an observer is shown
SETTLE_S = 0.5  # after a confirmation, how long an observer's judgement may still take
LOCAL_FALLBACK_S = 3.0  # without GLOBAL_POSITION_INT this long, a takeoff's height is -z


class Observer(Protocol):
    """Sees each height message while a command waits, and raises to end the wait
    (`gcs.vehicle_link.descent`)."""

    def __call__(self, msg: Any) -> None: ...

    def pending(self) -> bool:
        """Whether a judgement is under way (a fast descent not yet long enough to call):
        a confirmed mode is then reported only once it is decided."""
        ...


class NotConfirmed(RuntimeError):
    """A mode change the vehicle accepted but did not show in its HEARTBEAT."""


def autopilot(session: Session) -> Autopilot:
    if session.autopilot is None:
        raise RuntimeError("no vehicle heartbeat yet (wait_vehicle first)")
    return session.autopilot


def confirm_mode(session: Session, target: ModeTarget, timeout_s: float,
                 observe: Observer | None = None) -> None:
    """Wait for a HEARTBEAT of the vehicle that shows `target`; NotConfirmed naming the
    mode the last one showed, or that none came. `observe` sees the vehicle's heights
    meanwhile (`gcs.vehicle_link.descent`; it raises to end the wait)."""
    ap = autopilot(session)
    seen = None
    kinds = ["HEARTBEAT", *HEIGHTS] if observe is not None else ["HEARTBEAT"]
    wait = Wait(MODE.but(ceiling_s=timeout_s))
    while not (why := wait.expired()):
        hb = session.recv(kinds, timeout=wait.left())
        wait.note_session(session)  # any message of the vehicle's autopilot
        if not session.from_autopilot(hb):
            continue
        wait.heard()  # (a session-like object may not keep `last_heard`)
        if hb.get_type() != "HEARTBEAT":
            if observe is not None:
                observe(hb)
            continue
        seen = hb
        if ap.same_mode(target.custom_mode, hb.custom_mode):
            _settle(session, observe)
            return
    if why.startswith(":"):  # silence
        raise NotConfirmed(f"not confirmed{why}")
    if seen is None:
        raise NotConfirmed(f"not confirmed: no HEARTBEAT within {timeout_s:g} s")
    raise NotConfirmed(f"not confirmed: the vehicle is in {ap.mode_name(seen.custom_mode)}")


def _settle(session: Session, observe: Observer | None) -> None:
    """Keep showing the observer the heights while its judgement is pending, SETTLE_S at
    most: a mode confirmed while the vehicle falls is not reported as done."""
    end = time.monotonic() + SETTLE_S
    while observe is not None and observe.pending() and \
            (left := end - time.monotonic()) > 0:
        msg = session.recv(list(HEIGHTS), timeout=left)
        if session.from_autopilot(msg):
            observe(msg)


def set_mode(session: Session, target: ModeTarget, confirm_s: float = CONFIRM_S,
             observe: Observer | None = None) -> int:
    """DO_SET_MODE to `target` (not the takeoff procedure: `takeoff`); the vehicle's answer.
    ACCEPTED only once a HEARTBEAT showed the mode, else NotConfirmed."""
    ap = autopilot(session)
    result = session.command(M.MAV_CMD_DO_SET_MODE, *ap.set_mode_params(target.custom_mode))
    if result == M.MAV_RESULT_ACCEPTED:
        confirm_mode(session, target, confirm_s, observe)
    return result


def flight_state(session: Session) -> tuple[bool, int | None, float | None]:
    """(armed, EXTENDED_SYS_STATE.landed_state or None, height above home in m or None),
    asked for (MAV_CMD_REQUEST_MESSAGE) and waited for up to STATE_S."""
    s = session
    armed = landed = height = None
    # the link's latest HEARTBEAT tells the armed state without waiting when it is fresh and
    # came after the latest command sent (an arm's COMMAND_ACK comes before its HEARTBEAT)
    last = s.conn.messages.get("HEARTBEAT")
    heard = getattr(last, "_timestamp", 0.0)
    if s.from_autopilot(last) and time.time() - heard < FRESH_HEARTBEAT_S and \
            heard > s.commanded_at:
        armed = bool(last.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    asked = {M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: "EXTENDED_SYS_STATE",
             M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: "GLOBAL_POSITION_INT"}
    for msg_id in asked:
        s.send(M.MAVLink_command_long_message(s.target_system, s.target_component,
                                              M.MAV_CMD_REQUEST_MESSAGE, 0, msg_id,
                                              0, 0, 0, 0, 0, 0))
    end = time.monotonic() + STATE_S
    while (left := end - time.monotonic()) > 0 and (armed is None or landed is None
                                                     or height is None):
        msg = s.recv(["HEARTBEAT", "EXTENDED_SYS_STATE", "GLOBAL_POSITION_INT"],
                     timeout=left)
        if not s.from_autopilot(msg):
            continue
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        elif kind == "EXTENDED_SYS_STATE":
            landed = msg.landed_state
        elif kind == "GLOBAL_POSITION_INT":
            height = msg.relative_alt * 1e-3
    if armed is None and s.heartbeat_msg is not None:
        armed = bool(s.heartbeat_msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    return bool(armed), landed, height


def takeoff_params(ap: Autopilot, height_m: float, home_alt_m: float | None
                   ) -> tuple[float, ...]:
    """MAV_CMD_NAV_TAKEOFF p1..p7 for a climb to `height_m` above home: p7 relative on
    ArduPilot, AMSL on PX4 (home's altitude + height); yaw and position: the current."""
    if not ap.takeoff_alt_amsl:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, height_m)
    if home_alt_m is None:
        raise ValueError("PX4's takeoff altitude is AMSL: the vehicle's home is needed")
    return (0.0, 0.0, 0.0, math.nan, math.nan, math.nan, home_alt_m + height_m)


def takeoff(session: Session, height_m: float = DEFAULT_TAKEOFF_M, *,
            reach_s: float | None = None, tolerance_m: float = 0.5,
            confirm_s: float = CONFIRM_S, report: Callable[[float], None] | None = None,
            fail: type[Exception] = RuntimeError, observe: Observer | None = None,
            notice: Callable[[str], None] | None = None) -> tuple[int, float | None]:
    """Take off to `height_m` above home; (the vehicle's answer, the height reached when
    `reach_s` is given: waited for until within `tolerance_m`). `fail` (the caller's error
    type) for a vehicle that is disarmed, in the air, without home, or does not climb.
    `observe` sees the heights while it waits (and raises to end the wait). PX4 (and this
    FCU) take off to at least MIS_TAKEOFF_ALT above home: a lower height is raised to it,
    sent and waited for so, and `notice` is told."""
    from gcs.vehicle_link.mission_client import home_position

    s = session
    ap = autopilot(s)
    armed, landed, height = flight_state(s)
    if not armed:
        raise fail("the vehicle is not armed (arm it first)")
    in_air = landed not in _GROUND if landed is not None and \
        landed != M.MAV_LANDED_STATE_UNDEFINED else (height is not None and height > 1.0)
    if in_air:
        raise fail("the vehicle is in the air (takeoff is from the ground)")
    if ap.takeoff_mode is not None:
        mode = ap.resolve_mode(ap.takeoff_mode)
        result = set_mode(s, mode, confirm_s, observe)
        if result != M.MAV_RESULT_ACCEPTED:
            raise fail(f"{mode.name} refused: {s.describe(result)}")
    home_alt = None
    if ap.takeoff_alt_amsl:
        home = home_position(s.conn, s.target_system, s.target_component, send=s.send)
        if home is None:
            raise fail("the vehicle sent no HOME_POSITION (its takeoff altitude is AMSL)")
        home_alt = home.alt_m
    sent_at = time.monotonic()
    result = s.command(M.MAV_CMD_NAV_TAKEOFF, *takeoff_params(ap, height_m, home_alt))
    if result != M.MAV_RESULT_ACCEPTED and getattr(s, "command_sends", 1) > 1 and \
            _left_the_ground(s):
        result = M.MAV_RESULT_ACCEPTED  # the first send was taken, its answer lost
    if result != M.MAV_RESULT_ACCEPTED:
        return result, None
    if ap.takeoff_mode is None:  # PX4: NAV_TAKEOFF engages its TAKEOFF mode
        confirm_mode(s, ap.resolve_mode("TAKEOFF"), confirm_s, observe)
    if reach_s is None:
        return result, None
    climb = _RaisedClimb(s, height_m, sent_at, notice)
    reached = wait_height(s, lambda: climb.height_m() - tolerance_m, reach_s, report, observe)
    if reached is None:
        raise fail(f"{climb.height_m():g} m not reached within {reach_s:g} s")
    return result, reached


# What a vehicle says when it raises a takeoff to its least height (m above home): PX4 up
# to 1.14 ("Using minimum takeoff altitude: 2.50 m", its navigator's Takeoff; 1.15 and later
# take the altitude as given) and this FCU ("takeoff: using the minimum climb 2.5 m").
RAISED_TAKEOFF = re.compile(r"(?:minimum takeoff altitude|using the minimum climb):? "
                            r"([0-9]+(?:\.[0-9]+)?) ?m")


def raised_takeoff_m(text: str) -> float | None:
    """The height a vehicle says it raised a takeoff to (`RAISED_TAKEOFF`), else None."""
    found = RAISED_TAKEOFF.search(text)
    return float(found.group(1)) if found else None


class _RaisedClimb:
    """The height a takeoff climbs to: the one asked for, or higher where the vehicle said
    since `since` (monotonic s) that it raised it (`RAISED_TAKEOFF`; with the answer, or
    after it); `notice` is told once."""

    def __init__(self, session: Session, height_m: float, since: float,
                 notice: Callable[[str], None] | None) -> None:
        self.session, self.height, self.since, self.notice = session, height_m, since, notice

    def height_m(self) -> float:
        heard = getattr(self.session, "texts_since", None)
        for text in heard(self.since) if heard is not None else ():
            up = raised_takeoff_m(text)
            if up is not None and up > self.height:
                self.height = up
                if self.notice is not None:
                    self.notice(f"the vehicle raised the takeoff to {up:g} m above home: "
                                f"{text.strip()}")
        return self.height


def _left_the_ground(session: Session) -> bool:
    """Whether the vehicle is armed and leaving or off the ground (EXTENDED_SYS_STATE, else
    more than 0.2 m above home): a takeoff sent again after its answer was lost is refused
    by ArduCopter once it climbs ("can't takeoff again": MAV_RESULT_FAILED), and PX4 acts
    on each copy; the refusal of the copy does not mean the first was not taken."""
    armed, landed, height = flight_state(session)
    if landed is not None and landed != M.MAV_LANDED_STATE_UNDEFINED:
        return armed and landed in (M.MAV_LANDED_STATE_TAKEOFF, M.MAV_LANDED_STATE_IN_AIR)
    return armed and height is not None and height > 0.2


def wait_height(session: Session, at_least_m: Callable[[], float], timeout_s: float,
                report: Callable[[float], None] | None = None,
                observe: Observer | None = None) -> float | None:
    """Wait until the vehicle is at least `at_least_m` above home; the height then, None
    on timeout or when it disarms. The height above home is GLOBAL_POSITION_INT's relative
    altitude. LOCAL_POSITION_NED's -z is above the local origin, which is not home
    (ArduPilot sets its origin at the first fix and home at arming; PX4 gives home's local
    z apart): it is judged only from a vehicle that has sent no GLOBAL_POSITION_INT for
    LOCAL_FALLBACK_S since the wait began, and never once one came. `at_least_m()` is asked
    at each height (it may rise meanwhile)."""
    s = session
    start = time.monotonic()
    end = start + timeout_s
    global_heard = False
    while (left := end - time.monotonic()) > 0:
        msg = s.recv(["GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "HEARTBEAT"], timeout=left)
        if not s.from_autopilot(msg):
            continue
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if not msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED:
                return None
            continue
        if observe is not None:
            observe(msg)
        if kind == "GLOBAL_POSITION_INT":
            global_heard = True
            height = msg.relative_alt * 1e-3
        elif global_heard or time.monotonic() - start < LOCAL_FALLBACK_S:
            continue
        else:
            height = -msg.z
        if report is not None:
            report(height)
        if height >= at_least_m():
            return float(height)
    return None
