"""Sensors at their own rates, off the physics grid: sample k exactly at k / rate (integer
microseconds, no drift), taken from the state at that instant, optionally jittered (seeded,
bounded, in order); what the plant cannot serve refused when the profile meets the scenario,
naming the file and the key."""

from __future__ import annotations

import dataclasses
import math
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import ConfigError, load_scenario
from common.config.sensors import (
    SensorProfile,
    check_servable,
    load_sensor_profile,
    resolve_sensor_profile,
)
from common.frames import flu_to_frd, ned_to_enu
from common.quaternion import q_angle, q_conj, q_exp, q_mul, q_rotate_inv
from common.wire.simlink import HilSensor, Odometry
from sitl.plant import Plant, PlantState, initial_state
from sitl.sensor_feed import MAG_FIELDS, SensorFeed, state_at
from sitl.sensors import SampleClock, sensor_rng

ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"
INDOOR = ROOT / "config" / "sensors" / "mocap-indoor.toml"
SCENARIO = load_scenario(CASE1)
V_ENU_M_S = (1.5, -0.7, 0.4)


def _profile(**mocap: float) -> SensorProfile:
    """mocap-indoor without noise, latency or dropouts, the motion capture changed."""
    p = resolve_sensor_profile("mocap-indoor")
    m = dataclasses.replace(p.mocap, position_noise_m=0.0, attitude_noise_rad=0.0,
                            latency_s=0.0, **mocap)
    return dataclasses.replace(p, mocap=m)


def _moving(t_us: int) -> PlantState:
    """A vehicle flying straight and level at V_ENU_M_S, turning about its z axis at 1 rad/s
    (what the feed samples: position, velocity, attitude, rate)."""
    base = initial_state(SCENARIO, Plant(SCENARIO.vehicle))
    t = t_us * 1e-6
    return base._replace(time_us=t_us, p_enu_m=(V_ENU_M_S[0] * t, V_ENU_M_S[1] * t,
                                                2.0 + V_ENU_M_S[2] * t),
                         v_enu_m_s=V_ENU_M_S, q_enu_flu=q_exp((0.0, 0.0, t)),
                         omega_flu_rad_s=(0.0, 0.0, 1.0), landed=False)


def _fly(profile: SensorProfile, dt_us: int, steps: int, t0_us: int = 0,
         seed: int = 1) -> list[HilSensor | Odometry]:
    feed = SensorFeed(profile, seed, Plant(SCENARIO.vehicle, dt_us=dt_us), 2000)
    out = feed.period([_moving(t0_us)])
    for n in range(1, steps + 1):
        out += feed.period([_moving(t0_us + n * dt_us)])
    return out


def _poses(msgs: list[HilSensor | Odometry]) -> list[Odometry]:
    return [m for m in msgs if isinstance(m, Odometry)]


# ---------------------------------------------------------------------- the sample clock


