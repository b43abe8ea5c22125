"""`gcs replay`: the estimator re-run on an onboard log's inputs, as PX4's EKF2 replay.

The onboard log of a run with the estimator (EKF_EN = 1) holds every input the estimator
received (`sensor_combined`: each IMU sample, FRD; `vehicle_visual_odometry`: each external
pose, NED), the parameters, and the estimate the controller flew on at every control step
(`dq_onboard`: p, q, body velocity, bias-corrected rate; float64, ENU/FLU). The replay

- builds `EstimatorSettings` from the log's parameters (`fcu.params.estimator_settings` of
  the values in force when the first input arrived; `--param NAME=VALUE` overrides them for
  offline tuning) and the log's `dq_gravity_m_s2`;
- feeds `fcu.estimator.Estimator` the inputs in the order the FCU received them: by
  timestamp, a pose before the IMU sample of the same timestamp (the simulator sends a
  pose before the IMU sample of the same instant, and the log stamps a pose with the time
  of the IMU sample it arrived before), each kind in the log's order; the values converted
  to ENU/FLU as `fcu.edge.sim_bridge` converts the wire's;
- takes the estimate where the FCU's pipeline takes it (after each IMU sample on a multiple
  of `dq_control_period_us`; the body velocity and rate as `Estimator.output`, the
  quaternion normalised as `Pipeline.on_state` does) and compares, at every dq_onboard row,
  the newest estimate taken at or before the row's time with the logged one.

They agree when every value is within TOLERANCE x max(1, |logged value|) (float rounding);
normally they are bit-identical, which is said. Exit status: 0 agree, 1 differ (expected
with --param: then the replayed estimate's difference to the logged one is printed), 2 bad
input (not a ULog, no estimator inputs, a bad --param).
"""

from __future__ import annotations

import argparse
import bisect
import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.frames import frd_to_flu, ned_to_enu, q_ned_frd_to_enu_flu
from common.logs.ulog import ULogError, open_ulog, topic_rows
from common.process.diagnostics import get_logger, say
from common.quaternion import Quat, Vec3
from common.wire.rounding import f32
from fcu.control.rate_filter import ImuRateFilter
from fcu.estimator.ekf import Estimator
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.estimator.settings import EstimatorSettings
from fcu.params import BY_NAME, estimator_settings

log = get_logger(__name__)

TOLERANCE = 1e-9  # relative (to max(1, |value|)): float rounding, far below any estimate
STATE_COLUMNS = ("px", "py", "pz", "qw", "qx", "qy", "qz", "vbx", "vby", "vbz",
                 "wx", "wy", "wz")
QUANTITIES = {"position (m)": STATE_COLUMNS[0:3], "attitude q": STATE_COLUMNS[3:7],
              "body velocity (m/s)": STATE_COLUMNS[7:10], "rate (rad/s)": STATE_COLUMNS[10:13]}
DEFAULT_GRAVITY = 9.81


class ReplayError(ValueError):
    """A log the replay cannot use, or a bad --param."""


@dataclass
class Replay:
    time_us: np.ndarray  # the dq_onboard rows' times
    replayed: np.ndarray  # rows x STATE_COLUMNS; NaN where no estimate was taken yet
    logged: np.ndarray
    settings: EstimatorSettings
    imu_samples: int
    poses: int
    notes: list[str]

    @property
    def bit_identical(self) -> bool:
        return bool(np.array_equal(self.replayed, self.logged))

    def max_abs_diff(self) -> dict[str, float]:
        d = np.abs(self.replayed - self.logged)
        return {c: float(np.max(d[:, i])) if len(d) else 0.0
                for i, c in enumerate(STATE_COLUMNS)}

    @property
    def agree(self) -> bool:
        if not len(self.logged):
            return False
        d = np.abs(self.replayed - self.logged)
        limit = TOLERANCE * np.maximum(1.0, np.abs(self.logged))
        return bool(np.all(d <= limit))  # NaN compares False: differ


