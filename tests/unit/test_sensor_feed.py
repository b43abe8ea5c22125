"""The simulator's sensor feed with injected faults ([[sensor_fault]]): each kind does what it
says inside its window only, counted from the flight's start, and never changes a draw (a
feed with a fault sends what the feed without it sends, outside the fault); the scenario
table is validated."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from common.config.scenario import ConfigError, Scenario, SensorFault, load_scenario
from common.config.sensors import resolve_sensor_profile
from common.wire.simlink import HilSensor, Odometry
from sitl.plant import Plant, initial_state
from sitl.sensor_feed import SensorFeed

ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"
PROFILE = resolve_sensor_profile("mocap-indoor")  # IMU 1 kHz, poses 200 Hz after 5 ms
CONTROL_US = 2000
T0_US = 300_000  # the flight's start on the simulation clock (after an alignment)
Message = HilSensor | Odometry


def _feed_messages(faults: tuple[SensorFault, ...] | None, periods: int = 400,
                   seed: int = 3) -> list[Message]:
    """A feed's messages for a vehicle at rest, the flight starting at T0_US (no
    `start_flight` at all when faults is None)."""
    scenario = load_scenario(CASE1)
    plant = Plant(scenario.vehicle, dt_us=1000)
    feed = SensorFeed(PROFILE, seed, plant, CONTROL_US)
    state = initial_state(scenario, plant)
    out = list(feed.period([state]))
    for _ in range(periods):
        if faults is not None and state.time_us == T0_US:
            feed.start_flight(T0_US, faults)
        states = []
        for _ in range(CONTROL_US // 1000):
            state = state._replace(time_us=state.time_us + 1000)
            states.append(state)
        out += feed.period(states)
    return out


def _imu(messages: list[Message]) -> dict[int, HilSensor]:
    return {m.time_usec: m for m in messages if isinstance(m, HilSensor)}


def _poses(messages: list[Message]) -> dict[int, Odometry]:
    return {m.time_usec: m for m in messages if isinstance(m, Odometry)}


def _same(a: object, b: object) -> bool:
    """Equal value for value, NaN equal to NaN (repr of a float is exact)."""
    return repr(a) == repr(b)


def _in(t_us: int, start_s: float, end_s: float = math.inf) -> bool:
    return T0_US + start_s * 1e6 <= t_us < T0_US + end_s * 1e6


@pytest.fixture(scope="module")
def clean() -> list[Message]:
    return _feed_messages(None)


def test_no_fault_is_the_plain_feed(clean):
    """start_flight without faults changes nothing."""
    assert _same(_feed_messages(()), clean)
    assert len(_poses(clean)) > 100 and len(_imu(clean)) == 801


def test_mocap_off_captures_no_pose_in_its_window_and_keeps_the_draws(clean):
    """mocap_off [0.2, 0.3) s: the 20 captures of the window are missing, every other pose
    and every IMU sample is the same as without the fault (the capture still draws)."""
    faulty = _feed_messages((SensorFault("mocap_off", 0.2, 0.3),))
    poses, ref = _poses(faulty), _poses(clean)
    missing = sorted(set(ref) - set(poses))
    assert len(missing) == 20 and all(_in(t, 0.2, 0.3) for t in missing)
    assert set(poses) <= set(ref)
    assert all(_same(poses[t], ref[t]) for t in poses)
    assert any(t > T0_US + 300_000 for t in poses)  # poses come back after the window
    assert _same(_imu(faulty), _imu(clean))


def test_pose_nan_sends_the_window_s_poses_with_nan_at_their_capture_time(clean):
    faulty = _feed_messages((SensorFault("pose_nan", 0.1, 0.15),))
    poses, ref = _poses(faulty), _poses(clean)
    assert set(poses) == set(ref)
    bad = [t for t, m in poses.items() if not all(map(math.isfinite, (*m.p_ned_m,
                                                                     *m.q_ned_frd)))]
    assert len(bad) == 10 and all(_in(t, 0.1, 0.15) for t in bad)
    for t in bad:
        assert all(math.isnan(v) for v in (*poses[t].p_ned_m, *poses[t].q_ned_frd))
        assert poses[t].pose_covariance == ref[t].pose_covariance
    assert all(_same(poses[t], ref[t]) for t in poses if t not in bad)
    # placed in the stream where the clean pose is (after the latency)
    assert [type(m).__name__ for m in faulty] == [type(m).__name__ for m in clean]
    assert _same(_imu(faulty), _imu(clean))


def test_imu_nan_puts_nan_in_gyro_and_accelerometer_only(clean):
    faulty = _feed_messages((SensorFault("imu_nan", 0.05, 0.06),))
    imu, ref = _imu(faulty), _imu(clean)
    assert set(imu) == set(ref)
    bad = [t for t, m in imu.items() if not math.isfinite(sum(m.gyro_frd_rad_s))]
    assert bad == [T0_US + 50_000 + 1000 * k for k in range(10)]
    for t in bad:
        m, r = imu[t], ref[t]
        assert all(math.isnan(v) for v in (*m.gyro_frd_rad_s, *m.acc_frd_m_s2))
        assert _same((m.mag_frd_gauss, m.abs_pressure_hpa, m.pressure_alt_m,
                      m.fields_updated), (r.mag_frd_gauss, r.abs_pressure_hpa,
                                          r.pressure_alt_m, r.fields_updated))
    assert all(_same(imu[t], ref[t]) for t in imu if t not in bad)
    assert _same(_poses(faulty), _poses(clean))


def test_gyro_bias_step_adds_its_amplitude_in_flu_from_its_start(clean):
    """amplitude FLU (x, y, z) is (x, -y, -z) in the FRD gyro of HIL_SENSOR; open-ended
    without end_s, until end_s with it; the accelerometer is untouched."""
    a = (0.005, -0.002, 0.003)
    for end_s, faults in ((math.inf, (SensorFault("gyro_bias_step", 0.4, amplitude=a),)),
                          (0.5, (SensorFault("gyro_bias_step", 0.4, 0.5, a),))):
        imu, ref = _imu(_feed_messages(faults)), _imu(clean)
        for t, m in imu.items():
            r = ref[t]
            assert _same(m.acc_frd_m_s2, r.acc_frd_m_s2)
            d = [m.gyro_frd_rad_s[i] - r.gyro_frd_rad_s[i] for i in range(3)]
            if _in(t, 0.4, end_s):
                assert d == pytest.approx((a[0], -a[1], -a[2]), abs=1e-12)
            else:
                assert _same(m, r)
        assert sum(_in(t, 0.4, end_s) for t in imu) == (100 if end_s == 0.5 else 101)


def test_gyro_bias_step_saturates_at_the_gyro_range(clean):
    big = 10.0 * PROFILE.imu.gyro.range_rad_s
    imu = _imu(_feed_messages((SensorFault("gyro_bias_step", 0.0, amplitude=(big, 0, 0)),)))
    assert imu[T0_US + 1000].gyro_frd_rad_s[0] == PROFILE.imu.gyro.range_rad_s


def test_faults_count_from_the_flight_start_and_not_before_it(clean):
    """A window [0, 0.1) acts from T0_US on, never on the samples before the flight."""
    faulty = _feed_messages((SensorFault("imu_nan", 0.0, 0.1),))
    imu, ref = _imu(faulty), _imu(clean)
    bad = sorted(t for t, m in imu.items() if math.isnan(m.gyro_frd_rad_s[0]))
    assert bad[0] == T0_US + 1000 and bad[-1] == T0_US + 99_000  # T0 itself was sent before
    assert all(_same(imu[t], ref[t]) for t in imu if t <= T0_US)


def test_start_flight_refuses_a_second_start_and_bad_faults():
    scenario = load_scenario(CASE1)
    plant = Plant(scenario.vehicle, dt_us=1000)

    def feed() -> SensorFeed:
        return SensorFeed(PROFILE, 0, plant, CONTROL_US)

    f = feed()
    f.start_flight(0)
    with pytest.raises(ValueError, match="started"):
        f.start_flight(10)
    for bad, what in ((SensorFault("mocap_of", 0.0, 1.0), "kind"),
                      (SensorFault("imu_nan", 2.0, 1.0), "start_s < end_s"),
                      (SensorFault("imu_nan", -1.0, 1.0), "start_s < end_s"),
                      (SensorFault("gyro_bias_step", 0.0, amplitude=(math.nan, 0.0, 0.0)),
                       "amplitude")):
        with pytest.raises(ConfigError, match=what):
            feed().start_flight(0, (bad,))


# ---------------------------------------------------------------------------- the table


def _scenario(tmp_path: Path, faults: str, sensors: str | None = '"mocap-indoor"') -> Path:
    text = CASE1.read_text()
    for key in ("vehicle", "pid", "pd"):
        text = text.replace(f'{key} = "../', f'{key} = "{CASE1.parent.parent}/')
    if sensors is not None:
        text = text.replace("seed = 0\n", f"seed = 0\nsensors = {sensors}\n")
    path = tmp_path / "faults.toml"
    path.write_text(text + "\n" + faults)
    return path


def test_scenario_sensor_fault_tables_load(tmp_path):
    sc = load_scenario(_scenario(tmp_path, """
