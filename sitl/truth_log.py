"""The simulator's ground-truth log (`truth.ulg`): what the vehicle really did.

Topics (ULog, read with pyulog):

- `dq_truth`, one record per state sent to the FCU (the control rate): TRUTH_COLUMNS in
  float64, ENU/FLU, SI units; every metric is computed from it.
- `vehicle_local_position_groundtruth`, `vehicle_attitude_groundtruth`,
  `vehicle_angular_velocity_groundtruth` as PX4 SITL logs them (float32, NED/FRD), at
  GROUNDTRUTH_HZ.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from common.logs import px4_topics as px4
from common.logs.columns import TRUTH_COLUMNS
from common.logs.ulog import Topic, ULogWriter
from common.process.diagnostics import get_logger
from sitl.plant import PlantState

logger = get_logger(__name__)
_STAMP = struct.Struct("<Q")

DQ_TRUTH = Topic("dq_truth", (("uint64_t", "timestamp"),
                              *(("double", c) for c in TRUTH_COLUMNS[1:])))
TRUTH_TOPICS = (DQ_TRUTH, px4.VEHICLE_LOCAL_POSITION_GROUNDTRUTH,
                px4.VEHICLE_ATTITUDE_GROUNDTRUTH, px4.VEHICLE_ANGULAR_VELOCITY_GROUNDTRUTH)
GROUNDTRUTH_HZ = 100


class TruthLog(ULogWriter):
    """Append-only truth log; `record` queues one state, `log` a string, `flush` writes what
    is queued (ULogWriter)."""

    def __init__(self, sink: str | Path | bytearray, scenario_name: str) -> None:
        super().__init__(sink, TRUTH_TOPICS, info={
            "sys_name": "dqflight sitl", "ver_hw": "SITL", "sim_scenario": scenario_name})
        self._dq_truth = self._ids[DQ_TRUTH.name]
        msg_id, record = self._dq_truth
        self._head = struct.pack("<HBH", record.size - 3, 68, msg_id)  # a record's header
        self.period_us = 1_000_000 // GROUNDTRUTH_HZ
        self.next_gt_us = 0

    def record(self, s: PlantState, row: np.ndarray | None = None) -> None:
        """Queue the state s; `row`: its truth row (`sitl.plant.state_row`, float64) when
        the caller has it, whose bytes after the stamp are the record's."""
        w = self
        t = s.time_us
        msg_id, record = self._dq_truth  # the values of `truth_row`, packed here
        if row is not None:
            if row.dtype != np.float64 or row.shape != (len(TRUTH_COLUMNS),) or row[0] != t:
                raise ValueError(f"truth log: the row of {t} us is not that state's truth "
                                 f"row (dtype {row.dtype}, shape {row.shape}, time {row[0]})")
            self._pending += (self._head, _STAMP.pack(t), row[1:].tobytes())
        else:
            self._pending.append(record.pack(
                record.size - 3, 68, msg_id, t, *s.p_enu_m, *s.v_enu_m_s, *s.q_enu_flu,
                *s.omega_flu_rad_s, *s.rotor_speed_rad_s, *s.tilt_rad, float(s.landed)))
        if t >= self.next_gt_us:
            self.next_gt_us = (t // self.period_us + 1) * self.period_us
            w.add(px4.VEHICLE_LOCAL_POSITION_GROUNDTRUTH.name, px4.local_position_record(
                t, t, s.p_enu_m, s.v_enu_m_s, s.q_enu_flu, True, None))
            w.add(px4.VEHICLE_ATTITUDE_GROUNDTRUTH.name, px4.attitude_record(t, t, s.q_enu_flu))
            w.add(px4.VEHICLE_ANGULAR_VELOCITY_GROUNDTRUTH.name,
                  px4.angular_velocity_record(t, t, s.omega_flu_rad_s))


def flushed(log: TruthLog | None, time_us: int) -> TruthLog | None:
    """`log` with what it queued written; None once it cannot be written any more (a full
    disk, an I/O error): said once on stderr, closed, and the world goes on without it."""
    if log is None:
        return None
    log.flush()
    if not log.failed:
        return log
    logger.warning("sitl: truth log stopped at t = %.3f s: %s", time_us * 1e-6, log.failed)
    log.close()
    return None
