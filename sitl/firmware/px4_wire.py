"""PX4's side of the simulator MAVLink API as the plant sees it: pure, no I/O.

- PX4's hexarotor X (airframe 6001_hexa_x, control allocation CA_ROTOR0..5): where each
  of PX4's motor outputs sits (FRD, normalised) and its spin (CA_ROTORn_KM > 0: the
  propeller turns counter-clockwise seen from above, so its drag torque yaws the body
  clockwise, +yaw in FRD); `motor_order` finds the plant's rotor under each output from the
  vehicle's geometry (`sitl.firmware.rotor_layout`) and refuses a vehicle whose rotors do not sit
  and spin as PX4 expects.
- `command_from_outputs`: HIL_ACTUATOR_CONTROLS as the plant obeys it. PX4's simulated PWM
  output (pwm_out_sim) scales a non-reversible motor to 0..1; rotor speed = output x
  w_max (linear; thrust ~ output^2, PX4's THR_MDL_FAC = 1). Zero unless SAFETY_ARMED; a
  value that is not finite stops that rotor; the tilts are held at 0 (a planar hexa).
- `gps_fields`, `state_fields`: HIL_GPS (from the fix, `sitl.sensors.GpsModel`) and
  HIL_STATE_QUATERNION (the exact state), in the units SimulatorMavlink.cpp reads (degE7,
  mm, cm/s, cdeg, mG). HIL_GPS carries eph/epv and satellites; it has no velocity
  accuracy field (PX4 sets its own s_variance_m_s on reading it).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.config.scenario import VehicleConfig
from common.config.sensors import EXACT_GPS, GpsConfig
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.geodetic import ned_to_geodetic
from common.wire.mission_items import HomePosition
from sitl.firmware.rotor_layout import rotors_for_outputs
from sitl.plant import ActuatorCommand, PlantState


class Px4Motor(NamedTuple):
    """One output of PX4's hexa X: position (CA_ROTORn_PX forward, _PY right) and spin."""

    px: float
    py: float
    km: float  # CA_ROTORn_KM: > 0 counter-clockwise seen from above


# ROMFS/px4fmu_common/init.d/airframes/6001_hexa_x (KM defaults to +0.05 where not set).
PX4_HEXA_X = (Px4Motor(0.0, 0.5, -0.05), Px4Motor(0.0, -0.5, 0.05),
              Px4Motor(0.43, -0.25, -0.05), Px4Motor(-0.43, 0.25, 0.05),
              Px4Motor(0.43, 0.25, 0.05), Px4Motor(-0.43, -0.25, -0.05))
MODE_ARMED = 128  # MAV_MODE_FLAG_SAFETY_ARMED, as PX4 sets it in HIL_ACTUATOR_CONTROLS.mode
LOCKSTEP_FLAG = 1  # HIL_ACTUATOR_CONTROLS.flags bit 0: PX4 built with the lockstep scheduler


def motor_order(vehicle: VehicleConfig) -> tuple[int, ...]:
    """The plant's rotor index under each of PX4's hexa X outputs (MAIN1..6); ConfigError
    when the vehicle is not a planar hexa with PX4's positions and spins."""
    layout = [(math.degrees(math.atan2(m.py, m.px)), 1 if m.km > 0 else -1)
              for m in PX4_HEXA_X]
    return rotors_for_outputs(vehicle, layout, "PX4's hexa X",
                              " (config/scenarios/px4_hexa.toml has PX4's spins)")


class Command(NamedTuple):
    command: ActuatorCommand
    nonfinite: int  # motor outputs that were NaN or infinite (their rotor stopped)


def command_from_outputs(controls: tuple[float, ...], mode: int, order: tuple[int, ...],
                         w_max_rad_s: float) -> Command:
    """The rotor speeds PX4's motor outputs ask (controls[k] -> rotor order[k], 0..1 of
    w_max, clamped), all zero unless armed; tilts 0."""
    n = len(order)
    speeds = [0.0] * n
    bad = 0
    armed = bool(mode & MODE_ARMED)
    for k, rotor in enumerate(order):
        u = controls[k]
        if not math.isfinite(u):
            bad += 1
            continue
        if armed:
            speeds[rotor] = min(max(u, 0.0), 1.0) * w_max_rad_s
    return Command(ActuatorCommand(tuple(speeds), (0.0,) * n), bad)