[[sensor_fault]]
kind = "mocap_off"
start_s = 12.0
end_s = 12.5

[[sensor_fault]]
kind = "gyro_bias_step"
start_s = 3
amplitude = [0.005, 0, -1e-3]

[[sensor_fault]]
kind = "gyro_bias_step"
start_s = 1.0
end_s = 2.0
amplitude = [0.0, 0.001, 0.0]

[[sensor_fault]]
kind = "imu_nan"
start_s = 0.0
end_s = 0.01

[[sensor_fault]]
kind = "pose_nan"
start_s = 4.0
end_s = 4.05
"""))
    assert sc.sensor_faults == (
        SensorFault("mocap_off", 12.0, 12.5),
        SensorFault("gyro_bias_step", 3.0, math.inf, (0.005, 0.0, -1e-3)),
        SensorFault("gyro_bias_step", 1.0, 2.0, (0.0, 0.001, 0.0)),
        SensorFault("imu_nan", 0.0, 0.01), SensorFault("pose_nan", 4.0, 4.05))
    assert load_scenario(CASE1).sensor_faults == ()
    assert Scenario.__dataclass_fields__["sensor_faults"].default == ()


@pytest.mark.parametrize(("faults", "message"), [
    ('kind = "mocap_of"\nstart_s = 1.0\nend_s = 2.0',
     "'sensor_fault[0].kind': expected one of 'mocap_off', 'gyro_bias_step'"),
    ('kind = "imu_nan"\nstart_s = 2.0\nend_s = 1.0',
     "'sensor_fault[0].end_s': expected a time after start_s = 2.0"),
    ('kind = "pose_nan"\nstart_s = 2.0\nend_s = 2.0', "expected a time after start_s"),
    ('kind = "gyro_bias_step"\nstart_s = 2.0\nend_s = 1.0\namplitude = [0, 0, 0]',
     "expected a time after start_s"),
    ('kind = "mocap_off"\nstart_s = 1.0', "missing key 'sensor_fault[0].end_s'"),
    ('kind = "mocap_off"\nstart_s = -1.0\nend_s = 1.0', "'sensor_fault[0].start_s'"),
    ('kind = "gyro_bias_step"\nstart_s = 1.0', "missing key 'sensor_fault[0].amplitude'"),
    ('kind = "gyro_bias_step"\nstart_s = 1.0\namplitude = [0.1, 0.2]',
     "'sensor_fault[0].amplitude': expected a list of 3 numbers"),
    ('kind = "gyro_bias_step"\nstart_s = 1.0\namplitude = [0.1, nan, 0.0]',
     "'sensor_fault[0].amplitude': expected a list of 3 finite numbers"),
    ('kind = "gyro_bias_step"\nstart_s = 1.0\namplitude = [0.1, inf, 0.0]',
     "expected a list of 3 finite numbers"),
    ('kind = "gyro_bias_step"\nstart_s = 1.0\namplitude = "0.1"',
     "expected a list of 3 numbers"),
    ('kind = "mocap_off"\nstart_s = 1.0\nend_s = 2.0\namplitude = [0, 0, 0]',
     "unknown key 'sensor_fault[0].amplitude'"),
    ('kind = "imu_nan"\nstart_s = 1.0\nend_s = 2.0\nstart = 1.0',
     "unknown key 'sensor_fault[0].start'"),
])
def test_scenario_sensor_fault_errors_name_the_key(tmp_path, faults, message):
    with pytest.raises(ConfigError, match=r"faults\.toml") as err:
        load_scenario(_scenario(tmp_path, "[[sensor_fault]]\n" + faults + "\n"))
    assert message in str(err.value)


def test_a_fault_needs_a_sensor_profile(tmp_path):
    fault = '[[sensor_fault]]\nkind = "mocap_off"\nstart_s = 1.0\nend_s = 2.0\n'
    for sensors in ('"truth"', None):
        with pytest.raises(ConfigError, match="faults need a sensor profile"):
            load_scenario(_scenario(tmp_path, fault, sensors))
    with pytest.raises(ConfigError, match="an array of tables"):
        load_scenario(_scenario(tmp_path, fault.replace("[[sensor_fault]]",
                                                         "[sensor_fault]")))
    assert load_scenario(_scenario(tmp_path, fault, '"degraded"')).sensor_faults


def test_the_command_line_cannot_drop_a_scenario_s_faults(tmp_path):
    """`--sensors truth` on a scenario with faults is refused (gcs run, gcs table1 and
    sitl share apply_overrides' or the same check), never a run without its faults."""
    from gcs.run.overrides import apply_overrides

    fault = '[[sensor_fault]]\nkind = "mocap_off"\nstart_s = 1.0\nend_s = 2.0\n'
    sc = load_scenario(_scenario(tmp_path, fault))
    with pytest.raises(ConfigError, match="faults need a sensor profile"):
        apply_overrides(sc, sensors="truth")
    assert apply_overrides(sc, sensors="degraded").sensor_faults == sc.sensor_faults


@pytest.mark.parametrize("spread_s", [0.0, 0.05])
@pytest.mark.parametrize("imu_hz", [100.0, 250.0, 1000.0])
def test_the_accelerometer_integrates_to_the_touchdowns_velocity_change(imu_hz, spread_s):
    """Given exact sensors at 100, 250 or 1,000 Hz on a 1 ms physics step and a vehicle
    falling onto the ground, then the IMU samples' specific force (FRD on the wire) in ENU
    plus gravity, times each sample's interval, sums to the true velocity change over the
    touchdown: the contact's impulse rides in the first sample at or after its step,
    spread over that sample's interval, or with contact_spread_s over that long (then no
    sample reads more than the resting g plus the impulse over the spread)."""
    import dataclasses

    from common.config.sensors import PROFILE_IMU_RATE_MIN_HZ
    from common.frames import frd_to_flu
    from sitl.plant import ActuatorCommand, rotate

    scenario = load_scenario(CASE1)
    truth = resolve_sensor_profile("truth")
    profile = dataclasses.replace(truth, imu=dataclasses.replace(truth.imu, rate_hz=imu_hz),
                                  mag=dataclasses.replace(truth.mag, rate_hz=imu_hz),
                                  baro=dataclasses.replace(truth.baro, rate_hz=50.0))
    profile = dataclasses.replace(profile, imu=dataclasses.replace(
        profile.imu, accel=dataclasses.replace(profile.imu.accel, contact_spread_s=spread_s)))
    plant = Plant(scenario.vehicle, dt_us=1000)
    imu_us = round(1e6 / imu_hz)
    feed = SensorFeed(profile, 0, plant, imu_us, imu_rate_min_hz=PROFILE_IMU_RATE_MIN_HZ)
    s = plant.initial_state((0.0, 0.0, 0.3), on_ground=False, rotor_speed_rad_s=(200.0,) * 6)
    s = s._replace(v_enu_m_s=(0.3, -0.2, -1.2))
    cmd = ActuatorCommand((200.0,) * 6, (0.0,) * 6)
    v0 = s.v_enu_m_s
    dv = [0.0, 0.0, 0.0]
    feed.period([s])
    samples, peak, v_impact = 0, 0.0, v0
    for _ in range(round(0.6e6 / imu_us)):
        states = []
        for _ in range(imu_us // 1000):
            if not s.landed:
                v_impact = s.v_enu_m_s
            s = plant.step(s, cmd)
            states.append(s)
        for m in feed.period(states):
            if isinstance(m, HilSensor):
                f = rotate(s.q_enu_flu, frd_to_flu(m.acc_frd_m_s2))
                for i in range(3):
                    dv[i] += (f[i] - (0.0, 0.0, plant.g)[i]) * imu_us * 1e-6
                samples += 1
                if s.landed:  # the impulse and the resting reaction
                    peak = max(peak, math.dist(f, (0.0, 0.0, 0.0)))
    assert s.landed and samples > 50
    # to one sample's worth of the point sampling (the sample after the touchdown reads the
    # resting g for the part of its interval still in flight); the impulse is 1.2 m/s
    one_sample = plant.g * imu_us * 1e-6 + 0.01
    assert dv == pytest.approx([s.v_enu_m_s[i] - v0[i] for i in range(3)], abs=one_sample)
    impulse = math.dist(v_impact, (0.0, 0.0, 0.0))  # the contact's velocity change
    if spread_s:
        assert peak <= plant.g + impulse / spread_s + 0.5, peak
    else:
        assert peak >= impulse / (imu_us * 1e-6), peak
