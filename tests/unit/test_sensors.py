"""Sensor models (sitl.sensors) and their profiles (common.config.sensors)."""

from __future__ import annotations

import dataclasses
import math
import zlib
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import ConfigError
from common.config.sensors import (
    AccelConfig,
    GyroConfig,
    ImuConfig,
    MocapConfig,
    load_sensor_profile,
)
from common.frames import ned_to_enu
from common.quaternion import q_angle, q_conj, q_exp, q_mul, q_rotate_inv
from sitl.sensors import BaroModel, ImuModel, MagModel, MocapModel, SensorSuite, _Normals

ROOT = Path(__file__).resolve().parents[2]
PROFILES = ROOT / "config" / "sensors"

ZERO = (0.0, 0.0, 0.0)


def _imu(rate_hz: float = 1000.0, vib: float = 1.0, n_gyro: float = 0.0, n_acc: float = 0.0,
         b0_gyro: float = 0.0, rw_gyro: float = 0.0, range_gyro: float = 35.0,
         range_acc: float = 157.0) -> ImuConfig:
    return ImuConfig(rate_hz, vib, GyroConfig(n_gyro, b0_gyro, rw_gyro, range_gyro),
                     AccelConfig(n_acc, 0.0, 0.0, range_acc))


def _gyro_errors(cfg: ImuConfig, seed: int, n: int) -> np.ndarray:
    m = ImuModel(cfg, seed)
    dt = 1.0 / cfg.rate_hz
    return np.array([m.sample(i * dt, dt, ZERO, ZERO).omega_flu_rad_s for i in range(n)])


# ------------------------------------------------------------------------------- IMU


@pytest.mark.parametrize("rate_hz", [500.0, 1000.0, 4000.0])
def test_white_noise_sigma_is_density_times_sqrt_rate(rate_hz):
    n_g, n_a, samples = 4.9e-5, 6.67e-4, 20000
    m = ImuModel(_imu(rate_hz, n_gyro=n_g, n_acc=n_a), seed=1)
    dt = 1.0 / rate_hz
    out = [m.sample(i * dt, dt, (0.1, -0.2, 0.3), (0.0, 0.0, 9.81)) for i in range(samples)]
    g = np.array([s.omega_flu_rad_s for s in out]) - (0.1, -0.2, 0.3)
    a = np.array([s.f_flu_m_s2 for s in out]) - (0.0, 0.0, 9.81)
    # the sample sd of 20000 normals is within 3 % of sigma with overwhelming probability
    assert np.std(g, axis=0) == pytest.approx([n_g * math.sqrt(rate_hz)] * 3, rel=0.03)
    assert np.std(a, axis=0) == pytest.approx([n_a * math.sqrt(rate_hz)] * 3, rel=0.03)
    assert np.abs(np.mean(g, axis=0)).max() < 4 * n_g * math.sqrt(rate_hz) / math.sqrt(samples)


def test_vibration_factor_scales_white_noise():
    base = np.std(_gyro_errors(_imu(n_gyro=1e-4, vib=1.0), 3, 20000), axis=0)
    vib = np.std(_gyro_errors(_imu(n_gyro=1e-4, vib=10.0), 3, 20000), axis=0)
    assert vib / base == pytest.approx([10.0] * 3, rel=1e-9)  # same stream: exactly 10x
    assert vib == pytest.approx([10.0 * 1e-4 * math.sqrt(1000.0)] * 3, rel=0.03)


def test_turn_on_bias_constant_per_seed_and_differs_across_seeds():
    cfg = _imu(b0_gyro=0.002)
    a, b, c = ImuModel(cfg, 7), ImuModel(cfg, 7), ImuModel(cfg, 8)
    assert a.gyro.bias == b.gyro.bias
    assert a.gyro.bias != c.gyro.bias
    first = a.sample(0.0, 1e-3, ZERO, ZERO).omega_flu_rad_s
    for i in range(1, 200):  # no white noise, no walk: every sample is the bias itself
        assert a.sample(i * 1e-3, 1e-3, ZERO, ZERO).omega_flu_rad_s == first
    assert first == a.gyro.bias
    # across many seeds the draws have the configured sigma
    biases = np.array([ImuModel(cfg, s).gyro.bias for s in range(3000)])
    assert np.std(biases) == pytest.approx(0.002, rel=0.05)


