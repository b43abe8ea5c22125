"""The vehicle's physical parameters (docs/model.md#vehicle) from TOML (config/vehicles/), read
and checked by `common.config.reader`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.config.reader import ConfigError, Table, read_toml
from common.vehicle_constants import N_ROTORS

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class VehicleConfig:
    """Physical parameters of a tilt-rotor multirotor; body frame FLU, origin at the CoM."""

    name: str
    mass_kg: float
    inertia_diag_kg_m2: Vec3
    arm_length_m: float
    arm_azimuth_rad: tuple[float, ...]
    arm_elevation_rad: tuple[float, ...]
    spin: tuple[int, ...]
    thrust_coeff: float  # c_f, N s^2/rad^2
    drag_coeff: float  # c_d, N m s^2/rad^2
    rotor_speed_max_rad_s: float
    rotor_tau_up_s: float
    rotor_tau_down_s: float
    tilt_rate_max_rad_s: float
    gravity_m_s2: float = 9.81

    @property
    def n_rotors(self) -> int:
        return len(self.arm_azimuth_rad)


def parse_vehicle(data: dict[str, Any], source: str) -> VehicleConfig:
    t = Table(data, source)
    name = t.string("name")
    mass = t.number("mass_kg", lo=0.0, lo_open=True)
    inertia = t.vec3("inertia_diag_kg_m2", lo=0.0, lo_open=True)
    arm = t.number("arm_length_m", lo=0.0, lo_open=True)
    n = t.integer("n_rotors")
    if n != N_ROTORS:
        raise ConfigError(
            f"{source}: key 'n_rotors': expected {N_ROTORS}, got {n!r}: hexarotor only "
            f"(the logs and the simulator link carry six rotor speeds and six tilts)")
    if t.has("arm_azimuth_deg"):
        azimuth = tuple(math.radians(v) for v in t.numbers("arm_azimuth_deg", n))
    else:
        # The paper's gamma_i = pi/3 i - pi/6 generalised to n arms.
        azimuth = tuple(2.0 * math.pi * (i + 1) / n - math.pi / n for i in range(n))
    elevation = t.numbers("arm_elevation_rad", n, lo=-math.pi / 2, hi=math.pi / 2)
    spin_raw = t.raw("spin")
    if (not isinstance(spin_raw, list) or len(spin_raw) != n
            or any(s not in (1, -1) or isinstance(s, bool) for s in spin_raw)):
        raise t.error("spin", f"a list of {n} values, each +1 or -1")
    vehicle = VehicleConfig(
        name=name,
        mass_kg=mass,
        inertia_diag_kg_m2=inertia,
        arm_length_m=arm,
        arm_azimuth_rad=azimuth,
        arm_elevation_rad=elevation,
        spin=tuple(int(s) for s in spin_raw),
        thrust_coeff=t.number("thrust_coeff", lo=0.0, lo_open=True),
        drag_coeff=t.number("drag_coeff", lo=0.0),
        rotor_speed_max_rad_s=t.number("rotor_speed_max_rad_s", lo=0.0, lo_open=True),
        rotor_tau_up_s=t.number("rotor_tau_up_s", lo=0.0, lo_open=True),
        rotor_tau_down_s=t.number("rotor_tau_down_s", lo=0.0, lo_open=True),
        tilt_rate_max_rad_s=t.number("tilt_rate_max_rad_s", lo=0.0, lo_open=True),
        gravity_m_s2=t.number("gravity_m_s2", 9.81, lo=0.0),
    )
    t.finish()
    return vehicle


def load_vehicle(path: str | Path) -> VehicleConfig:
    path = Path(path)
    return parse_vehicle(read_toml(path), str(path))
