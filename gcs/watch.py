"""`gcs watch`: a live terminal view of one vehicle, refreshed several times a second.

Mode, armed, mission item, position and attitude with their tracking errors, rotor speeds and
tilts, link quality and the last status texts. q or Ctrl-C quits. On a terminal it draws with
curses; piped, it prints one plain snapshot per refresh.
"""

from __future__ import annotations

import curses
import math
import sys
import time
from collections.abc import Callable

from common.mavlink import MAV
from gcs.session import Session
from gcs.vehicle_link import Snapshot, link_quality, mode_name

M = MAV


def render(system_id: int, snap: Snapshot, now: float,
           quality: tuple[float, int, int]) -> list[str]:
    """The view of one vehicle as lines of text (pure: same input, same lines)."""
    lines = [f"system {system_id}   ({now - snap.started:5.1f} s)   q: quit"]
    hb = snap.get("HEARTBEAT")
    if hb is None:
        return [*lines, "waiting for HEARTBEAT ..."]
    armed = "ARMED" if hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED else "disarmed"
    mc = snap.get("MISSION_CURRENT")
    mission = f"item {mc.seq}/{mc.total}" if mc is not None and mc.total else "no mission"
    lines.append(f"mode {mode_name(hb.custom_mode, hb.autopilot):<10} {armed:<9} {mission}")
    pos, att = snap.get("LOCAL_POSITION_NED"), snap.get("ATTITUDE")
    t_ms = None
    if pos is not None:
        t_ms = pos.time_boot_ms
        lines.append(f"position NED  x {pos.x:8.3f}  y {pos.y:8.3f}  z {pos.z:8.3f} m   "
                     f"v {math.sqrt(pos.vx ** 2 + pos.vy ** 2 + pos.vz ** 2):6.2f} m/s")
    tgt = snap.get("POSITION_TARGET_LOCAL_NED")
    if tgt is not None:
        lines.append(f"target   NED  x {tgt.x:8.3f}  y {tgt.y:8.3f}  z {tgt.z:8.3f} m")
    if att is not None:
        r, p, y = (math.degrees(a) for a in (att.roll, att.pitch, att.yaw))
        lines.append(f"attitude      roll {r:7.2f}  pitch {p:7.2f}  yaw {y:7.2f} deg")
    err_pos, err_att = snap.messages.get("ERR_POS"), snap.messages.get("ERR_ATT")
    if err_pos is not None or err_att is not None:
        ep = err_pos.value if err_pos is not None else math.nan
        ea = err_att.value if err_att is not None else math.nan
        lines.append(f"errors        position {ep * 1000:9.3f} mm   attitude {ea * 1000:8.4f} mrad")
    out = snap.get("ACTUATOR_OUTPUT_STATUS")
    if out is not None:
        lines.append("rotors rad/s  " + " ".join(f"{v:7.1f}" for v in out.actuator[:6]))
        lines.append("tilts  rad    " + " ".join(f"{v:7.3f}" for v in out.actuator[6:12]))
    loss, received, lost = quality
    rate = snap.received / max(now - snap.started, 1e-3)
    sim = f"   vehicle clock {t_ms / 1000:8.2f} s" if t_ms is not None else ""
    lines.append(f"link  {rate:6.0f} msg/s   loss {loss:5.2f} %  ({lost} of "
                 f"{received + lost}){sim}")
    lines += [f"> {t}" for t in snap.texts[-4:]]
    return lines


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
    period = 1.0 / refresh_hz

    def view() -> list[str]:
        now = time.monotonic()
        quality = link_quality(session)
        lines: list[str] = []
        for sysid in sorted(snaps) or [session.target_system]:
            if lines:
                lines.append("")
            lines += render(sysid, snaps.get(sysid, Snapshot()), now, quality)
        return lines

    end = math.inf if duration is None else time.monotonic() + duration
    if out is not None or not sys.stdout.isatty():
        write = out or (lambda text: print(text, flush=True))
        try:
            while time.monotonic() < end:
                _pump(session, snaps, period, only)
                write("\n".join(view()) + "\n")
        except KeyboardInterrupt:
            pass
        return 0

    def loop(screen) -> None:
        curses.curs_set(0)
        screen.nodelay(True)
        while time.monotonic() < end:
            _pump(session, snaps, period, only)
            screen.erase()
            height, width = screen.getmaxyx()
            for i, line in enumerate(view()[:height - 1]):
                screen.addnstr(i, 0, line, width - 1)
            screen.refresh()
            key = screen.getch()
            if key in (ord("q"), ord("Q"), 27):
                return

    try:
        curses.wrapper(loop)
    except KeyboardInterrupt:
        pass
    return 0