def test_bias_random_walk_variance_grows_linearly():
    rw, dt, steps, seeds = 1e-3, 1e-3, 400, 1000
    cfg = _imu(rw_gyro=rw)
    paths = np.array([_gyro_errors(cfg, s, steps)[:, 0] for s in range(seeds)])
    for k in (99, 199, 399):
        t = (k + 1) * dt
        var = np.var(paths[:, k])
        # var of a sample variance over 1000 normals: sd ~ 4.5 %; allow 15 %
        assert var == pytest.approx(rw * rw * t, rel=0.15), k
    assert np.var(paths[:, 399]) > 3.0 * np.var(paths[:, 99])


def test_gauss_markov_bias_is_bounded_with_its_correlation_time():
    """Given a correlation time tau (Gazebo classic's IMU plugin: 300 s accel, 1000 s
    gyro), the bias is first-order Gauss-Markov: from 0 its variance is
    s^2 tau/2 (1 - exp(-2t/tau)), below the random walk's s^2 t and bounded by s^2 tau/2;
    with tau the walk is unchanged for t << tau and the same draws are used."""
    rw, tau, dt, steps, seeds = 1e-3, 0.1, 1e-3, 400, 1000
    cfg = _imu(rw_gyro=rw)
    cfg = dataclasses.replace(cfg, gyro=dataclasses.replace(cfg.gyro,
                                                             bias_correlation_time_s=tau))
    paths = np.array([_gyro_errors(cfg, s, steps)[:, 0] for s in range(seeds)])
    for k in (49, 199, 399):
        t = (k + 1) * dt
        expect = rw * rw * tau / 2.0 * (1.0 - math.exp(-2.0 * t / tau))
        assert np.var(paths[:, k]) == pytest.approx(expect, rel=0.15), k
    assert np.var(paths[:, 399]) < 0.5 * rw * rw * 0.4  # the random walk's at 0.4 s
    # lag-one correlation of the stationary part: exp(-dt / tau)
    a, b = paths[:, 300:399].ravel(), paths[:, 301:400].ravel()
    assert np.corrcoef(a, b)[0, 1] == pytest.approx(math.exp(-dt / tau), abs=0.01)
    slow = dataclasses.replace(cfg, gyro=dataclasses.replace(cfg.gyro,
                                                              bias_correlation_time_s=1e9))
    assert _gyro_errors(slow, 3, 50) == pytest.approx(_gyro_errors(_imu(rw_gyro=rw), 3, 50),
                                                      rel=1e-6, abs=1e-15)


def test_px4_default_biases_are_gazebo_s_gauss_markov():
    p = load_sensor_profile(PROFILES / "px4-default.toml")
    assert p.imu.accel.bias_correlation_time_s == 300.0
    assert p.imu.gyro.bias_correlation_time_s == 1000.0
    assert p.imu.accel.contact_spread_s == 0.05
    for name in ("mocap-indoor", "degraded", "truth"):  # no key: unbounded, one sample
        other = load_sensor_profile(PROFILES / f"{name}.toml")
        assert other.imu.accel.bias_correlation_time_s is None
        assert other.imu.gyro.bias_correlation_time_s is None
        assert other.imu.accel.contact_spread_s == 0.0


def test_saturation_clips_each_axis():
    m = ImuModel(_imu(range_gyro=math.radians(2000.0), range_acc=16 * 9.80665), 0)
    s = m.sample(0.0, 1e-3, (100.0, -100.0, 1.0), (0.0, 200.0, -200.0))
    assert s.omega_flu_rad_s == (math.radians(2000.0), -math.radians(2000.0), 1.0)
    assert s.f_flu_m_s2 == (0.0, 16 * 9.80665, -16 * 9.80665)
    noisy = ImuModel(_imu(n_gyro=1.0, range_gyro=0.5), 0)
    g = np.array([noisy.sample(0.0, 1e-3, ZERO, ZERO).omega_flu_rad_s for _ in range(500)])
    assert np.abs(g).max() == 0.5