def parse_params(items: list[str]) -> dict[str, float]:
    """NAME=VALUE pairs, checked against the FCU's parameter table (name, range), stored as
    the FCU stores them (float32)."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip().upper()
        if not sep:
            raise ReplayError(f"--param {item}: expected NAME=VALUE")
        spec = BY_NAME.get(name)
        if spec is None:
            raise ReplayError(f"--param {item}: unknown parameter {name}")
        try:
            value = float(text)
        except ValueError:
            raise ReplayError(f"--param {item}: {text!r} is not a number") from None
        if not (math.isfinite(value) and spec.lo <= value <= spec.hi):
            raise ReplayError(f"--param {item}: not in [{spec.lo:g}, {spec.hi:g}]")
        out[name] = f32(value)
    return out


def _column(cols: tuple[str, ...], rows: np.ndarray, name: str) -> np.ndarray:
    return rows[:, cols.index(name)]


def _inputs(ulog: Any) -> tuple[list[tuple[int, int, int, ImuInput | PoseInput]], int, int]:
    """The estimator's inputs as (received us, 0 pose / 1 IMU, log order, input), sorted."""
    try:
        icols, imu = topic_rows(ulog, "sensor_combined")
        pcols, pose = topic_rows(ulog, "vehicle_visual_odometry")
    except ULogError:
        raise ReplayError("no estimator inputs (sensor_combined, vehicle_visual_odometry): "
                          "not the onboard log of a run with the estimator (EKF_EN = 1)"
                          ) from None
    if not len(imu):
        raise ReplayError("sensor_combined is empty: the estimator was off (EKF_EN = 0)")
    items: list[tuple[int, int, int, ImuInput | PoseInput]] = []
    t = _column(icols, imu, "time_us")
    g = [_column(icols, imu, f"gyro_rad[{i}]") for i in range(3)]
    a = [_column(icols, imu, f"accelerometer_m_s2[{i}]") for i in range(3)]
    for k in range(len(imu)):
        w: Vec3 = (float(g[0][k]), float(g[1][k]), float(g[2][k]))
        f: Vec3 = (float(a[0][k]), float(a[1][k]), float(a[2][k]))
        items.append((int(t[k]), 1, k, ImuInput(int(t[k]), frd_to_flu(w), frd_to_flu(f))))
    rx = _column(pcols, pose, "time_us")
    cap = _column(pcols, pose, "timestamp_sample")
    p = [_column(pcols, pose, f"position[{i}]") for i in range(3)]
    q = [_column(pcols, pose, f"q[{i}]") for i in range(4)]
    pv = _column(pcols, pose, "position_variance[0]")
    av = _column(pcols, pose, "orientation_variance[0]")
    for k in range(len(pose)):
        p_ned: Vec3 = (float(p[0][k]), float(p[1][k]), float(p[2][k]))
        q_ned: Quat = (float(q[0][k]), float(q[1][k]), float(q[2][k]), float(q[3][k]))
        pos_var, att_var = float(pv[k]), float(av[k])
        items.append((int(rx[k]), 0, k, PoseInput(
            int(cap[k]), ned_to_enu(p_ned), q_ned_frd_to_enu_flu(q_ned),
            pos_var if math.isfinite(pos_var) and pos_var > 0.0 else math.nan,
            att_var if math.isfinite(att_var) and att_var > 0.0 else math.nan)))
    items.sort(key=lambda it: it[:3])
    return items, len(imu), len(pose)


def _params(ulog: Any, first_us: int, notes: list[str]) -> dict[str, float]:
    """The parameters in force when the first input arrived (later EKF_* changes noted:
    the FCU restarts its estimator on them, the replay does not follow)."""
    values = {k: float(v) for k, v in ulog.initial_parameters.items()}
    for t, name, value in ulog.changed_parameters:
        if t <= first_us:
            values[name] = float(value)
        elif name.startswith("EKF_") and float(value) != values.get(name):
            notes.append(f"{name} changed to {value:g} at t = {t * 1e-6:.3f} s, after the "
                         "first input: replayed with the earlier value")
    return values


