"""A run folder loaded for its report: metrics.json, scenario.toml and the two logs joined on
time_us (gcs.report.metrics.join_logs), non-finite rows dropped, cut at the divergence."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.vehicle_constants import N_ROTORS
from gcs.report.metrics import estimation_error_rows, join_logs, log_columns
from gcs.report.run_metrics import RunMetrics
from gcs.run.runio import check_run_dir, read_run_logs


@dataclass
class RunData:
    """A run folder's logs joined on time_us, non-finite rows dropped, cut at divergence."""

    run_dir: Path
    metrics: RunMetrics
    scenario: dict[str, Any]
    t: np.ndarray  # s
    p: np.ndarray  # truth position, ENU m
    q: np.ndarray  # truth attitude (w, x, y, z)
    p_d: np.ndarray
    q_d: np.ndarray
    tilt_raw: np.ndarray  # rad, (N, 6)
    tilt_cmd: np.ndarray
    dropped_rows: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return str(self.metrics.get("scenario") or self.scenario.get("name") or "run")

    @property
    def controller(self) -> str:
        return str(self.metrics.get("controller") or self.scenario.get("controller") or "?")

    @property
    def status(self) -> str:
        return str(self.metrics.get("status", "unknown"))

    @property
    def diverged(self) -> bool:
        return self.status == "diverged"

    @property
    def title(self) -> str:
        text = f"{self.name} [{self.controller.upper()}]"
        if self.diverged and len(self.t):
            text += f" (DIVERGED at t = {self.t[-1]:.2f} s)"
        elif self.status not in ("completed", "unknown"):
            text += f" ({self.status})"
        return text

    @property
    def force_terms(self) -> list[dict[str, Any]]:
        return list(self.scenario.get("disturbance", {}).get("force", []))

    @property
    def torque_terms(self) -> list[dict[str, Any]]:
        return list(self.scenario.get("disturbance", {}).get("torque", []))

    @property
    def disturbed(self) -> bool:
        return bool(self.force_terms or self.torque_terms)


def load_run(run_dir: Path) -> RunData:
    run_dir = Path(run_dir)
    metrics = check_run_dir(run_dir)
    scen_path = run_dir / "scenario.toml"
    scenario = tomllib.loads(scen_path.read_text()) if scen_path.exists() else {}
    tc, truth, oc, onboard = read_run_logs(run_dir)
    truth = truth[np.isfinite(truth[:, tc.index("time_us")])]
    onboard = onboard[np.isfinite(onboard[:, oc.index("time_us")])]
    common_t, truth, onboard = join_logs(tc, truth, oc, onboard)
    t = common_t * 1e-6
    p = log_columns(tc, truth, "px", "py", "pz")
    q = log_columns(tc, truth, "qw", "qx", "qy", "qz")
    p_d = log_columns(oc, onboard, "pdx", "pdy", "pdz")
    q_d = log_columns(oc, onboard, "qdw", "qdx", "qdy", "qdz")
    tilt_raw = log_columns(oc, onboard, *(f"tilt_raw{i}" for i in range(N_ROTORS)))
    tilt_cmd = log_columns(oc, onboard, *(f"tilt_cmd{i}" for i in range(N_ROTORS)))

    keep = np.all(np.isfinite(np.hstack([p, q, p_d, q_d, tilt_raw, tilt_cmd])), axis=1)
    notes: list[str] = []
    divergence_t_s = metrics.get("divergence_t_s")
    if divergence_t_s is not None:
        # metrics.json ends a diverged run at its first divergent sample; so do the figures.
        keep &= t <= divergence_t_s + 1e-9
    dropped = int(np.sum(~keep))
    if dropped:
        nonfinite = int(np.sum(~np.all(np.isfinite(
            np.hstack([p, q, p_d, q_d, tilt_raw, tilt_cmd])), axis=1)))
        notes.append(f"{dropped} logged rows left out of the figures ({nonfinite} with "
                     "non-finite values" + (", the rest after the divergence" if
                                             dropped > nonfinite else "") + ").")
    t, p, q, p_d, q_d = t[keep], p[keep], q[keep], p_d[keep], q_d[keep]
    tilt_raw, tilt_cmd = tilt_raw[keep], tilt_cmd[keep]
    return RunData(run_dir, metrics, scenario, t, p, q, p_d, q_d, tilt_raw, tilt_cmd,
                   dropped_rows=dropped, notes=notes)


def estimation_errors(data: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t s, position error norm m, world velocity error norm m/s, attitude error angle rad)
    of the estimate (dq_onboard's state) against the truth at the same control steps, by
    gcs.report.metrics.estimation_error_rows (metrics.json's estimation_error); non-finite
    rows dropped, cut at divergence."""
    tc, truth, oc, onboard = read_run_logs(data.run_dir)
    truth = truth[np.isfinite(truth[:, tc.index("time_us")])]
    onboard = onboard[np.isfinite(onboard[:, oc.index("time_us")])]
    common_t, truth, onboard = join_logs(tc, truth, oc, onboard)
    dp, dv, da = estimation_error_rows(tc, truth, oc, onboard)
    t = common_t * 1e-6
    keep = np.isfinite(dp) & np.isfinite(dv) & np.isfinite(da)
    divergence_t_s = data.metrics.get("divergence_t_s")
    if divergence_t_s is not None:
        keep &= t <= divergence_t_s + 1e-9
    return t[keep], dp[keep], dv[keep], da[keep]


def cut_short(data: RunData) -> bool:
    run = data.metrics.get("overrides", {}).get("duration_s")
    full = data.scenario.get("duration_s")
    return isinstance(run, int | float) and isinstance(full, int | float) and run < full