def test_same_seed_same_sequence_regardless_of_other_sensors():
    profile = load_sensor_profile(PROFILES / "degraded.toml")
    alone = SensorSuite.from_profile(profile, 42)
    mixed = SensorSuite.from_profile(profile, 42)
    q = (1.0, 0.0, 0.0, 0.0)
    imu_a, imu_b = [], []
    for i in range(300):
        t = i * 1e-3
        imu_a.append(alone.imu.sample(t, 1e-3, (0.1, 0.2, 0.3), (0.0, 0.0, 9.81)))
        mixed.baro.sample(t, (0.0, 0.0, 1.0))
        mixed.mag.sample(t, q)
        if i % 3 == 0:
            mixed.mocap.capture(t, (1.0, 2.0, 3.0), q)
        imu_b.append(mixed.imu.sample(t, 1e-3, (0.1, 0.2, 0.3), (0.0, 0.0, 9.81)))
    assert imu_a == imu_b
    for i in range(50):  # and the pose source: after 300 IMU samples vs on a fresh suite
        alone.mocap.capture(i * 0.01, (1.0, 2.0, 3.0), q)
    mocap_a = alone.mocap.deliver(10.0)
    fresh = SensorSuite.from_profile(profile, 42).mocap
    for i in range(50):
        fresh.capture(i * 0.01, (1.0, 2.0, 3.0), q)
    mocap_b = fresh.deliver(10.0)
    assert mocap_a == mocap_b and len(mocap_a) > 40
    other = SensorSuite.from_profile(profile, 43)
    assert other.imu.sample(0.0, 1e-3, ZERO, ZERO) != SensorSuite.from_profile(
        profile, 42).imu.sample(0.0, 1e-3, ZERO, ZERO)


# ------------------------------------------------------------------------- baro, mag


def test_baro_noise_and_bias():
    from common.config.sensors import BaroConfig
    m = BaroModel(BaroConfig(50.0, 0.1, 0.3), 5)
    h = np.array([m.sample(i * 0.02, (0.0, 0.0, 2.0)).alt_m for i in range(20000)])
    assert np.mean(h) == pytest.approx(2.3, abs=0.005)
    assert np.std(h) == pytest.approx(0.1, rel=0.03)


def test_mag_rotates_the_earth_field_into_flu():
    from common.config.sensors import MagConfig
    field_ned = (0.216, 0.012, 0.425)
    m = MagModel(MagConfig(100.0, field_ned, 0.0), 0)
    # body x east (identity ENU/FLU): north (ENU y) is body +y (left), down is body -z
    assert m.sample(0.0, (1.0, 0.0, 0.0, 0.0)).b_flu_gauss == pytest.approx(
        (0.012, 0.216, -0.425), abs=1e-15)
    q = q_exp((0.0, 0.0, math.pi / 2))  # yaw +90 deg about ENU up: body x north
    assert m.sample(0.0, q).b_flu_gauss == pytest.approx((0.216, -0.012, -0.425), abs=1e-12)
    noisy = MagModel(MagConfig(100.0, field_ned, 0.002), 0)
    b = np.array([noisy.sample(0.0, q).b_flu_gauss for _ in range(20000)])
    assert np.std(b, axis=0) == pytest.approx([0.002] * 3, rel=0.03)
    assert np.mean(b, axis=0) == pytest.approx(q_rotate_inv(q, ned_to_enu(field_ned)), abs=1e-4)


# ------------------------------------------------------------------------------ mocap