def replay(path: str | Path, overrides: dict[str, float] | None = None) -> Replay:
    """Re-run the estimator on the log at `path` and line it up with dq_onboard."""
    ulog = open_ulog(path, ["sensor_combined", "vehicle_visual_odometry", "dq_onboard"])
    items, n_imu, n_pose = _inputs(ulog)
    notes: list[str] = []
    values = _params(ulog, items[0][0], notes)
    values.update(overrides or {})
    settings, period_us = _settings(ulog, values, notes)
    try:
        dcols, drows = topic_rows(ulog, "dq_onboard")
    except ULogError:
        dcols, drows = ("time_us", *STATE_COLUMNS), np.zeros((0, 1 + len(STATE_COLUMNS)))
    row_t = _column(dcols, drows, "time_us").astype(np.int64)
    if period_us <= 0:  # an older log: the rows' spacing (lockstep: one control period)
        steps = np.diff(row_t)
        steps = steps[steps > 0]
        period_us = int(np.bincount(steps).argmax()) if len(steps) else 1
        notes.append(f"no dq_control_period_us in the log: {period_us} us from dq_onboard")
    taken_t, taken = _estimates(items, settings, values.get("IMU_GYRO_CUTOFF", 0.0), period_us)
    replayed = np.full((len(row_t), len(STATE_COLUMNS)), math.nan)
    for r, t in enumerate(row_t.tolist()):
        k = bisect.bisect_right(taken_t, t) - 1
        if k >= 0:
            replayed[r] = taken[k]
    logged = np.column_stack([_column(dcols, drows, c) for c in STATE_COLUMNS]) \
        if len(drows) else np.zeros((0, len(STATE_COLUMNS)))
    return Replay(row_t, replayed, logged, settings, n_imu, n_pose, notes)


def _settings(ulog: Any, values: dict[str, float],
              notes: list[str]) -> tuple[EstimatorSettings, int]:
    """The estimator's settings from the log's parameters and gravity, and the control
    period the log names (0: none; notes say what was assumed)."""
    info = ulog.msg_info_dict
    try:
        gravity = float(info.get("dq_gravity_m_s2", DEFAULT_GRAVITY))
        period_us = int(info.get("dq_control_period_us", 0))
    except (TypeError, ValueError):
        raise ReplayError("unreadable dq_gravity_m_s2 or dq_control_period_us") from None
    if "dq_gravity_m_s2" not in info:
        notes.append(f"no dq_gravity_m_s2 in the log: gravity {DEFAULT_GRAVITY} m/s^2")
    missing = [n for n in BY_NAME if n.startswith("EKF_") and n not in values]
    if missing:
        raise ReplayError(f"the log lacks the parameters {', '.join(missing)}")
    try:
        settings = estimator_settings(values, gravity)
    except ValueError as exc:
        raise ReplayError(f"estimator settings: {exc}") from None
    if settings is None:
        raise ReplayError("EKF_EN is 0: no estimator to replay")
    return settings, period_us


def _estimates(items: list[tuple[int, int, int, ImuInput | PoseInput]],
               settings: EstimatorSettings, gyro_cutoff_hz: float,
               period_us: int) -> tuple[list[int], list[tuple[float, ...]]]:
    """The estimator fed the log's inputs in order: its output (rates filtered as the
    pipeline does) at every control step, with the step's time."""
    est = Estimator(settings)
    rate_filter = ImuRateFilter(gyro_cutoff_hz)  # as the pipeline
    taken_t: list[int] = []
    taken: list[tuple[float, ...]] = []
    for _, kind, _, m in items:
        if kind == 0:
            assert isinstance(m, PoseInput)
            est.on_pose(m)
            continue
        assert isinstance(m, ImuInput)
        est.on_imu(m)
        rate_filter.update(m.t_us, m.omega_flu_rad_s)
        if m.t_us % period_us == 0:
            out = rate_filter.flown(est)  # filtered and normalized, as the pipeline
            if out is not None:
                s = out[1]
                taken_t.append(m.t_us)
                taken.append((*s.p_enu_m, *s.q_enu_flu, *s.v_flu_m_s, *s.omega_flu_rad_s))
    return taken_t, taken