def test_a_120_hz_clock_is_exact_and_drift_free_over_a_million_samples():
    """Sample k at round(k * 1e6 / 120) us: within half a microsecond of k / 120 s for every
    k, each second exactly on its microsecond, and after 10^6 samples at 8333333333 us
    (a clock adding the rounded period 8333 us would be 333 ms late by then)."""
    c = SampleClock(120.0)
    c.start(0)
    times = np.array([c.take()[0] for _ in range(1_000_001)], dtype=np.int64)
    k = np.arange(times.size, dtype=np.int64)
    assert np.abs(times - k * (1e6 / 120.0)).max() <= 0.5
    assert np.array_equal(times[::120], k[::120] // 120 * 1_000_000)
    assert times[-1] == 8_333_333_333
    assert set(np.diff(times).tolist()) == {8333, 8334}


@pytest.mark.parametrize("rate_hz", [100.0, 200.0, 400.0, 1000.0])
def test_a_rate_on_the_grid_samples_on_exact_multiples_of_its_period(rate_hz):
    c = SampleClock(rate_hz)
    c.start(0)
    period = round(1e6 / rate_hz)
    assert [c.take() for _ in range(5)] == [(k * period, period) for k in range(5)]


def test_a_clock_started_late_takes_the_first_sample_due_and_keeps_the_grid():
    c = SampleClock(120.0)
    c.start(10_000)  # samples at 8333 (before) and 16667
    assert c.take() == (16_667, 8333)  # the nominal interval before the first
    assert c.take() == (25_000, 8333)
    c = SampleClock(333.0)
    c.start(3003)  # 1e6/333 = 3003.003: sample 1 is due at 3003 itself
    assert c.take()[0] == 3003


@pytest.mark.parametrize("dt_us", [1000, 833])
def test_a_120_hz_feed_stamps_every_pose_exactly_on_a_1000_and_an_833_us_step(dt_us):
    """Through the feed, started late on the clock (10^6 frames in), on ArduCopter's 833 us
    JSON step and on the 1 ms step: every frame exactly at round(k * 1e6 / 120) us, none
    missing, each sent in the physics step that reaches its instant."""
    t0 = (1_000_000 * 1_000_000 + 60) // 120  # frame 10^6: 8333333333 us
    t0 -= t0 % dt_us
    msgs = _fly(_profile(rate_hz=120.0), dt_us, steps=round(2.0e6 / dt_us), t0_us=t0)
    stamps = [m.time_usec for m in _poses(msgs)]
    k0 = -(-t0 * 120 // 1_000_000)
    want = [(2 * k * 1_000_000 + 120) // 240 for k in range(k0, k0 + len(stamps))]
    assert stamps == want and len(stamps) == 240
    assert stamps[0] - t0 < 8334


# ------------------------------------------------------------------- state at an instant


def test_a_sample_on_the_grid_is_the_physics_state_itself():
    a, b = _moving(8000), _moving(9000)
    assert state_at(a, b, 9000) is b


def test_a_sample_between_two_steps_is_the_state_at_its_instant():
    """Position, velocity and rate linear, attitude on the geodesic: at 8333 us between the
    steps at 8000 and 9000 us the state of a vehicle moving uniformly is its true one."""
    a, b = _moving(8000), _moving(9000)
    s = state_at(a, b, 8333)
    want = _moving(8333)
    assert s.time_us == 8333
    assert s.p_enu_m == pytest.approx(want.p_enu_m, abs=1e-12)
    assert s.v_enu_m_s == pytest.approx(want.v_enu_m_s, abs=1e-12)
    assert q_angle(q_mul(q_conj(s.q_enu_flu), want.q_enu_flu)) < 1e-9
    assert s.landed == a.landed


def test_a_120_hz_pose_carries_the_position_at_its_stamp_not_at_the_step_before():
    """Noise-free motion capture at 120 Hz on a vehicle at 1.7 m/s: each pose's position is
    the true one at its stamp (the step before it would be off by up to 0.3 ms of flight,
    0.5 mm)."""
    for m in _poses(_fly(_profile(rate_hz=120.0), 1000, steps=200)):
        t = m.time_usec * 1e-6
        want_ned = (V_ENU_M_S[1] * t, V_ENU_M_S[0] * t, -(2.0 + V_ENU_M_S[2] * t))
        assert m.p_ned_m == pytest.approx(want_ned, abs=1e-9), m.time_usec


def test_a_pose_goes_out_before_the_first_imu_sample_at_or_after_its_delivery():
    """On the grid (200 Hz, no latency) the pose of 5000 us precedes the IMU sample of 5000
    us; off it (120 Hz) the pose of 8333 us precedes the IMU sample of 9000 us."""
    for rate_hz, pose_us, imu_us in ((200.0, 5000, 5000), (120.0, 8333, 9000)):
        msgs = _fly(_profile(rate_hz=rate_hz), 1000, steps=12)
        i = next(i for i, m in enumerate(msgs)
                 if isinstance(m, Odometry) and m.time_usec == pose_us)
        assert isinstance(msgs[i + 1], HilSensor) and msgs[i + 1].time_usec == imu_us
        assert isinstance(msgs[i - 1], HilSensor) and msgs[i - 1].time_usec == imu_us - 1000


def test_magnetometer_and_barometer_off_the_imu_grid_ride_on_the_next_imu_sample():
    """A 75 Hz magnetometer (every 13333.3 us) on a 1 kHz IMU: 75 flagged HIL_SENSOR in a
    second, each the first IMU sample at or after its instant, with the field at its instant
    (the vehicle turns at 1 rad/s: the IMU's instant would show another heading)."""
    p = resolve_sensor_profile("mocap-indoor")
    p = dataclasses.replace(p, mag=dataclasses.replace(p.mag, rate_hz=75.0, noise_gauss=0.0))
    msgs = [m for m in _fly(p, 1000, steps=1000) if isinstance(m, HilSensor)]
    flagged = [m for m in msgs if m.fields_updated & MAG_FIELDS]
    due = [(2 * k * 1_000_000 + 75) // 150 for k in range(76)]
    assert [m.time_usec for m in flagged] == [-(-t // 1000) * 1000 for t in due]
    b_enu = ned_to_enu(p.mag.field_ned_gauss)
    for m, t in zip(flagged, due, strict=True):
        want = flu_to_frd(q_rotate_inv(_moving(t).q_enu_flu, b_enu))
        assert m.mag_frd_gauss == pytest.approx(want, abs=1e-9), t
    assert all(math.isnan(m.mag_frd_gauss[0]) for m in msgs if m not in flagged)


# ---------------------------------------------------------------------------- jitter


def test_jitter_is_bounded_seeded_reproducible_and_in_order():
    def stamps(seed: int, jitter_s: float = 0.002) -> list[int]:
        c = SampleClock(120.0, jitter_s, sensor_rng(seed, "mocap.jitter"))
        c.start(0)
        return [c.take()[0] for _ in range(20_000)]

    nominal = stamps(0, 0.0)
    a = stamps(7)
    offsets = np.array(a) - np.array(nominal)
    assert np.abs(offsets).max() <= 2000 and np.abs(offsets).max() > 1900
    assert abs(offsets.mean()) < 30 and offsets.std() > 1000  # uniform: sd 2000/sqrt(3)
    assert a == stamps(7) and a != stamps(8)
    assert all(np.diff(a) > 0)
    with pytest.raises(ValueError, match="Generator"):
        SampleClock(120.0, 0.001)


def test_a_jittered_motion_capture_is_stamped_with_its_jittered_instant():
    """Poses at their jittered instants (within jitter_s of k / rate), the same for the same
    seed, the IMU's stream untouched by the motion capture's jitter."""
    plain = _fly(_profile(rate_hz=120.0), 1000, steps=1000)
    jit = _fly(_profile(rate_hz=120.0, jitter_s=0.003), 1000, steps=1000)
    t_plain = [m.time_usec for m in _poses(plain)]
    t_jit = [m.time_usec for m in _poses(jit)]
    assert len(t_jit) == len(t_plain)
    d = np.array(t_jit) - np.array(t_plain)
    assert np.abs(d).max() <= 3000 and np.count_nonzero(d) > len(d) // 2
    for m in _poses(jit):  # taken at its own instant, not at its nominal one
        t = m.time_usec * 1e-6
        assert m.p_ned_m[1] == pytest.approx(V_ENU_M_S[0] * t, abs=1e-9)
    assert [m.time_usec for m in _poses(_fly(_profile(rate_hz=120.0, jitter_s=0.003), 1000,
                                              steps=1000))] == t_jit
    imu = [repr(m) for m in plain if isinstance(m, HilSensor)]
    assert imu == [repr(m) for m in jit if isinstance(m, HilSensor)]


# ---------------------------------------------------------------------------- refusals


def _write(tmp_path: Path, name: str, *edits: tuple[str, str]) -> Path:
    text = INDOOR.read_text()
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


MOCAP_RATE = "rate_hz = 200.0  # Qualisys"


@pytest.mark.parametrize(("edits", "message"), [
    ([(MOCAP_RATE, "jitter_s = 0.0025\nrate_hz = 200.0  #")],
     "mocap.jitter_s = 0.0025 is not below half the sample period (0.0025 s at 200 Hz)"),
    ([(MOCAP_RATE, "jitter_s = -0.001\nrate_hz = 200.0  #")], "key 'mocap.jitter_s'"),
    ([(MOCAP_RATE, 'jitter_s = "1 ms"\nrate_hz = 200.0  #')], "key 'mocap.jitter_s'"),
    ([(MOCAP_RATE, "rate_hz = 0.0  #")], "key 'mocap.rate_hz'"),
    ([(MOCAP_RATE, "rate_hz = -120.0  #")], "key 'mocap.rate_hz'"),
    ([("noise_gauss = 0.002", "noise_gauss = 0.002\njitter = 0.001")],
     "unknown key 'mag.jitter'"),
    ([("rate_hz = 100.0\n# WMM", "rate_hz = 2000.0\n# WMM")],
     "mag.rate_hz = 2000 is faster than imu.rate_hz = 1000"),
])
def test_the_loader_refuses_what_no_plant_serves_naming_file_and_key(tmp_path, edits,
                                                                     message):
    path = _write(tmp_path, "bad-profile.toml", *edits)
    with pytest.raises(ConfigError) as err:
        load_sensor_profile(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)


@pytest.mark.parametrize(("edits", "message"), [
    ([(MOCAP_RATE, "rate_hz = 5000.0  #")],
     "mocap.rate_hz = 5000 is faster than the physics step allows (1000 us: at most 1000 Hz)"),
    ([("rate_hz = 1000.0  # ICM", "rate_hz = 750.0  # ICM")],
     "imu.rate_hz = 750 puts no sample at the end of every 2000 us control period"),
    ([("vibration_factor = 10.0", "vibration_factor = 10.0\njitter_s = 0.0001")],
     "imu.jitter_s = 0.0001: the IMU's sample at the end of each control period"),
])
def test_a_scenario_refuses_a_profile_its_plant_cannot_serve(tmp_path, edits, message):
    """At the scenario's load (key `sensors`) and when --sensors overrides it, before any
    run: the message names the profile's file and its key."""
    from gcs.run.overrides import apply_overrides

    path = _write(tmp_path, "mocap-fast.toml", *edits)
    profile = load_sensor_profile(path)  # loads: it is the scenario's rates it cannot meet
    with pytest.raises(ConfigError) as err:
        check_servable(profile, 1000, 2000)
    assert str(err.value).startswith(f"{path}: {message}")
    with pytest.raises(ConfigError, match=re.escape(message.split(" (")[0])):
        apply_overrides(SCENARIO, sensors=str(path))
    text = CASE1.read_text().replace("seed = 0\n", f"seed = 0\nsensors = \"{path}\"\n")
    for key in ("vehicle", "pid", "pd"):
        text = text.replace(f'{key} = "../', f'{key} = "{CASE1.parent.parent}/')
    scenario = tmp_path / "scenario.toml"
    scenario.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(str(path))):
        load_scenario(scenario)


def test_the_physics_step_and_control_period_decide_what_is_servable():
    """A 1200 Hz IMU is served on ArduCopter's 833 us step (1200.5 Hz), not on 1 ms; the
    truth profile is never sampled, so nothing is refused for it."""
    p = resolve_sensor_profile("mocap-indoor")
    fast = dataclasses.replace(p, imu=dataclasses.replace(p.imu, rate_hz=1200.0))
    check_servable(fast, 833, 2500)
    with pytest.raises(ConfigError, match=r"imu\.rate_hz = 1200 is faster"):
        check_servable(fast, 1000, 2500)
    with pytest.raises(ConfigError, match=r"imu\.rate_hz = 1200 puts no sample"):
        check_servable(fast, 833, 2000)
    check_servable(resolve_sensor_profile("truth"), 5000, 5000)
    with pytest.raises(ConfigError, match="faster than the physics step"):
        SensorFeed(p, 0, Plant(SCENARIO.vehicle, dt_us=2000), 2000)


def test_shipped_profiles_load_and_the_120_hz_one_is_off_the_grid():
    p = resolve_sensor_profile("mocap-120hz")
    assert p.mocap.rate_hz == 120.0 and p.mocap.jitter_s == 0.0
    assert Fraction(1_000_000) / Fraction(p.mocap.rate_hz) % 1000 != 0
    check_servable(p, 1000, 2000)


def test_a_firmware_scenario_takes_the_firmwares_rates(tmp_path):
    """A scenario naming PX4's 250 Hz profile loads for a firmware protocol (the plant checks
    what the firmware gets when it serves it), and is refused for this project's FCU link,
    which needs 500 Hz and a sample at the end of every control period."""
    px4 = ROOT / "config" / "scenarios" / "px4_hexa.toml"
    text = px4.read_text().replace('seed = 0\n', 'seed = 0\nsensors = "px4-default"\n')
    text = text.replace('vehicle = "../', f'vehicle = "{px4.parent.parent}/')
    for key in ("pid", "pd"):
        text = text.replace(f'{key} = "../', f'{key} = "{px4.parent.parent}/')
    path = tmp_path / "px4_noisy.toml"
    path.write_text(text)
    assert load_scenario(path, firmware=True).sensors.imu.rate_hz == 250.0
    with pytest.raises(ConfigError, match=r"imu\.rate_hz = 250 is below 500 Hz"):
        load_scenario(path)
