"""The command line's choices applied to a scenario before any run, in-process or through
processes (`gcs run`, `gcs table1`): loads neither the FCU nor the plant."""

from __future__ import annotations

import dataclasses
from typing import Any

from common.config.scenario import Scenario, check_sensor_faults
from common.config.sensors import check_servable, resolve_sensor_profile


def apply_overrides(scenario: Scenario, *, controller: str | None = None,
                    ideal_actuators: bool | None = None,
                    duration_s: float | None = None, sensors: str | None = None,
                    seed: int | None = None) -> Scenario:
    """The scenario with the command line's choices (a sensor profile by name or file)."""
    changes: dict[str, Any] = {}
    if sensors is not None:
        changes["sensors"] = resolve_sensor_profile(sensors)
    if seed is not None:
        changes["seed"] = seed
    if controller is not None:
        changes["controller"] = controller
    if ideal_actuators is not None:
        changes["ideal_actuators"] = ideal_actuators
    if duration_s is not None:
        changes["duration_s"] = min(duration_s, scenario.duration_s)
    out = dataclasses.replace(scenario, **changes)
    check_sensor_faults(out.sensor_faults, out.sensors, "--sensors")
    if out.sensors is not None:  # refused before any run, processes or in-process
        check_servable(out.sensors, 1_000_000 // out.physics_rate_hz,
                       1_000_000 // out.control_rate_hz)
    return out