def _attitude_angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    dot = np.clip(np.abs(np.sum(qa * qb, axis=1)), 0.0, 1.0)
    angle: np.ndarray = 2.0 * np.arccos(dot)
    return angle


def write_estimate(path: Path, r: Replay) -> None:
    """The replayed estimate at the dq_onboard rows: CSV when the name ends in .csv, else
    JSON {"columns": [...], "rows": [[...], ...]} (NaN as null)."""
    cols = ("time_us", *STATE_COLUMNS)
    rows = [[int(t), *(float(v) for v in vals)] for t, vals in zip(r.time_us, r.replayed,
                                                                   strict=True)]
    if path.suffix.lower() == ".csv":
        with path.open("w", newline="") as fh:
            out = csv.writer(fh)
            out.writerow(cols)
            out.writerows([[row[0], *(repr(v) for v in row[1:])] for row in rows])
        return
    clean = [[v if not (isinstance(v, float) and not math.isfinite(v)) else None for v in row]
             for row in rows]
    path.write_text(json.dumps({"columns": list(cols), "rows": clean}) + "\n")


def report(r: Replay, overrides: dict[str, float]) -> tuple[str, int]:
    """The text `gcs replay` prints and its exit status."""
    lines = [f"replayed {r.imu_samples} IMU samples and {r.poses} poses; compared "
             f"{len(r.time_us)} control steps (dq_onboard)"]
    if overrides:
        lines.append("  parameters changed: " + ", ".join(f"{k}={v:g}"
                                                          for k, v in overrides.items()))
    lines += [f"  note: {n}" for n in r.notes]
    diffs = r.max_abs_diff()
    lines.append("  max |replayed - logged|:")
    for label, cols in QUANTITIES.items():
        lines.append(f"    {label:<20} " + "  ".join(f"{c} {diffs[c]:.3e}" for c in cols))
    if not len(r.time_us):
        lines.append("  no dq_onboard rows (the vehicle never flew): nothing to compare")
        return "\n".join(lines), 1
    if r.agree:
        how = "bit-identical" if r.bit_identical else f"within {TOLERANCE:g} relative"
        lines.append(f"  agree: the replayed estimate equals the logged one ({how})")
        return "\n".join(lines), 0
    ok = np.all(np.isfinite(r.replayed), axis=1)
    pos = np.linalg.norm(r.replayed[ok, 0:3] - r.logged[ok, 0:3], axis=1)
    att = _attitude_angle(r.replayed[ok, 3:7], r.logged[ok, 3:7])
    vel = np.linalg.norm(r.replayed[ok, 7:10] - r.logged[ok, 7:10], axis=1)
    lines.append("  differ: the replayed estimate against the logged one")
    if len(pos):
        lines += [f"    position difference  max {pos.max():.3e} m   rms "
                  f"{math.sqrt(float(np.mean(pos ** 2))):.3e} m",
                  f"    attitude difference  max {att.max():.3e} rad   rms "
                  f"{math.sqrt(float(np.mean(att ** 2))):.3e} rad",
                  f"    velocity difference  max {vel.max():.3e} m/s   rms "
                  f"{math.sqrt(float(np.mean(vel ** 2))):.3e} m/s"]
    if (~ok).any():
        lines.append(f"    {int((~ok).sum())} step(s) without a replayed estimate")
    return "\n".join(lines), 1


def main(args: argparse.Namespace) -> int:
    """`gcs replay LOG [--out FILE] [--param NAME=VALUE ...]`; exit 0/1/2 as above."""
    try:
        overrides = parse_params(args.param or [])
        r = replay(args.log, overrides)
    except (ReplayError, ULogError) as exc:
        log.error(f"gcs replay: {exc}")
        return 2
    text, status = report(r, overrides)
    say(text)
    if args.out is not None:
        write_estimate(args.out, r)
        say(f"  wrote {args.out}")
    return status
