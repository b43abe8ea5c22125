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
