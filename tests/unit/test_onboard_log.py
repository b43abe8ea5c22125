"""The FCU hands each control step's records to the kernel before the next step, so a kill
between two steps loses nothing that was computed."""

from __future__ import annotations

from pathlib import Path

from common.config.scenario import load_gains, load_vehicle
from common.links import free_port
from common.logs.ulog import read_topic
from common.wire.mission_items import PX4_SITL_HOME
from fcu.edge.flight_controller import FlightController
from fcu.pipeline import Pipeline
from fcu.stages import VehicleState

ROOT = Path(__file__).resolve().parents[2]


def test_each_control_step_is_in_the_file_when_the_step_returns(tmp_path):
    pipeline = Pipeline(load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml"),
                        load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)
    path = tmp_path / "onboard.ulg"
    fc = FlightController(pipeline, f"udpout:127.0.0.1:{free_port()}",
                          [f"udpout:127.0.0.1:{free_port()}"], system_id=1, lockstep=True,
                          home=PX4_SITL_HOME, onboard_log=path, stats_path=None)
    try:
        pipeline.on_state(0, VehicleState((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                                          (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), 0)
        assert pipeline.arm()[0] == 0
        for k in range(5):
            pipeline.on_state(2000 * k, pipeline.state, 2000 * k)
            fc._control_step(2000 * k, 0.002)
            _, rows = read_topic(path, "dq_onboard")  # no close, no housekeeping between
            assert rows[:, 0].tolist() == [2000.0 * i for i in range(k + 1)]
    finally:
        fc.close()


def test_a_step_after_a_newer_sample_is_keyed_by_the_period_it_answers():
    """Given an in-process mocap flight in which, before every 10th control step, an IMU
    sample 1 ms newer than the period's end reaches the estimator first (as in real time,
    where the FCU's tick may follow an odd sample of a 1 kHz IMU), then every dq_onboard row
    is keyed by the period's end, where the estimate is taken (`state_time_us`, and the
    timestamp with it), and every step joins a truth row in the metrics; keyed by the newest
    sample instead, a tenth of the rows joined none."""
    import dataclasses
    import io

    from pyulog import ULog

    from common.config.scenario import load_scenario
    from common.config.sensors import resolve_sensor_profile
    from fcu.estimator.inputs import ImuInput
    from gcs.run.inprocess import run_scenario

    injected = []

    def newer_sample_first(t_us: int, pipeline: Pipeline) -> None:
        inputs = pipeline.estimator_inputs or []
        imu = [x for x in inputs if isinstance(x, ImuInput)]
        if t_us % 20_000 == 0 and imu and imu[-1].t_us == t_us:
            pipeline.on_imu(imu[-1]._replace(t_us=t_us + 1000))
            injected.append(t_us)

    scenario = dataclasses.replace(load_scenario(ROOT / "config/scenarios/case1_figure8.toml"),
                                   sensors=resolve_sensor_profile("mocap-indoor"),
                                   duration_s=3.0)
    result = run_scenario(scenario, before_step=newer_sample_first)
    assert len(injected) >= 100
    assert result.onboard_ulog is not None
    dq = ULog(io.BytesIO(result.onboard_ulog), ["dq_onboard"]).data_list[0].data
    stamps = dq["state_time_us"].astype(int)
    assert len(stamps) >= 1400 and set(stamps % 2000) == {0}
    assert set(injected) <= set(stamps.tolist())
    assert result.metrics["samples"] == len(result.onboard) == len(stamps)


def test_a_late_sample_at_a_period_end_does_not_move_the_period_answered_back():
    """Given IMU samples at the period ends 2, 4 and 6 ms, then a reordered one stamped 4 ms
    again and one stamped 2 ms (a real-time link may reorder), then the period the next step
    answers stays 6 ms; a newer period end moves it on."""
    from fcu.estimator.inputs import ImuInput
    from fcu.estimator.settings import EstimatorSettings

    pipeline = Pipeline(load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml"),
                        load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)
    pipeline.use_estimator(EstimatorSettings())
    rest = ((0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
    for t_us in (2000, 3000, 4000, 5000, 6000, 4000, 2000):
        pipeline.on_imu(ImuInput(t_us, *rest))
    assert pipeline.period_stamp_us == 6000
    pipeline.on_imu(ImuInput(8000, *rest))
    assert pipeline.period_stamp_us == 8000
