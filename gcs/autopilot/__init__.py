"""Which autopilot the ground station talks to, and that autopilot's dialect: mode names
and encodings (`dialect`), health and readiness decoding (`health`), and the telemetry the
station asks it for (`streams`). See `dialect` for the table of mode names."""

from gcs.autopilot.dialect import (
    ARDUPILOT,
    PORTABLE_NAMES,
    PX4,
    Autopilot,
    ModeTarget,
    UnknownMode,
    all_mode_names,
    autopilot_of,
)

__all__ = ["ARDUPILOT", "PORTABLE_NAMES", "PX4", "Autopilot", "ModeTarget", "UnknownMode",
           "all_mode_names", "autopilot_of"]
