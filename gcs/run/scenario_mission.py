"""What a run sets on the vehicle from its scenario: its parameters (`scenario_params`) and
its trajectory as a mission (local NED items), for runs through the mission protocol: flown
by `fcu.mission.MissionExecutor` from the scenario's start it gives the same reference as
`fcu.reference.trajectory.make_trajectory` (Case I: to rounding at every step).

Case I (docs/model.md#scenarios): takeoff (the quintic rise), loiter at the top, the
figure-infinity (command 31001) about the ENU axis n (sent in NED: [1, 2, 3] -> [2, 1, -3]),
loiter to the end of the run. Hover (Case II): one loiter for the whole run. Mission: the
items of the scenario's mission file, as `gcs mission upload` would send them.
"""

from __future__ import annotations

import math
from pathlib import Path

from common.config.scenario import Scenario
from common.frames import enu_to_ned
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT
from common.wire.mission_items import MissionItem, local_xy

M = MAV


def _item(seq: int, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
          p4: float = 0.0, x_m: float = 0.0, y_m: float = 0.0, z: float = 0.0) -> MissionItem:
    return MissionItem(seq=seq, frame=M.MAV_FRAME_LOCAL_NED, command=command,
                       current=1 if seq == 0 else 0, autocontinue=1, param1=p1, param2=p2,
                       param3=p3, param4=p4, x=local_xy(x_m), y=local_xy(y_m), z=z,
                       mission_type=M.MAV_MISSION_TYPE_MISSION)


def scenario_mission(scenario: Scenario) -> list[MissionItem]:
    """The mission items of a scenario's trajectory (kinds "case1_figure8", "hover", and
    "mission": the items of its mission file)."""
    traj = scenario.trajectory
    if traj.kind == "mission":
        from gcs.mission_files import read_mission

        return read_mission(Path(traj.mission_file))
    north, east, down = enu_to_ned(traj.position_enu_m)
    if traj.kind == "hover":
        return [_item(0, M.MAV_CMD_NAV_LOITER_TIME, p1=scenario.duration_s, x_m=north,
                      y_m=east, z=down)]
    if traj.kind != "case1_figure8":
        raise ValueError(f"no mission for trajectory kind {traj.kind!r}")
    top = -(traj.position_enu_m[2] + traj.rise_height_m)
    axis = enu_to_ned(traj.axis_enu)
    return [
        # x, y are ignored by the takeoff (vertical climb); sent as the start for readers.
        _item(0, M.MAV_CMD_NAV_TAKEOFF, p2=traj.rise_end_s, p4=math.nan, x_m=north, y_m=east,
              z=top),
        _item(1, M.MAV_CMD_NAV_LOITER_TIME, p1=traj.figure_start_s - traj.rise_end_s,
              x_m=north, y_m=east, z=top),
        _item(2, MAV_CMD_FIGURE_EIGHT, p1=traj.amplitude_m,
              p2=traj.figure_end_s - traj.figure_start_s, p3=axis[0], p4=axis[1], z=axis[2]),
        _item(3, M.MAV_CMD_NAV_LOITER_TIME,
              p1=max(0.0, scenario.duration_s - traj.figure_end_s), x_m=north, y_m=east,
              z=top),
    ]


def scenario_params(scenario: Scenario) -> dict[str, float]:
    """Parameters a run sets on the FCU beyond its defaults (the same through processes):
    no lead for actuators without lag; with a sensor profile the estimator's noise figures
    those of the profile's IMU and motion capture and its fusion horizon at the pose's
    latency (as a user tunes EKF2_GYR_NOISE, EKF2_ACC_NOISE, EKF2_EVP_NOISE, EKF2_EVA_NOISE
    and EKF2_EV_DELAY to the vehicle); the scenario's own [params]; last, with a sensor
    profile, the estimator on. Set in this order."""
    params = {"COM_DIV_POS": scenario.divergence_position_m}
    if scenario.ideal_actuators:
        params["CA_LAG_COMP"] = 0.0  # actuators without lag: nothing to lead
    if scenario.uses_sensors:
        assert scenario.sensors is not None
        imu = scenario.sensors.imu
        params["EKF_GYR_NOISE"] = max(imu.gyro_sigma_rad_s, 1e-4)  # the IMU's, per sample
        params["EKF_ACC_NOISE"] = max(imu.accel_sigma_m_s2, 1e-3)
        mocap = scenario.sensors.mocap
        params["EKF_EVP_NOISE"] = max(mocap.position_noise_m, 1e-5)  # trust its covariance
        params["EKF_EVA_NOISE"] = max(mocap.attitude_noise_rad, 1e-5)
        params["EKF_EV_DELAY"] = mocap.latency_s
    params.update(scenario.params)
    if scenario.uses_sensors:
        # Last: the estimator starts (and in lockstep simulated time runs, aligning it) once
        # it is on, so the flight starts at the same instant however the sets were timed.
        params.pop("EKF_EN", None)
        params["EKF_EN"] = 1.0
    return params
