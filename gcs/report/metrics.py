"""Tracking metrics of a run (docs/architecture.md#a-run-folder) and the paper's Table I.

Position error = |p - p_d|; attitude error = angle of q_d* q in [0, pi]; both sampled at the
control steps (the desired pose is the one the controller computed for that step), over the
rows where the vehicle is meant to follow its reference (`followed_rows`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from common.config.scenario import Scenario
from common.outcome import (
    CRASH_SPEED_M_S,
    Event,
    classify,
    diverged_rows,
    touchdowns,
)
from common.quaternion import angle_between_rows, rotate_rows
from gcs.report.run_metrics import (
    ErrorStats,
    RunMetrics,
    StepPercentiles,
    Tracking,
    event_record,
)


def attitude_error_rad(q: np.ndarray, q_d: np.ndarray) -> np.ndarray:
    """Angle of q_d* q for rows of (w, x, y, z) quaternions, in [0, pi]."""
    return angle_between_rows(q, q_d)


def error_stats(err: np.ndarray) -> ErrorStats:
    if err.size == 0:
        return {"max": 0.0, "mean": 0.0, "rmse": 0.0}
    return {"max": float(np.max(err)), "mean": float(np.mean(err)),
            "rmse": float(math.sqrt(float(np.mean(err * err))))}


def percentiles_us(samples: np.ndarray) -> StepPercentiles:
    if samples.size == 0:
        return {"p50": 0.0, "p99": 0.0, "max": 0.0}
    return {"p50": float(np.percentile(samples, 50)), "p99": float(np.percentile(samples, 99)),
            "max": float(np.max(samples))}


def tracking_metrics(p: np.ndarray, q: np.ndarray, p_d: np.ndarray,
                     q_d: np.ndarray) -> Tracking:
    """Table I figures; rows must be finite (a diverged run is cut at its last finite row)."""
    pos = np.linalg.norm(p - p_d, axis=1)
    att = attitude_error_rad(q, q_d)
    return {"position_error_m": error_stats(pos), "attitude_error_rad": error_stats(att)}


# The rule that picks the rows the errors are judged over (metrics.json's error_rows.rule).
ERROR_ROWS_RULE = "ground_below_reference_excluded"
GROUND_Z_M = 0.0  # the plant's ground plane (ENU z)


def followed_rows(p_d: np.ndarray, landed: np.ndarray) -> np.ndarray:
    """Rows where the vehicle is meant to follow its reference: every row, but those on the
    ground (the plant's contact flag `landed`) with the reference below the ground plane
    (z_d < 0), which the vehicle cannot follow there: a landing's set-point sinking on
    through contact until the land detector disarms. A row in the air counts, whatever its
    reference; so does a row on the ground with its reference at or above the ground: the
    rest before a take-off, a climb from the ground (Case I's) while the rotors spin up.
    With the ground switched off (Case II) the vehicle is never landed: every row counts."""
    with np.errstate(invalid="ignore"):
        below = np.asarray(p_d[:, 2] < GROUND_Z_M) if len(p_d) else np.zeros(0, dtype=bool)
    return np.asarray(~((np.asarray(landed) > 0.5) & below))


def rank_key(metrics: dict[str, Any]) -> tuple[int, float]:
    """Sort key: completed runs first, then by position RMSE (diverged ranks below all)."""
    return (0 if metrics.get("status") == "completed" else 1,
            float(metrics["position_error_m"]["rmse"]))


STATE_TIME = "state_time_us"  # dq_onboard: the state's stamp on the simulator's clock


def onboard_on_truth_clock(columns: tuple[str, ...], rows: np.ndarray
                           ) -> tuple[tuple[str, ...], np.ndarray]:
    """dq_onboard's rows keyed for the join with dq_truth: their `time_us` is the stamp of
    the state each step acted on as the simulator sent it (`state_time_us`), not the FCU's
    flight clock that stamps onboard.ulg (the same clock in lockstep, another in real time);
    the column itself is dropped. A log without it (written before it) is keyed as it is."""
    if STATE_TIME not in columns:
        return columns, rows
    i = columns.index(STATE_TIME)
    keyed = np.delete(rows, i, axis=1) if rows.ndim == 2 else rows
    if len(keyed):
        keyed[:, 0] = rows[:, i]
    return columns[:i] + columns[i + 1:], keyed


def join_logs(truth_columns: Sequence[str], truth: np.ndarray, onboard_columns: Sequence[str],
              onboard: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The one join of the plant's truth log with the FCU's onboard log: rows of both at the
    same time_usec (the control steps), as (time_us, truth rows, onboard rows)."""
    t_truth = truth[:, list(truth_columns).index("time_us")].astype(np.int64)
    t_onb = onboard[:, list(onboard_columns).index("time_us")].astype(np.int64)
    common_t, i_truth, i_onb = np.intersect1d(t_truth, t_onb, return_indices=True)
    return common_t, truth[i_truth], onboard[i_onb]


def log_columns(columns: Sequence[str], rows: np.ndarray, *names: str) -> np.ndarray:
    """The named columns of a log's rows."""
    return rows[:, [list(columns).index(n) for n in names]]


def crash_time_us(truth_columns: Sequence[str], truth: np.ndarray) -> int | None:
    """First ground contact faster than CRASH_SPEED_M_S in a truth log (None: none)."""
    if len(truth) < 2:
        return None
    speed = np.linalg.norm(log_columns(truth_columns, truth, "vx", "vy", "vz"), axis=1)
    landed = truth[:, list(truth_columns).index("landed")]
    t = truth[:, list(truth_columns).index("time_us")]
    for row, v in touchdowns(landed, speed):
        if v > CRASH_SPEED_M_S:
            return int(t[row])
    return None


def estimation_error_rows(truth_columns: Sequence[str], truth_j: np.ndarray,
                          onboard_columns: Sequence[str], onboard_j: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The estimate (the state the FCU flew on, dq_onboard) against the truth (dq_truth) at
    the same steps (`join_logs` rows), per row: position error norm |p_est - p| in m,
    world-frame (ENU) velocity error norm |R(q_est) v_est_flu - v| in m/s and attitude error
    angle of q* q_est in rad."""
    p = log_columns(truth_columns, truth_j, "px", "py", "pz")
    v = log_columns(truth_columns, truth_j, "vx", "vy", "vz")
    q = log_columns(truth_columns, truth_j, "qw", "qx", "qy", "qz")
    p_e = log_columns(onboard_columns, onboard_j, "px", "py", "pz")
    q_e = log_columns(onboard_columns, onboard_j, "qw", "qx", "qy", "qz")
    v_e = rotate_rows(q_e, log_columns(onboard_columns, onboard_j, "vbx", "vby", "vbz"))
    return (np.linalg.norm(p_e - p, axis=1), np.linalg.norm(v_e - v, axis=1),
            attitude_error_rad(q_e, q))


def estimation_error(truth_columns: Sequence[str], truth_j: np.ndarray,
                     onboard_columns: Sequence[str], onboard_j: np.ndarray) -> dict[str, Any]:
    """`estimation_error_rows` as metrics.json's estimation_error: position, velocity and
    attitude, each {max, mean, rmse}."""
    dp, dv, da = estimation_error_rows(truth_columns, truth_j, onboard_columns, onboard_j)
    return {"position_m": error_stats(dp), "velocity_m_s": error_stats(dv),
            "attitude_rad": error_stats(da)}


def add_link_timing(metrics: RunMetrics, fcu_stats: dict[str, Any],
                    sitl_stats: dict[str, Any], transport: str, *, lockstep: bool) -> None:
    """Into `metrics`, the lockstep path's timing in a run through processes: the wall time
    per control step
    (`step_wall_us`), the simulator link's round trip that the FCU timed before the flight
    (TIMESYNC ping-pong between the two processes, median: `link_rtt_us`, and as
    `udp_rtt_us` on UDP), their ratio `step_per_rtt`, and where a step's wall time goes
    (`step_stages_us`: each process's stages, means per step, from their stats)."""
    samples = int(metrics.get("samples") or 0)
    wall = float(metrics.get("wall_time_s") or 0.0)
    step_us = wall / samples * 1e6 if samples and lockstep else None
    rtt = (fcu_stats.get("sim_rtt") or {}).get("median_us")
    metrics["step_wall_us"] = step_us
    metrics["link_rtt_us"] = rtt
    metrics["step_per_rtt"] = step_us / rtt if step_us and rtt else None
    if transport == "udp":
        metrics["udp_rtt_us"] = rtt
    stages = {}
    if fcu_stats.get("stage_us"):
        stages["fcu"] = fcu_stats["stage_us"]
    if sitl_stats.get("stage_us"):
        stages["sitl"] = sitl_stats["stage_us"]
    if stages:
        metrics["step_stages_us"] = stages


def build_metrics(scenario: Scenario, truth_columns: Sequence[str], truth: np.ndarray,
                  onboard_columns: Sequence[str], onboard: np.ndarray, *,
                  events: Sequence[Event], wall_time_s: float, transport: str,
                  lockstep: bool, deadline_misses: int = 0, mission_completed: bool = False,
                  stopped: str = "", reached_end: bool | None = None,
                  flight_start_us: int = 0,
                  compile_time_s: float | None = None) -> RunMetrics:
    """metrics.json content (docs/architecture.md#a-run-folder), status included (common.outcome).

    `reached_end`: whether the run reached its end; None reads it from the truth log (the
    simulator's clock is the flight's in lockstep and in-process). `flight_start_us`: the
    flight's start on that clock (after the estimator's alignment with a sensor profile):
    the scenario's duration counts from it. `stopped`: "timeout" or
    "aborted" when the runner could not finish. `compile_time_s` (in-process runs): the
    seconds its process spent compiling or loading the numba kernels, outside wall_time_s.

    Errors compare the plant's true pose with the desired pose the FCU computed for the same
    control step (`join_logs`), over the rows `followed_rows` keeps (`error_rows`: the rule,
    the rows counted and those left out; divergence is judged on every row). A run
    diverges at the first joined sample that `diverged_rows` flags (position beyond the
    scenario's limit, attitude error above the scenario's divergence_attitude_rad held for
    its divergence_attitude_hold_s, or a non-finite state), and its figures cover the run up
    to that instant (never inf or NaN).
    """
    common_t, truth_j, onboard_j = join_logs(truth_columns, truth, onboard_columns, onboard)
    p = log_columns(truth_columns, truth_j, "px", "py", "pz")
    q = log_columns(truth_columns, truth_j, "qw", "qx", "qy", "qz")
    p_d = log_columns(onboard_columns, onboard_j, "pdx", "pdy", "pdz")
    q_d = log_columns(onboard_columns, onboard_j, "qdw", "qdx", "qdy", "qdz")
    bad = diverged_rows(p, q, p_d, q_d, scenario.divergence_position_m, t_us=common_t,
                        attitude_limit_rad=scenario.divergence_attitude_rad,
                        attitude_hold_s=scenario.divergence_attitude_hold_s)
    end = len(common_t)
    divergence_t_us = None
    cause = ""
    if np.any(bad):
        first = int(np.argmax(bad))
        divergence_t_us = int(common_t[first])
        if not diverged_rows(p[first:first + 1], q[first:first + 1], p_d[first:first + 1],
                             q_d[first:first + 1], scenario.divergence_position_m,
                             t_us=common_t[first:first + 1])[0]:
            cause = (f"attitude error above {scenario.divergence_attitude_rad:g} rad for "
                     f"{scenario.divergence_attitude_hold_s:g} s")
        # Keep the first divergent sample when it is finite: the figures reach that instant.
        end = first + 1 if np.all(np.isfinite(np.hstack([p[first], q[first], p_d[first],
                                                          q_d[first]]))) else first
    t_truth = truth[:, list(truth_columns).index("time_us")] if len(truth) else np.zeros(0)
    if reached_end is None:  # lockstep: the simulator's clock is the flight's
        reached_end = bool(len(t_truth)) and \
            int(t_truth[-1]) >= flight_start_us + round(scenario.duration_s * 1e6)
    outcome = classify(reached_end=reached_end, events=events,
                       divergence_t_us=divergence_t_us,
                       crash_t_us=crash_time_us(truth_columns, truth), stopped=stopped,
                       divergence_cause=cause)
    followed = followed_rows(p_d[:end], truth_j[:end, list(truth_columns).index("landed")])
    sim_time_s = float((t_truth[-1] - flight_start_us) * 1e-6) if len(t_truth) else 0.0
    steps = onboard_j[:end, list(onboard_columns).index("step_us")]
    sat = onboard_j[:end, list(onboard_columns).index("saturated")]
    tracking = tracking_metrics(p[:end][followed], q[:end][followed], p_d[:end][followed],
                                q_d[:end][followed])
    metrics: RunMetrics = {
        "scenario": scenario.name,
        "sensors": scenario.sensors.name if scenario.sensors is not None else "truth",
        "alignment_s": flight_start_us * 1e-6,
        "controller": scenario.controller,
        "lockstep": lockstep,
        "transport": transport,
        "sim_time_s": sim_time_s,
        "wall_time_s": wall_time_s,
        "real_time_factor": sim_time_s / wall_time_s if wall_time_s > 0 else 0.0,
        "control_rate_hz": scenario.control_rate_hz,
        "physics_rate_hz": scenario.physics_rate_hz,
        "ideal_actuators": scenario.ideal_actuators,
        "damping": scenario.gains.damping,
        "position_error_m": tracking["position_error_m"],
        "attitude_error_rad": tracking["attitude_error_rad"],
        "error_rows": {"rule": ERROR_ROWS_RULE, "counted": int(np.sum(followed)),
                       "on_ground_reference_below": int(end - np.sum(followed))},
        "fcu_step_us": percentiles_us(steps[np.isfinite(steps)]),
        "deadline_misses": deadline_misses,
        "saturated_steps": int(np.sum(sat > 0)),
        "samples": int(end),
        "mission_completed": mission_completed,
        "status": outcome.status,
        "status_reason": outcome.reason,
        "divergence_t_s": None if divergence_t_us is None else divergence_t_us * 1e-6,
        "failsafe": outcome.failsafe,
        "events": [event_record(e) for e in events],
        "seed": scenario.seed,
    }
    if scenario.uses_sensors:
        metrics["estimation_error"] = estimation_error(truth_columns, truth_j[:end],
                                                       onboard_columns, onboard_j[:end])
    if compile_time_s is not None:
        metrics["compile_time_s"] = compile_time_s
    return metrics
