"""The autopilot on the other end, from its HEARTBEAT (`autopilot`, `type`), and its dialect:
mode names and their encodings, how it takes off, flies to a pose and counts mission items.

ArduPilot numbers its modes per vehicle (pymavlink's tables `mavutil.mode_mapping_acm`,
`_apm`, `_rover`, `_sub`, chosen by MAV_TYPE) and puts the number in custom_mode; PX4 (and
this project's FCU, which says MAV_AUTOPILOT_PX4) puts main mode << 16 | sub mode << 24
(`common.wire.modes`, `mavutil.px4_map`). MAV_AUTOPILOT_GENERIC is read as PX4, as MAVSDK does.
`gcs mode NAME` takes the vehicle's own names (case-insensitive) and the portable names
below; where the vehicle has a mode of that very name, its own wins.

| portable | PX4, this FCU  | ArduCopter | ArduPlane | ArduRover | ArduSub |
|----------|----------------|------------|-----------|-----------|---------|
| HOLD     | AUTO.LOITER    | BRAKE      | LOITER    | HOLD      | POSHOLD |
| LOITER   | AUTO.LOITER    | LOITER     | LOITER    | LOITER    | POSHOLD |
| MISSION  | AUTO.MISSION   | AUTO       | AUTO      | AUTO      | AUTO    |
| TAKEOFF  | takeoff        | takeoff    | TAKEOFF   | -         | -       |
| LAND     | AUTO.LAND      | LAND       | AUTOLAND  | -         | SURFACE |
| RTL      | AUTO.RTL       | RTL        | RTL       | RTL       | SURFACE |
| POSCTL   | POSCTL         | POSHOLD    | CRUISE    | STEERING  | POSHOLD |
| OFFBOARD | OFFBOARD       | GUIDED     | GUIDED    | GUIDED    | GUIDED  |

"takeoff" is the takeoff procedure (`gcs takeoff` at its default altitude): ArduCopter
GUIDED then MAV_CMD_NAV_TAKEOFF, PX4 MAV_CMD_NAV_TAKEOFF. HOLD is BRAKE on ArduCopter
because BRAKE holds the position without reading the pilot's sticks: LOITER, POSHOLD and
ALT_HOLD read the throttle stick, and without a transmitter (a ground station alone, or
ArduPilot's SITL) they read it low and the vehicle descends. "-": the vehicle has no such
mode (exit 2 with its list).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega

import common.wire.mavlink  # noqa: F401  (pins MAVLink 2 before mavutil is used)
from common.wire import modes as px4_modes
from common.wire.mavlink import MAV

M = MAV
# What the station decodes: ardupilotmega holds common and ArduPilot's own messages
# (EKF_STATUS_REPORT, MEMINFO, ...), which are then received, not counted lost; common
# messages decode the same in both.
STATION_DIALECT = ardupilotmega
ARDUPILOT, PX4 = "ardupilot", "px4"
PORTABLE_NAMES = ("HOLD", "LOITER", "MISSION", "TAKEOFF", "LAND", "RTL", "POSCTL", "OFFBOARD")
TAKEOFF_PROCEDURE = "takeoff"
FIRMWARE_ARDUPILOT, FIRMWARE_PX4 = 3, 12  # QGC .plan firmwareType (MAV_AUTOPILOT)

_TABLES = {"copter": mavutil.mode_mapping_acm, "plane": mavutil.mode_mapping_apm,
           "rover": mavutil.mode_mapping_rover, "sub": mavutil.mode_mapping_sub}

# portable name -> the autopilot's own name (TAKEOFF_PROCEDURE: `gcs takeoff`); a name
# missing here and among the vehicle's own is not available on it
_PORTABLE: dict[tuple[str, str], dict[str, str]] = {
    (PX4, ""): {"TAKEOFF": TAKEOFF_PROCEDURE},
    (ARDUPILOT, "copter"): {"HOLD": "BRAKE", "MISSION": "AUTO", "TAKEOFF": TAKEOFF_PROCEDURE,
                            "POSCTL": "POSHOLD", "OFFBOARD": "GUIDED"},
    (ARDUPILOT, "plane"): {"HOLD": "LOITER", "MISSION": "AUTO", "LAND": "AUTOLAND",
                           "POSCTL": "CRUISE", "OFFBOARD": "GUIDED"},
    (ARDUPILOT, "rover"): {"MISSION": "AUTO", "POSCTL": "STEERING", "OFFBOARD": "GUIDED"},
    (ARDUPILOT, "sub"): {"HOLD": "POSHOLD", "LOITER": "POSHOLD", "MISSION": "AUTO",
                         "LAND": "SURFACE", "RTL": "SURFACE", "POSCTL": "POSHOLD",
                         "OFFBOARD": "GUIDED"},
}

# PX4's own modes beyond the ones this project flies, as pymavlink names them
_PX4_OTHERS: dict[str, int] = {name: (main << 16) | (sub << 24) for name, (_base, main, sub)
               in mavutil.px4_map.items() if px4_modes.by_name(name) is None}


class UnknownMode(ValueError):
    """A mode name the autopilot does not have; the message lists the names it has."""


@dataclass(frozen=True)
class ModeTarget:
    """A mode asked for: its name in the autopilot's own spelling and its custom_mode, or
    the takeoff procedure (`takeoff`, custom_mode of the mode it flies in)."""

    name: str
    custom_mode: int
    takeoff: bool = False


@dataclass(frozen=True)
class Autopilot:
    """The autopilot behind a HEARTBEAT and what differs between autopilots."""

    kind: str  # ARDUPILOT or PX4
    vehicle: str  # "copter", "plane", "rover", "sub", or "" (unknown)
    mission_home_at_seq0: bool  # ArduPilot keeps home at mission seq 0
    firmware_type: int  # QGC .plan's firmwareType
    mav_type: int = 0
    dialect: str = "common"  # the pymavlink dialect its messages decode with

    @property
    def label(self) -> str:
        """ArduCopter, ArduPlane, ... or PX4."""
        if self.kind == PX4:
            return "PX4"
        return {"copter": "ArduCopter", "plane": "ArduPlane", "rover": "ArduRover",
                "sub": "ArduSub"}.get(self.vehicle, "ArduPilot")

    # -------------------------------------------------------------- modes

    def own_modes(self) -> dict[str, int]:
        """The autopilot's own mode names (its spelling) and custom_mode values."""
        if self.kind == PX4:
            own = {mode.name: mode.custom_mode for mode in px4_modes.Mode}
            own.update({"LOITER": px4_modes.Mode.HOLD.custom_mode}, **_PX4_OTHERS)
            return own
        table = mavutil.mode_mapping_bynumber(self.mav_type) or {}
        return {name: number for number, name in table.items()}

    def mode_names(self) -> list[str]:
        """Every name `resolve_mode` takes: the own names, then the portable ones."""
        own = list(self.own_modes())
        return own + [n for n in PORTABLE_NAMES if n not in own and self._portable(n)]

    def _portable(self, name: str) -> str | None:
        key = (self.kind, "" if self.kind == PX4 else self.vehicle)
        return _PORTABLE.get(key, {}).get(name)

    def resolve_mode(self, name: str) -> ModeTarget:
        """The mode NAME asks for (case-insensitive); UnknownMode listing the names."""
        key = name.strip().upper()
        own = self.own_modes()
        if self.kind == PX4 and key not in own and key != "TAKEOFF":
            alias = px4_modes.ALIASES.get(key)
            key = alias.name if alias is not None else key
        if key == "TAKEOFF" and self._portable(key) == TAKEOFF_PROCEDURE:
            flies_in = "GUIDED" if self.kind == ARDUPILOT else "TAKEOFF"
            return ModeTarget("TAKEOFF", own[flies_in], takeoff=True)
        if key in own:
            return ModeTarget(key, own[key])
        mapped = self._portable(key)
        if mapped is not None and mapped in own:
            return ModeTarget(mapped, own[mapped])
        raise UnknownMode(f"unknown mode {name} on {self.label} "
                          f"(one of {', '.join(self.mode_names())})")

    def mode_name(self, custom_mode: int) -> str:
        """custom_mode in the autopilot's own spelling (pymavlink's for ArduPilot)."""
        if self.kind == PX4:
            mode = px4_modes.decode_custom(custom_mode)
            if mode is not None:
                return mode.name
            for name, value in _PX4_OTHERS.items():
                if self.same_mode(value, custom_mode):
                    return name
            main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
            return f"custom {main}.{sub}"
        table = mavutil.mode_mapping_bynumber(self.mav_type) or {}
        return str(table.get(custom_mode, f"Mode({custom_mode})"))

    def same_mode(self, wanted: int, custom_mode: int) -> bool:
        """Whether a HEARTBEAT's custom_mode is the mode `wanted` (PX4: the sub-mode counts
        only under AUTO)."""
        if self.kind != PX4:
            return wanted == custom_mode
        main, got_main = (wanted >> 16) & 0xFF, (custom_mode >> 16) & 0xFF
        if main != got_main:
            return False
        return main != px4_modes.MAIN_AUTO or (wanted >> 24) & 0xFF == (custom_mode >> 24) & 0xFF

    def set_mode_params(self, custom_mode: int) -> tuple[float, float, float]:
        """MAV_CMD_DO_SET_MODE p1..p3 for a custom_mode: ArduPilot's mode number in p2,
        PX4's main mode in p2 and sub mode in p3."""
        flag = float(M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        if self.kind == ARDUPILOT:
            return flag, float(custom_mode), 0.0
        return flag, float((custom_mode >> 16) & 0xFF), float((custom_mode >> 24) & 0xFF)

    # -------------------------------------------------------------- procedures

    @property
    def guided_mode(self) -> str:
        """The mode a ground station flies set-points in: GUIDED, or PX4's OFFBOARD."""
        return "GUIDED" if self.kind == ARDUPILOT else "OFFBOARD"

    @property
    def takeoff_mode(self) -> str | None:
        """The mode MAV_CMD_NAV_TAKEOFF needs first (ArduCopter: GUIDED), None if any."""
        return "GUIDED" if self.kind == ARDUPILOT else None

    @property
    def takeoff_alt_amsl(self) -> bool:
        """NAV_TAKEOFF's p7: AMSL (PX4) or metres above home (ArduPilot)."""
        return self.kind == PX4


def _vehicle(mav_type: int) -> str:
    table = mavutil.mode_mapping_bynumber(mav_type)
    return next((name for name, t in _TABLES.items() if t is table), "")


def autopilot_of(heartbeat: Any) -> Autopilot:
    """The autopilot behind a HEARTBEAT (its `autopilot` and `type`)."""
    mav_type = int(heartbeat.type)
    if int(heartbeat.autopilot) == M.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return Autopilot(ARDUPILOT, _vehicle(mav_type), mission_home_at_seq0=True,
                         firmware_type=FIRMWARE_ARDUPILOT, mav_type=mav_type,
                         dialect="ardupilotmega")
    return Autopilot(PX4, _vehicle(mav_type), mission_home_at_seq0=False,
                     firmware_type=FIRMWARE_PX4, mav_type=mav_type, dialect="common")


def all_mode_names() -> list[str]:
    """Every mode name some autopilot takes: the portable ones first."""
    names = dict.fromkeys(PORTABLE_NAMES)
    names.update(dict.fromkeys(Autopilot(PX4, "", False, FIRMWARE_PX4).own_modes()))
    names.update(dict.fromkeys(px4_modes.ALIASES))
    for table in _TABLES.values():
        names.update(dict.fromkeys(table.values()))
    return list(names)
