"""`gcs watch`: a live terminal view of one vehicle, refreshed several times a second.

Mode, armed, landed state, mission item, position and attitude with their tracking errors,
rotor speeds and tilts, health, the active failsafe (HEARTBEAT system_status CRITICAL or
EMERGENCY, with the last failsafe STATUSTEXT), link quality and the last status texts. A
vehicle whose HEARTBEAT has not come for more than STALE_S seconds is shown as "LINK LOST
for N s" and its values as stale (greyed on a terminal, marked "[stale]" when piped).
q or Ctrl-C quits. On a terminal it draws with curses, in colour where the terminal has
colours; piped, it prints one plain snapshot per refresh.
"""

from __future__ import annotations

import curses
import math
import sys
import time
from collections.abc import Callable

from common.process.diagnostics import say
from common.wire.mavlink import MAV
from gcs.autopilot.health import format_readiness, readiness
from gcs.autopilot.health import health as health_text
from gcs.vehicle_link.session import Session
from gcs.vehicle_link.snapshot import Snapshot, link_quality
from gcs.vehicle_link.status import heartbeat_mode, landed_name

M = MAV
STALE_S = 2.0  # no HEARTBEAT for longer than this: the link is lost
RATE_WINDOW_S = 2.0  # messages per second over this window

# Styles of the lines: plain text, title, values that may be stale, good, warning, alarm.
PLAIN, TITLE, VALUE, OK, WARN, ALERT = "plain", "title", "value", "ok", "warn", "alert"
Line = tuple[str, str]


def _status_name(state: int) -> str:
    enum = M.enums["MAV_STATE"]
    return enum[state].name.replace("MAV_STATE_", "") if state in enum else str(state)


def view_lines(system_id: int, snap: Snapshot, now: float,
               quality: tuple[float, int, int]) -> list[Line]:
    """The view of one vehicle as (text, style) lines."""
    lines: list[Line] = [(f"system {system_id}   ({now - snap.started:5.1f} s)   q: quit",
                          TITLE)]
    hb = snap.get("HEARTBEAT")
    if hb is None:
        return [*lines, ("waiting for HEARTBEAT ...", WARN)]
    silent = snap.age("HEARTBEAT", now) or 0.0
    if silent > STALE_S:
        lines.append((f"LINK LOST for {silent:.0f} s: no HEARTBEAT; the values below are the "
                      "last heard", ALERT))
    if hb.system_status in (M.MAV_STATE_CRITICAL, M.MAV_STATE_EMERGENCY):
        why = snap.failsafe_text or "no reason heard"
        lines.append((f"FAILSAFE ({_status_name(hb.system_status)}): {why}", ALERT))
    armed = hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    ext = snap.get("EXTENDED_SYS_STATE")
    landed = landed_name(ext.landed_state) if ext is not None else "landed state unknown"
    mc = snap.get("MISSION_CURRENT")
    mission = f"item {mc.seq}/{mc.total}" if mc is not None and mc.total else "no mission"
    lines.append((f"mode {heartbeat_mode(hb):<10} "
                  f"{'ARMED' if armed else 'disarmed':<9} {landed:<11} {mission}   "
                  f"status {_status_name(hb.system_status)}", VALUE))
    pos, att = snap.get("LOCAL_POSITION_NED"), snap.get("ATTITUDE")
    t_ms = None
    if pos is not None:
        t_ms = pos.time_boot_ms
        lines.append((f"position NED  x {pos.x:8.3f}  y {pos.y:8.3f}  z {pos.z:8.3f} m   "
                      f"v {math.sqrt(pos.vx ** 2 + pos.vy ** 2 + pos.vz ** 2):6.2f} m/s",
                      VALUE))
    tgt = snap.get("POSITION_TARGET_LOCAL_NED")
    if tgt is not None:
        lines.append((f"target   NED  x {tgt.x:8.3f}  y {tgt.y:8.3f}  z {tgt.z:8.3f} m",
                      VALUE))
    if att is not None:
        r, p, y = (math.degrees(a) for a in (att.roll, att.pitch, att.yaw))
        lines.append((f"attitude      roll {r:7.2f}  pitch {p:7.2f}  yaw {y:7.2f} deg", VALUE))
    err_pos, err_att = snap.messages.get("ERR_POS"), snap.messages.get("ERR_ATT")
    if err_pos is not None or err_att is not None:
        ep = err_pos.value if err_pos is not None else math.nan
        ea = err_att.value if err_att is not None else math.nan
        lines.append((f"errors        position {ep * 1000:9.3f} mm   attitude "
                      f"{ea * 1000:8.4f} mrad", VALUE))
    out = snap.get("ACTUATOR_OUTPUT_STATUS")
    if out is not None:
        lines.append(("rotors rad/s  " + " ".join(f"{v:7.1f}" for v in out.actuator[:6]),
                      VALUE))
        lines.append(("tilts  rad    " + " ".join(f"{v:7.3f}" for v in out.actuator[6:12]),
                      VALUE))
    ss, ekf = snap.get("SYS_STATUS"), snap.get("EKF_STATUS_REPORT")
    if ss is not None:
        text = health_text(ss)
        lines.append((f"health        {text.replace('unhealthy sensors:', 'unhealthy:')}",
                      OK if text == "ok" else WARN))
    if ss is not None or ekf is not None:
        ready = readiness(ss, ekf, snap.texts)
        lines.append((f"readiness     {format_readiness(ready)}",
                      OK if ready["ready_to_arm"] and ready.get("ekf", "ok") == "ok" else WARN))
    loss, received, lost = quality
    sim = f"   vehicle clock {t_ms / 1000:8.2f} s" if t_ms is not None else ""
    lines.append((f"link  {snap_rate(snap, now):6.0f} msg/s   loss {loss:5.2f} %  ({lost} of "
                  f"{received + lost}){sim}", VALUE))
    lines += [(f"> {t}", PLAIN) for t in snap.texts[-4:]]
    if silent > STALE_S:  # everything the vehicle said is as old as its last heartbeat
        lines = [(text, "stale") if style in (VALUE, OK, WARN) else (text, style)
                 for text, style in lines]
    return lines