class GpsFields(NamedTuple):
    """HIL_GPS as PX4 reads it."""

    time_usec: int
    fix_type: int
    lat: int  # degE7
    lon: int  # degE7
    alt: int  # mm AMSL
    eph: int  # cm
    epv: int  # cm
    vel: int  # ground speed, cm/s
    vn: int  # cm/s NED
    ve: int
    vd: int
    cog: int  # cdeg, 0..35999; 65535 unknown
    satellites_visible: int


class StateFields(NamedTuple):
    """HIL_STATE_QUATERNION (ground truth) as PX4 reads it."""

    time_usec: int
    attitude_quaternion: tuple[float, float, float, float]  # NED -> FRD, (w, x, y, z)
    rollspeed: float  # FRD, rad/s
    pitchspeed: float
    yawspeed: float
    lat: int  # degE7
    lon: int
    alt: int  # mm AMSL
    vx: int  # cm/s NED
    vy: int
    vz: int
    ind_airspeed: int  # cm/s (no wind: the ground speed)
    true_airspeed: int
    xacc: int  # mG, FRD specific force (what an accelerometer reads)
    yacc: int
    zacc: int


GPS_FIX_3D = 3
COG_MIN_SPEED_M_S = 0.1  # below this the course over ground is unknown (65535)
G0_M_S2 = 9.80665


def _i16(v: float) -> int:
    return max(-32768, min(32767, round(v)))


def _u16(v: float) -> int:
    return max(0, min(65535, round(v)))


def _geodetic(s: PlantState, home: HomePosition) -> tuple[int, int, int]:
    lat, lon, alt = ned_to_geodetic(enu_to_ned(s.p_enu_m), *home)
    return round(lat * 1e7), round(lon * 1e7), round(alt * 1e3)


def gps_fields(s: PlantState, home: HomePosition, gps: GpsConfig = EXACT_GPS) -> GpsFields:
    """The GPS fix of the state (its position and velocity as the fix has them), 3D, with
    the accuracies and satellites of `gps` (default: 1 m, 10 satellites)."""
    lat, lon, alt = _geodetic(s, home)
    vn, ve, vd = enu_to_ned(s.v_enu_m_s)
    speed = math.hypot(vn, ve)
    cog = 65535 if speed < COG_MIN_SPEED_M_S else \
        round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100.0) % 36000
    return GpsFields(s.time_us, GPS_FIX_3D, lat, lon, alt, _u16(gps.eph_m * 100.0),
                     _u16(gps.epv_m * 100.0), _u16(speed * 100.0), _i16(vn * 100.0),
                     _i16(ve * 100.0), _i16(vd * 100.0), cog, gps.satellites)


def state_fields(s: PlantState, home: HomePosition, f_flu_m_s2: tuple[float, float, float]
                 ) -> StateFields:
    """The exact state; `f_flu_m_s2` is the specific force (Plant.specific_force_flu)."""
    lat, lon, alt = _geodetic(s, home)
    v = enu_to_ned(s.v_enu_m_s)
    w = flu_to_frd(s.omega_flu_rad_s)
    f = flu_to_frd(f_flu_m_s2)
    speed = _u16(math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2) * 100.0)
    mg = 1000.0 / G0_M_S2
    return StateFields(s.time_us, q_enu_flu_to_ned_frd(s.q_enu_flu), w[0], w[1], w[2],
                       lat, lon, alt, _i16(v[0] * 100.0), _i16(v[1] * 100.0),
                       _i16(v[2] * 100.0), speed, speed, _i16(f[0] * mg), _i16(f[1] * mg),
                       _i16(f[2] * mg))

