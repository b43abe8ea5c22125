"""What PX4 is given to sense on `sitl --protocol px4-hil`: the sensor profile (the
scenario's, else PX4's simulators' noisy sensors, config/sensors/px4-default.toml), the
warning for exact sensors that PX4 would call stale, and the physics step under the IMU
period."""

from __future__ import annotations

import math

from common.config.scenario import Scenario
from common.config.sensors import SensorProfile, resolve_sensor_profile, stale_sensors

PX4_PROFILE = "px4-default"  # the sensors where the scenario names none


def px4_sensor_profile(scenario: Scenario) -> SensorProfile:
    """The scenario's sensor profile, or PX4's simulators' noisy sensors (px4-default)."""
    if scenario.sensors is not None:
        return scenario.sensors
    return resolve_sensor_profile(PX4_PROFILE)


def stale_warning(profile: SensorProfile) -> str | None:
    """The one-line warning for a profile with exact sensors, None when all are noisy."""
    exact = stale_sensors(profile)
    if not exact:
        return None
    return (f"sitl: warning: sensor profile '{profile.name}' has exact {', '.join(exact)}: "
            "PX4 declares a sensor whose value repeats (100 samples, 1,000 for the "
            "magnetometer) stale at rest")


def physics_step_us(imu_us: int, physics_hz: int) -> int:
    """The longest physics step that divides the IMU period and is not longer than the
    scenario's step."""
    n = max(1, math.ceil(imu_us * physics_hz / 1_000_000))
    while imu_us % n:
        n += 1
    return imu_us // n
