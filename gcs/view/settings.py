"""`gcs view`'s settings: where it serves, the channels and their rates, the path window,
the /vehicle/state schema, the publishing schedule, and its error."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent.parent
DEFAULT_VEHICLE = ROOT / "config" / "vehicles" / "hexa_tilted.toml"
HOST = "127.0.0.1"  # loopback only, whatever the caller asks
DEFAULT_PORT = 8765

BASE_HZ = 20  # the publishing tick; every channel's rate divides it
RATES_HZ: dict[str, int] = {"/tf": 20, "/vehicle/state": 10, "/path/flown": 5,
                            "/path/desired": 5, "/airframe": 1}
TOPICS = tuple(RATES_HZ)
PATH_WINDOW_US = 60_000_000
PATH_SPACING_US = 100_000
STATE_SCHEMA: dict[str, Any] = {
    "title": "dqflight.VehicleState",
    "type": "object",
    "properties": {
        "time_s": {"type": "number", "description": "vehicle time, s"},
        "source": {"type": "string", "enum": ["live", "replay"]},
        "mode": {"type": ["string", "null"]},
        "armed": {"type": ["boolean", "null"]},
        "rotor_speeds_rad_s": {"type": ["array", "null"], "items": {"type": "number"}},
        "tilts_rad": {"type": ["array", "null"], "items": {"type": "number"}},
        "position_enu_m": {"type": ["array", "null"], "items": {"type": "number"}},
        "desired_position_enu_m": {"type": ["array", "null"], "items": {"type": "number"}},
    },
}


class ViewError(RuntimeError):
    """Bad input for `gcs view`: a run folder, an MCAP path, a port that cannot be used."""



def replay_ticks(t_first_us: int, t_last_us: int, hz: int = BASE_HZ) -> Iterator[int]:
    """Publishing instants of a replay: every 1/hz s of the timeline, first to last row."""
    step = 1_000_000 // hz
    t = t_first_us
    while t <= t_last_us:
        yield t
        t += step


def due_topics(tick: int) -> list[str]:
    """The topics published at tick number `tick` of the BASE_HZ tick."""
    return [topic for topic, hz in RATES_HZ.items() if tick % (BASE_HZ // hz) == 0]