def test_mocap_delivers_each_capture_exactly_latency_later():
    cfg = MocapConfig(200.0, 0.0, 0.0, 0.0073, 0.0)  # latency not a multiple of the period
    m = MocapModel(cfg, 0)
    got = []
    dt_poll = 1e-4
    for k in range(20000):  # 2 s of polls at 10 kHz, captures every 5 ms
        t = k * dt_poll
        if k % 50 == 0:
            m.capture(t, (t, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
        for d in m.deliver(t):
            got.append((t, d))
    assert len(got) == 400 - 1  # the last capture (1.995 s, due 2.0023 s) is in flight
    for t_poll, d in got:
        assert d.delivered_s == d.capture_s + 0.0073
        assert d.delivered_s <= t_poll < d.delivered_s + dt_poll + 1e-12  # first poll after
        assert d.p_enu_m[0] == d.capture_s  # the pose is the one captured, not a later one
    caps = [d.capture_s for _, d in got]
    assert caps == sorted(caps)
    assert m.deliver(1e9)[0].capture_s == pytest.approx(got[-1][1].capture_s + 0.005)


def test_mocap_dropout_fraction():
    p, n = 0.01, 40000
    m = MocapModel(MocapConfig(100.0, 0.0, 0.0, 0.0, p), 9)
    for i in range(n):
        m.capture(i * 0.01, ZERO, (1.0, 0.0, 0.0, 0.0))
    delivered = len(m.deliver(1e9))
    assert delivered + m.dropped == n
    sd = math.sqrt(n * p * (1 - p))  # binomial
    assert abs(m.dropped - n * p) < 5 * sd
    assert m.dropped > 0


def test_mocap_attitude_and_position_noise_statistics():
    s_a, s_p, n = 1e-3, 2e-4, 20000
    m = MocapModel(MocapConfig(200.0, s_p, s_a, 0.0, 0.0), 11)
    q_true = q_exp((0.3, -0.2, 1.0))
    for i in range(n):
        m.capture(i * 0.005, (1.0, 2.0, 3.0), q_true)
    ds = m.deliver(1e9)
    angles = np.array([q_angle(q_mul(q_conj(q_true), d.q_enu_flu)) for d in ds])
    # |d| for d ~ N(0, s^2 I3): E|d|^2 = 3 s^2, E|d| = 2 s sqrt(2/pi) (Maxwell)
    assert np.mean(angles ** 2) == pytest.approx(3 * s_a * s_a, rel=0.05)
    assert np.mean(angles) == pytest.approx(2 * s_a * math.sqrt(2 / math.pi), rel=0.03)
    assert all(abs(math.fsum(c * c for c in d.q_enu_flu) - 1.0) < 1e-12 for d in ds)
    p = np.array([d.p_enu_m for d in ds]) - (1.0, 2.0, 3.0)
    assert np.std(p, axis=0) == pytest.approx([s_p] * 3, rel=0.03)


def test_mocap_rejects_time_going_back():
    m = MocapModel(MocapConfig(100.0, 0.0, 0.0, 0.01, 0.0), 0)
    m.capture(1.0, ZERO, (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        m.capture(0.5, ZERO, (1.0, 0.0, 0.0, 0.0))


# ---------------------------------------------------------------------------- profiles


def test_the_three_profiles_load():
    truth = load_sensor_profile(PROFILES / "truth.toml")
    indoor = load_sensor_profile(PROFILES / "mocap-indoor.toml")
    degraded = load_sensor_profile(PROFILES / "degraded.toml")
    assert truth.is_truth and not indoor.is_truth and not degraded.is_truth
    assert indoor.imu.gyro.noise_density_rad_s_sqrt_hz == pytest.approx(4.9e-5)
    assert indoor.imu.accel.noise_density_m_s2_sqrt_hz == pytest.approx(68e-6 * 9.80665,
                                                                          rel=0.02)
    assert indoor.imu.vibration_factor == 10.0
    assert indoor.imu.gyro.turn_on_bias_sigma_rad_s == 0.002
    assert indoor.imu.gyro.bias_random_walk_rad_s2_sqrt_hz > 0.0
    assert (indoor.mocap.rate_hz, indoor.mocap.position_noise_m, indoor.mocap.attitude_noise_rad,
            indoor.mocap.latency_s) == (200.0, 0.0002, 0.001, 0.005)
    assert degraded.imu.gyro.noise_density_rad_s_sqrt_hz == pytest.approx(2.4e-4)
    assert degraded.imu.accel.noise_density_m_s2_sqrt_hz == pytest.approx(175e-6 * 9.80665,
                                                                            rel=0.02)
    assert (degraded.mocap.rate_hz, degraded.mocap.latency_s,
            degraded.mocap.dropout_probability) == (100.0, 0.02, 0.01)
    for p in (truth, indoor, degraded):
        assert p.imu.rate_hz >= 500.0


def test_truth_profile_yields_exact_values():
    suite = SensorSuite.from_profile(load_sensor_profile(PROFILES / "truth.toml"), 123)
    omega, f = (0.123, -4.56, 7.89), (0.01, -0.02, 9.80665)
    q = q_exp((0.1, 0.2, -0.3))
    for i in range(100):
        t = i * 1e-3
        s = suite.imu.sample(t, 1e-3, omega, f)
        assert (s.t_s, s.omega_flu_rad_s, s.f_flu_m_s2) == (t, omega, f)
        assert suite.baro.sample(t, (1.0, 2.0, 3.25)).alt_m == 3.25
        assert suite.mag.sample(t, q).b_flu_gauss == q_rotate_inv(
            q, ned_to_enu(suite.mag.cfg.field_ned_gauss))
        suite.mocap.capture(t, (1.0, 2.0, 3.25), q)
        (d,) = suite.mocap.deliver(t)  # no latency: delivered at once
        assert (d.capture_s, d.delivered_s, d.p_enu_m, d.q_enu_flu) == (t, t, (1.0, 2.0, 3.25), q)


GOOD = (PROFILES / "mocap-indoor.toml").read_text()


@pytest.mark.parametrize(("old", "new", "key"), [
    ("noise_density_rad_s_sqrt_hz = 4.9e-5", "noise_density_rad_s_sqrt_hz = nan",
     "imu.gyro.noise_density_rad_s_sqrt_hz"),
    ("noise_density_m_s2_sqrt_hz = 6.67e-4", "noise_density_m_s2_sqrt_hz = -6.67e-4",
     "imu.accel.noise_density_m_s2_sqrt_hz"),
    ("noise_gauss = 0.002", "", "mag.noise_gauss"),
    ("latency_s = 0.005", 'latency_s = "5 ms"', "mocap.latency_s"),
    ("dropout_probability = 0.0", "dropout_probability = 1.5", "mocap.dropout_probability"),
    ("[imu]\nrate_hz = 1000.0", "[imu]\nrate_hz = 50.0", "imu.rate_hz"),
    ("[mocap]\nrate_hz = 200.0", "[mocap]\nrate_hz = 20000.0", "mocap.rate_hz"),
    ("[baro]\nrate_hz = 50.0", "[baro]\nrate_hz = 0.5", "baro.rate_hz"),
    ("vibration_factor = 10.0", "vibration_factor = inf", "imu.vibration_factor"),
    ("range_rad_s = 34.906585", "range_rad_s = 0.0", "imu.gyro.range_rad_s"),
    ("range_rad_s = 34.906585", "range_rad_s = 34.906585\nbias_correlation_time_s = 0.0",
     "imu.gyro.bias_correlation_time_s"),
    ("range_m_s2 = 156.9064", "range_m_s2 = 156.9064\nbias_correlation_time_s = -300.0",
     "imu.accel.bias_correlation_time_s"),
    ("range_m_s2 = 156.9064", "range_m_s2 = 156.9064\ncontact_spread_s = -0.05",
     "imu.accel.contact_spread_s"),
    ("field_ned_gauss = [0.216, 0.012, 0.425]", "field_ned_gauss = [0.2, 0.4]",
     "mag.field_ned_gauss"),
    ("bias_m = 0.0", "bias_m = 0.0\nbias_ft = 1.0", "baro.bias_ft"),
    ('kind = "model"', 'kind = "perfect"', "kind"),
    ('kind = "model"', "kind = 1", "kind"),
])
def test_bad_profiles_name_the_file_and_key(tmp_path, old, new, key):
    assert GOOD.count(old) == 1, old
    bad = tmp_path / "bad.toml"
    bad.write_text(GOOD.replace(old, new))
    with pytest.raises(ConfigError) as exc:
        load_sensor_profile(bad)
    assert str(bad) in str(exc.value)
    assert f"'{key}'" in str(exc.value)


def test_truth_profile_with_noise_is_refused(tmp_path):
    text = (PROFILES / "truth.toml").read_text().replace("latency_s = 0.0", "latency_s = 0.01")
    bad = tmp_path / "truth.toml"
    bad.write_text(text)
    with pytest.raises(ConfigError, match=r"'mocap\.latency_s'"):
        load_sensor_profile(bad)


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        load_sensor_profile(tmp_path / "nope.toml")
    (tmp_path / "x.toml").write_text("name = ")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_sensor_profile(tmp_path / "x.toml")


def test_profile_is_frozen():
    p = load_sensor_profile(PROFILES / "truth.toml")
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.kind = "model"  # type: ignore[misc]


def test_each_sensor_has_its_own_stream():
    m = ImuModel(_imu(n_gyro=1e-3, n_acc=1e-3), 0)
    s = m.sample(0.0, 1e-3, ZERO, ZERO)
    assert s.omega_flu_rad_s != s.f_flu_m_s2  # gyro and accel draw from different streams


def test_draws_fetched_in_blocks_are_the_stream_of_one_call_per_sample():
    """Given two Generators of one seed, then the triads' block-fetched normals (across
    several block boundaries) are, bit for bit, what one rng.normal(0, 1, 6) per sample
    gives: a sensor's noise does not depend on how its draws are fetched."""
    blocks = _Normals(np.random.default_rng(7), 6, block=5)
    calls = np.random.default_rng(7)
    for _ in range(23):
        assert blocks.take() == calls.normal(0.0, 1.0, 6).tolist()


def test_mag_and_mocap_noise_are_numpy_element_wise_to_the_bit():
    """The magnetometer's and the motion capture's noise added on floats give numpy's
    element-wise p + s n to the bit (the same Generator draws, in the same order)."""
    from common.config.sensors import MagConfig
    field_ned = (0.216, 0.012, 0.425)
    mag = MagModel(MagConfig(100.0, field_ned, 0.002), 3)
    ref = np.random.default_rng(np.random.SeedSequence([3, _crc("mag")]))
    cfg = MocapConfig(200.0, 2e-4, 1e-3, 0.0, 0.0)
    mocap = MocapModel(cfg, 5)
    ref_m = np.random.default_rng(np.random.SeedSequence([5, _crc("mocap")]))
    rng = np.random.default_rng(8)
    for k in range(300):
        v = rng.normal(0.0, 1.0, 4)
        q = tuple(float(c) for c in v / np.linalg.norm(v))
        q4 = (q[0], q[1], q[2], q[3])
        p = (float(rng.normal()), float(rng.normal()), float(rng.normal()))
        want_b = np.asarray(q_rotate_inv(q4, ned_to_enu(field_ned))) + 0.002 * ref.normal(
            0.0, 1.0, 3)
        assert np.array(mag.sample(k * 0.01, q4).b_flu_gauss).tobytes() == want_b.tobytes()
        ref_m.random()
        n = ref_m.normal(0.0, 1.0, 6)
        want_p = np.asarray(p) + cfg.position_noise_m * n[:3]
        d = cfg.attitude_noise_rad * n[3:]
        want_q = q_mul(q4, q_exp((float(d[0]), float(d[1]), float(d[2]))))
        mocap.capture(k * 0.005, p, q4)
        got = mocap.queue.popleft()
        assert np.array(got.p_enu_m).tobytes() == want_p.tobytes()
        assert np.array(got.q_enu_flu).tobytes() == np.array(want_q).tobytes()


def _crc(name: str) -> int:
    return zlib.crc32(name.encode())
