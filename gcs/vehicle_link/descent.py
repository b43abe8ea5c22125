"""A falling vehicle is never silent: while `gcs goto`, `takeoff` and `mode` wait, the
height the vehicle reports is watched, and an uncommanded loss of height or a descent faster
than the vehicle's own limit ends the command at once with `Unsafe` ("UNSAFE: ..." and the
figures; exit 1).

- The height comes from LOCAL_POSITION_NED (-z, vz) or, where the vehicle sends none,
  GLOBAL_POSITION_INT (relative_alt, vz): whichever is heard first, that one alone, so that
  two origins never mix. `goto` takes LOCAL_POSITION_NED alone: its target's height, the
  floor's cap, is in that frame (the local origin is not home on ArduPilot).
- A descent is too fast when the vehicle sinks faster than 1.5 x its limit + 0.5 m/s for
  0.2 s. The limit is the vehicle's own descent-speed parameter (PX4 and this FCU:
  MPC_Z_VEL_MAX_DN in m/s; ArduCopter: WPNAV_SPEED_DN in cm/s), DEFAULT_LIMIT_M_S where it
  cannot be read. A vehicle falling from a hover reaches that in about 0.4 s, 0.8 m down.
- A loss of height is uncommanded when the vehicle is FLOOR_MARGIN_M below the floor the
  command sets: `goto` the lower of its start and its target, `takeoff` the highest point
  it has reached, the modes that hold height (HOLD, LOITER, POSCTL, OFFBOARD and their
  ArduPilot names) the height at the command. LAND, RTL and MISSION descend by design: only
  the speed is judged there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from gcs.autopilot import ARDUPILOT, Autopilot
from gcs.vehicle_link.session import GcsError, Session

DEFAULT_LIMIT_M_S = 3.0  # a vehicle whose descent limit cannot be read
SPEED_FACTOR, SPEED_MARGIN_M_S = 1.5, 0.5
SUSTAIN_S = 0.2
FLOOR_MARGIN_M = 1.0
# the modes that hold their height: a loss of height in them is uncommanded
HOLDING_MODES = frozenset({"HOLD", "LOITER", "AUTO.LOITER", "POSCTL", "OFFBOARD", "BRAKE",
                           "POSHOLD", "GUIDED", "ALT_HOLD", "ALTCTL"})
HEIGHT_MESSAGES = ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT")


class Unsafe(GcsError):
    """The vehicle lost height it was not told to lose, or sank faster than its limit."""

    def __init__(self, reason: str) -> None:
        super().__init__(f"UNSAFE: {reason}")


def height_of(msg: Any) -> tuple[float, float] | None:
    """(height m, up positive; climb rate m/s, up positive) from a LOCAL_POSITION_NED or a
    GLOBAL_POSITION_INT; None for any other message or a value that is not finite."""
    kind = msg.get_type()
    if kind == "LOCAL_POSITION_NED":
        h, climb = -float(msg.z), -float(msg.vz)
    elif kind == "GLOBAL_POSITION_INT":
        h, climb = msg.relative_alt * 1e-3, -msg.vz * 1e-2
    else:
        return None
    return (h, climb) if math.isfinite(h) and math.isfinite(climb) else None


@dataclass
class DescentWatch:
    """Judges the heights a vehicle reports (`update` with each message); pure: the time is
    given with each sample. `floor_m` None: no floor yet (the first height sets it when
    `floor_from_start`); `rising_floor`: the floor follows the highest height seen
    (takeoff)."""

    limit_m_s: float
    limit_source: str
    floor_m: float | None = None
    floor_what: str = ""
    floor_from_start: bool = False
    floor_cap_m: float | None = None  # a floor set from the start is at most this (goto)
    rising_floor: bool = False
    source: str | None = None  # the message type the heights come from
    _fast_since: float | None = None
    _peak_m: float = field(default=-math.inf)

    @property
    def pending(self) -> bool:
        """A fast descent is under way but not yet long enough to call a fall."""
        return self._fast_since is not None

    @property
    def threshold_m_s(self) -> float:
        return SPEED_FACTOR * self.limit_m_s + SPEED_MARGIN_M_S

    def update(self, msg: Any, t_s: float) -> None:
        """Take one message (others than the height's are ignored); Unsafe when the vehicle
        falls. Durations are on the vehicle's clock (the message's time_boot_ms) where it
        gives one, so that a burst of late messages, or a simulated vehicle faster than
        real time, is judged by the time it flew; else on `t_s`, the receiving clock."""
        kind = msg.get_type()
        if kind not in HEIGHT_MESSAGES or (self.source is not None and kind != self.source):
            return
        sample = height_of(msg)
        if sample is None:
            return
        self.source = kind
        boot_ms = getattr(msg, "time_boot_ms", 0)
        self.sample(sample[0], sample[1], boot_ms * 1e-3 if boot_ms > 0 else t_s)

    def sample(self, height_m: float, climb_m_s: float, t_s: float) -> None:
        """One height (m, up) and climb rate (m/s, up) at `t_s`; Unsafe when falling."""
        if self.floor_m is None and self.floor_from_start:
            self.floor_m = height_m if self.floor_cap_m is None else \
                min(height_m, self.floor_cap_m)
        if self.rising_floor and height_m > self._peak_m:
            self._peak_m = height_m
            self.floor_m = height_m
        if self.floor_m is not None and height_m < self.floor_m - FLOOR_MARGIN_M:
            raise Unsafe(f"lost {self.floor_m - height_m:.2f} m of height uncommanded: "
                         f"{height_m:.2f} m, {self.floor_what} {self.floor_m:.2f} m "
                         f"(sinking at {-climb_m_s:.2f} m/s)")
        if -climb_m_s > self.threshold_m_s:
            if self._fast_since is None:
                self._fast_since = t_s
            elif t_s - self._fast_since >= SUSTAIN_S:
                raise Unsafe(f"descending at {-climb_m_s:.2f} m/s at {height_m:.2f} m, faster "
                             f"than the vehicle's limit ({self.limit_m_s:g} m/s, "
                             f"{self.limit_source}) for {t_s - self._fast_since:.2f} s")
        else:
            self._fast_since = None


def descent_limit(session: Session, ap: Autopilot) -> tuple[float, str]:
    """The vehicle's descent-speed limit (m/s) and where it comes from: its parameter, or
    DEFAULT_LIMIT_M_S when the parameter cannot be read."""
    from gcs.vehicle_link.params import param_get

    name, scale = ("WPNAV_SPEED_DN", 0.01) if ap.kind == ARDUPILOT else ("MPC_Z_VEL_MAX_DN", 1.0)
    try:
        value = param_get(session, name, timeout=1.0) * scale
    except (GcsError, KeyError, ValueError):
        value = math.nan
    if math.isfinite(value) and value > 0.0:
        return value, name
    return DEFAULT_LIMIT_M_S, f"{name} not read: default"


def watch_for(session: Session, ap: Autopilot, *, floor: str,
              floor_cap_m: float | None = None, heights: str | None = None) -> DescentWatch:
    """A watch for a command: `floor` "start" (the height at its first sample, at most
    `floor_cap_m`: goto's target), "peak" (the highest seen: takeoff) or "none" (the speed
    alone). `heights`: the one message the heights come from (goto: LOCAL_POSITION_NED,
    the frame of its target's height), else whichever of HEIGHT_MESSAGES comes first."""
    limit, source = descent_limit(session, ap)
    return DescentWatch(limit, source, floor_from_start=floor == "start",
                        floor_cap_m=floor_cap_m, rising_floor=floor == "peak",
                        floor_what={"start": "the floor of the command",
                                    "peak": "after reaching"}.get(floor, ""),
                        source=heights)
