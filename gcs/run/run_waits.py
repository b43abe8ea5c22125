"""The waits of `gcs run` through processes (`gcs.run.process_run`), each on progress, not on a
fixed wall time: a loaded machine slows a lockstep run and must not fail it.

- start-up: the children are alive (checked every CHECK_S) until the vehicle's first
  HEARTBEAT, at most STARTUP_S (a first run compiles the kernels);
- the vehicle's state (its first ATTITUDE_QUATERNION): while the vehicle is heard, at most
  STATE_S;
- parameters, the mission upload, arming and mission start: `gcs.vehicle_link.patience`'s policy;
- the flight: while simulated time advances (the vehicle's time_boot_ms); it fails only
  when that clock stands still for STALL_S of wall time, when a child dies, or at an
  explicit wall-clock ceiling (`wall_timeout_s`, none by default in lockstep);
- the end: the children stop on SIGTERM, waited for up to STOP_S each (they write their
  logs and stats first).

Each ceiling's error names what was waited for.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from common.wire.mavlink import MAV
from gcs.vehicle_link.patience import SILENCE_S
from gcs.vehicle_link.session import GcsError, Session

M = MAV
STARTUP_S = 300.0  # the children's start (imports, kernel compilation) up to a HEARTBEAT
STATE_S = 120.0  # a heard vehicle's first state (its estimator may be aligning)
STALL_S = 60.0  # the flight's clock standing still this long (wall time) ends the run
STOP_S = 60.0  # each child's exit after SIGTERM (it writes its logs and stats)
CHECK_S = 0.5  # how often the children are checked meanwhile
# A child of this run is local: silence this long while it lives is a stall, not a link.
RUN_SILENCE_S = max(SILENCE_S, 20.0)


class Checked(Protocol):
    """The run's children: `check()` raises when one has died."""

    def check(self) -> None: ...


class RunError(RuntimeError):
    """A run that could not be carried out (a child died, the vehicle refused, a timeout)."""


class RunTimeout(RunError):
    """The run made no progress within a ceiling (the message names which)."""


def wait_started(session: Session, children: Checked, system_id: int,
                 ceiling_s: float = STARTUP_S) -> None:
    """The vehicle's first HEARTBEAT while the children live; GcsError at the ceiling."""
    end = time.monotonic() + ceiling_s
    while (left := end - time.monotonic()) > 0.0:
        children.check()
        try:
            session.wait_vehicle(timeout=min(CHECK_S * 2, left), system_id=system_id)
            return
        except GcsError:
            continue
    children.check()
    raise GcsError(f"no vehicle heartbeat within the {ceiling_s:g} s start-up ceiling "
                   "(the sitl and fcu processes kept running)")


def wait_state(session: Session, children: Checked, ceiling_s: float = STATE_S,
               silence_s: float = RUN_SILENCE_S) -> Any:
    """The vehicle's first ATTITUDE_QUATERNION (it has a state) while it is heard; None
    when it falls silent for `silence_s` or at the ceiling."""
    start = time.monotonic()
    while (now := time.monotonic()) - start < ceiling_s:
        children.check()
        if now - max(session.last_heard, start) > silence_s:
            return None
        att = session.recv(["ATTITUDE_QUATERNION"], timeout=CHECK_S)
        if session.from_autopilot(att):
            return att
    return None


@dataclass
class Progress:
    sim_time_s: float = 0.0
    mission_completed: bool = False
    messages: list[str] = field(default_factory=list)


Report = Callable[[Progress], None]  # called with the run's progress as it goes


def watch(session: Session, children: Checked, progress: Progress, end_s: float,
          total: int, wall_timeout_s: float | None = None, report: Report | None = None,
          stall_s: float = STALL_S) -> None:
    """Follow the flight until the vehicle's clock reaches end_s (a diverged or crashed
    vehicle too: the simulator runs to the end, as in-process). RunTimeout when that clock
    stands still for `stall_s` of wall time (no state, or the same one) or at
    `wall_timeout_s` (None: no wall-clock ceiling)."""
    end_ms = round(end_s * 1000)
    start = time.monotonic()
    ceiling = math.inf if wall_timeout_s is None else wall_timeout_s
    last_check = 0.0
    last_ms, last_progress = -1, start
    ends_at = math.inf  # once the end is reached: the last messages' grace
    while (now := time.monotonic()) < ends_at:
        if now - start > ceiling:
            raise RunTimeout(f"the run did not reach t = {end_s} s within the "
                             f"{ceiling:.0f} s wall-clock ceiling (reached "
                             f"{progress.sim_time_s:.2f} s)")
        if now - last_progress > stall_s:
            raise RunTimeout(f"the vehicle's clock stopped at {max(last_ms, 0) / 1000:.3f} s "
                             f"for {stall_s:.0f} s of wall time")
        msg = session.recv(["ATTITUDE_QUATERNION", "MISSION_CURRENT", "STATUSTEXT",
                            "MISSION_ITEM_REACHED"], timeout=0.2)
        now = time.monotonic()
        if now - last_check > CHECK_S:
            children.check()
            last_check = now
            if report is not None:
                report(progress)
        if not session.from_autopilot(msg):
            continue
        if msg.get_type() != "ATTITUDE_QUATERNION":
            _mission_news(msg, progress, total)
            continue
        progress.sim_time_s = msg.time_boot_ms * 1e-3
        if msg.time_boot_ms > last_ms:
            last_ms, last_progress = msg.time_boot_ms, now
        if msg.time_boot_ms >= end_ms and math.isinf(ends_at):
            ends_at = now + 0.3  # let the last mission messages arrive


def _mission_news(msg: MAV.MAVLink_message, progress: Progress, total: int) -> None:
    """MISSION_CURRENT or MISSION_ITEM_REACHED that show the mission of `total` items
    completed, and STATUSTEXT, into `progress`."""
    kind = msg.get_type()
    if kind == "MISSION_CURRENT":
        if msg.mission_state == M.MISSION_STATE_COMPLETE and msg.total == total:
            progress.mission_completed = True
    elif kind == "MISSION_ITEM_REACHED" and msg.seq == total - 1:
        progress.mission_completed = True
    elif kind == "STATUSTEXT":
        progress.messages.append(msg.text)
