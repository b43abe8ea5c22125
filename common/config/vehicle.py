"""The vehicle's physical parameters (docs/model.md#vehicle) from TOML (config/vehicles/), read
and checked by `common.config.reader`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.config.keys import Key, KeyTable
from common.config.reader import ConfigError, Table, read_toml
from common.vehicle_constants import N_ROTORS

Vec3 = tuple[float, float, float]


VEHICLE_KEYS = KeyTable("", (
    Key("name", "string", "the vehicle's name"),
    Key("mass_kg", "number", "mass", "kg", lo=0.0, lo_open=True),
    Key("inertia_diag_kg_m2", "vec3", "the principal moments of inertia (body FLU)", "kg m^2",
        lo=0.0, lo_open=True),
    Key("arm_length_m", "number", "arm length, CoM to rotor hub", "m", lo=0.0, lo_open=True),
    Key("n_rotors", "integer", "the number of arms: the logs and the simulator link carry "
        "six rotor speeds and six tilts", range_doc=f"{N_ROTORS} only"),
    Key("arm_azimuth_deg", "numbers", "each arm's azimuth from +x towards +y", "deg",
        n=N_ROTORS, default_doc="30, 90, ..., 330"),
    Key("arm_elevation_rad", "numbers", "each arm's elevation (> 0 puts the tip below the hub)",
        "rad", n=N_ROTORS, lo=-math.pi / 2, hi=math.pi / 2),
    Key("spin", "raw", "each rotor's spin direction (+1 counter-clockwise)",
        type_doc=f"list of {N_ROTORS} integers", range_doc="+1 or -1"),
    Key("thrust_coeff", "number", "c_f: thrust = c_f w^2", "N s^2/rad^2", lo=0.0, lo_open=True),
    Key("drag_coeff", "number", "c_d: drag torque = c_d w^2", "N m s^2/rad^2", lo=0.0),
    Key("rotor_speed_max_rad_s", "number", "the rotors' speed limit", "rad/s", lo=0.0,
        lo_open=True),
    Key("rotor_tau_up_s", "number", "the rotor lag's time constant, speeding up", "s",
        lo=0.0, lo_open=True),
    Key("rotor_tau_down_s", "number", "the rotor lag's time constant, slowing down", "s",
        lo=0.0, lo_open=True),
    Key("tilt_rate_max_rad_s", "number", "the tilt servos' rate limit", "rad/s",
        lo=0.0, lo_open=True),
    Key("gravity_m_s2", "number", "gravity", "m/s^2", 9.81, lo=0.0),
))


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
    k = VEHICLE_KEYS
    name = k["name"].read(t)
    mass = k["mass_kg"].read(t)
    inertia = k["inertia_diag_kg_m2"].read(t)
    arm = k["arm_length_m"].read(t)
    n = k["n_rotors"].read(t)
    if n != N_ROTORS:
        raise ConfigError(
            f"{source}: key 'n_rotors': expected {N_ROTORS}, got {n!r}: hexarotor only "
            f"(the logs and the simulator link carry six rotor speeds and six tilts)")
    if t.has("arm_azimuth_deg"):
        azimuth = tuple(math.radians(v) for v in k["arm_azimuth_deg"].read(t))
    else:
        # The paper's gamma_i = pi/3 i - pi/6 generalised to n arms.
        azimuth = tuple(2.0 * math.pi * (i + 1) / n - math.pi / n for i in range(n))
    elevation = k["arm_elevation_rad"].read(t)
    spin_raw = k["spin"].read(t)
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
        thrust_coeff=k["thrust_coeff"].read(t),
        drag_coeff=k["drag_coeff"].read(t),
        rotor_speed_max_rad_s=k["rotor_speed_max_rad_s"].read(t),
        rotor_tau_up_s=k["rotor_tau_up_s"].read(t),
        rotor_tau_down_s=k["rotor_tau_down_s"].read(t),
        tilt_rate_max_rad_s=k["tilt_rate_max_rad_s"].read(t),
        gravity_m_s2=k["gravity_m_s2"].read(t),
    )
    t.finish()
    return vehicle


def load_vehicle(path: str | Path) -> VehicleConfig:
    path = Path(path)
    return parse_vehicle(read_toml(path), str(path))