def snap_rate(snap: Snapshot, now: float) -> float:
    """Messages per second over the last RATE_WINDOW_S (0 once the vehicle is silent)."""
    samples = snap.rate_samples
    samples.append((now, snap.received))
    while len(samples) > 2 and now - samples[1][0] >= RATE_WINDOW_S:
        samples.pop(0)
    t0, n0 = samples[0]
    return (snap.received - n0) / (now - t0) if now - t0 > 1e-3 else 0.0


def render(system_id: int, snap: Snapshot, now: float,
           quality: tuple[float, int, int]) -> list[str]:
    """The view as plain text: stale values marked "[stale]", alarms in capitals."""
    return [text + ("   [stale]" if style == "stale" else "")
            for text, style in view_lines(system_id, snap, now, quality)]


def _pump(session: Session, snaps: dict[int, Snapshot], seconds: float,
          only: int | None) -> None:
    """Take messages for `seconds`; one snapshot per vehicle (autopilot component)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        msg = session.recv(None, timeout=max(0.0, end - time.monotonic()))
        if msg is None or msg.get_type() == "BAD_DATA":
            continue
        sysid = msg.get_srcSystem()
        if (only is not None and sysid != only) or msg.get_srcComponent() != \
                session.target_component:
            continue
        snap = snaps.setdefault(sysid, Snapshot())
        snap.received += 1
        if msg.get_type() == "NAMED_VALUE_FLOAT":
            snap.messages[msg.name] = msg
        snap.update(msg)


def watch(session: Session, refresh_hz: float = 5.0, duration: float | None = None,
          out: Callable[[str], None] | None = None, all_vehicles: bool = False) -> int:
    """Watch the session's vehicle, or every vehicle heard (`all_vehicles`)."""
    snaps: dict[int, Snapshot] = {}
    only = None if all_vehicles else session.target_system
    if session.heartbeat_msg is not None and session.target_system:
        # the heartbeat that found the vehicle: no "waiting for HEARTBEAT" at the start
        snaps[session.target_system] = first = Snapshot()
        first.update(session.heartbeat_msg, session.heartbeat_at)
    period = 1.0 / refresh_hz

    def pump() -> None:
        _pump(session, snaps, period, only)

    end = math.inf if duration is None else time.monotonic() + duration
    if out is not None or not sys.stdout.isatty():
        return _watch_plain(lambda: _view(session, snaps), pump, end, out or say)

    def loop(screen: curses.window) -> None:
        curses.curs_set(0)
        screen.nodelay(True)
        styles = _styles()
        while time.monotonic() < end:
            pump()
            screen.erase()
            height, width = screen.getmaxyx()
            for i, (line, style) in enumerate(_view(session, snaps)[:height - 1]):
                screen.addnstr(i, 0, line, width - 1, styles.get(style, curses.A_NORMAL))
            screen.refresh()
            key = screen.getch()
            if key in (ord("q"), ord("Q"), 27):
                return

    try:
        curses.wrapper(loop)
    except KeyboardInterrupt:
        pass
    return 0


def _view(session: Session, snaps: dict[int, Snapshot]) -> list[Line]:
    """The lines of every vehicle heard (or of the session's, not yet heard), a blank line
    between two vehicles."""
    now = time.monotonic()
    quality = link_quality(session)
    lines: list[Line] = []
    for sysid in sorted(snaps) or [session.target_system]:
        if lines:
            lines.append(("", PLAIN))
        lines += view_lines(sysid, snaps.get(sysid, Snapshot()), now, quality)
    return lines


def _watch_plain(view: Callable[[], list[Line]], pump: Callable[[], None], end: float,
                 write: Callable[[str], None]) -> int:
    """Not on a terminal: the view written whole after each refresh until `end` (stale
    lines marked) or Ctrl-C."""
    try:
        while time.monotonic() < end:
            pump()
            write("\n".join(text + ("   [stale]" if style == "stale" else "")
                            for text, style in view()) + "\n")
    except KeyboardInterrupt:
        pass
    return 0


def _styles() -> dict[str, int]:
    """The curses attribute of each line style: colours where the terminal has them,
    else bold and reverse video for an alert."""
    styles = {TITLE: curses.A_BOLD, "stale": curses.A_DIM}
    if curses.has_colors():
        curses.start_color()
        curses.use_default_colors()
        for n, (style, colour) in enumerate(((OK, curses.COLOR_GREEN),
                                             (WARN, curses.COLOR_YELLOW),
                                             (ALERT, curses.COLOR_RED)), start=1):
            curses.init_pair(n, colour, -1)
            styles[style] = curses.color_pair(n) | (curses.A_BOLD if style == ALERT else 0)
    else:
        styles[ALERT] = curses.A_BOLD | curses.A_REVERSE
    return styles
