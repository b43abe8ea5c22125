"""The replay's input: a run folder's truth.ulg (`dq_truth`) and onboard.ulg (`dq_onboard`)
as time-sorted arrays, sampled at any instant of the run's timeline."""

from __future__ import annotations

import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from common.quaternion import Quat, Vec3
from common.vehicle_constants import N_ROTORS
from gcs.report.metrics import onboard_on_truth_clock
from gcs.view.sample import Pose, Sample
from gcs.view.settings import DEFAULT_VEHICLE, ViewError


def _cols(columns: Sequence[str], rows: np.ndarray, names: Sequence[str],
          what: str) -> np.ndarray:
    missing = [n for n in names if n not in columns]
    if missing:
        raise ViewError(f"{what}: no column {missing[0]}")
    return rows[:, [list(columns).index(n) for n in names]]


@dataclass
class ReplayLog:
    """The replayed samples: truth rows (time, pose, speeds, tilts) and onboard rows (time,
    desired pose, armed), ENU/FLU, each sorted by time."""

    truth_t_us: np.ndarray
    truth_p: np.ndarray
    truth_q: np.ndarray
    truth_rotors: np.ndarray
    truth_tilts: np.ndarray
    onboard_t_us: np.ndarray
    onboard_pd: np.ndarray
    onboard_qd: np.ndarray
    onboard_armed: np.ndarray | None

    @classmethod
    def from_rows(cls, truth_cols: Sequence[str], truth: np.ndarray,
                  onboard_cols: Sequence[str] | None = None,
                  onboard: np.ndarray | None = None) -> ReplayLog:
        truth = truth[np.isfinite(_cols(truth_cols, truth, ("time_us",), "dq_truth")[:, 0])]
        if onboard is None or onboard_cols is None:
            onboard_cols, onboard = ("time_us",), np.zeros((0, 1))
        onboard = onboard[np.isfinite(_cols(onboard_cols, onboard, ("time_us",),
                                            "dq_onboard")[:, 0])]
        truth = truth[np.argsort(_cols(truth_cols, truth, ("time_us",), "dq_truth")[:, 0],
                                 kind="stable")]
        ob_t = _cols(onboard_cols, onboard, ("time_us",), "dq_onboard")[:, 0]
        onboard, ob_t = onboard[np.argsort(ob_t, kind="stable")], np.sort(ob_t, kind="stable")
        armed = (_cols(onboard_cols, onboard, ("armed",), "dq_onboard")[:, 0]
                 if "armed" in onboard_cols else None)
        has_desired = len(onboard) > 0
        return cls(
            truth_t_us=_cols(truth_cols, truth, ("time_us",), "dq_truth")[:, 0].astype(np.int64),
            truth_p=_cols(truth_cols, truth, ("px", "py", "pz"), "dq_truth"),
            truth_q=_cols(truth_cols, truth, ("qw", "qx", "qy", "qz"), "dq_truth"),
            truth_rotors=_cols(truth_cols, truth, [f"rotor{i}" for i in range(N_ROTORS)],
                               "dq_truth"),
            truth_tilts=_cols(truth_cols, truth, [f"tilt{i}" for i in range(N_ROTORS)],
                              "dq_truth"),
            onboard_t_us=ob_t.astype(np.int64),
            onboard_pd=(_cols(onboard_cols, onboard, ("pdx", "pdy", "pdz"), "dq_onboard")
                        if has_desired else np.zeros((0, 3))),
            onboard_qd=(_cols(onboard_cols, onboard, ("qdw", "qdx", "qdy", "qdz"), "dq_onboard")
                        if has_desired else np.zeros((0, 4))),
            onboard_armed=armed)

    @property
    def span_us(self) -> tuple[int, int]:
        if len(self.truth_t_us) == 0:
            raise ViewError("dq_truth holds no rows")
        return int(self.truth_t_us[0]), int(self.truth_t_us[-1])

    def sample_at(self, t_us: int) -> Sample:
        """The sample as it stood at `t_us`: the last truth and onboard rows at or before."""
        s = Sample()
        i = int(np.searchsorted(self.truth_t_us, t_us, side="right")) - 1
        if i >= 0:
            s.pose = Pose(_vec3(self.truth_p[i]), _quat(self.truth_q[i]))
            s.pose_time_us = int(self.truth_t_us[i])
            s.rotor_speeds_rad_s = tuple(float(v) for v in self.truth_rotors[i])
            s.tilts_rad = tuple(float(v) for v in self.truth_tilts[i])
            s.actuator_time_us = s.pose_time_us
        j = int(np.searchsorted(self.onboard_t_us, t_us, side="right")) - 1
        if j >= 0:
            pd, qd = self.onboard_pd[j], self.onboard_qd[j]
            if np.all(np.isfinite(pd)) and np.all(np.isfinite(qd)):
                s.desired = Pose(_vec3(pd), _quat(qd))
                s.desired_time_us = int(self.onboard_t_us[j])
            if self.onboard_armed is not None:
                s.armed = bool(self.onboard_armed[j] > 0.5)
        return s


def _vec3(a: np.ndarray) -> Vec3:
    return (float(a[0]), float(a[1]), float(a[2]))


def _quat(a: np.ndarray) -> Quat:
    return (float(a[0]), float(a[1]), float(a[2]), float(a[3]))


def replay_vehicle_path(run_dir: Path) -> Path:
    """The vehicle file a run folder's scenario names (looked up among config/vehicles by
    name, the copied scenario's relative path no longer resolving), else the default."""
    try:
        name = Path(str(tomllib.loads((run_dir / "scenario.toml").read_text())["vehicle"])).name
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return DEFAULT_VEHICLE
    candidate = DEFAULT_VEHICLE.parent / name
    return candidate if candidate.is_file() else DEFAULT_VEHICLE


def load_replay(run_dir: Path) -> ReplayLog:
    """The run folder's truth.ulg (required) and onboard.ulg (optional) as a ReplayLog."""
    if not run_dir.is_dir():
        raise ViewError(f"{run_dir} is not a folder")
    truth_path, onboard_path = run_dir / "truth.ulg", run_dir / "onboard.ulg"
    if not truth_path.is_file():
        raise ViewError(f"{run_dir} has no truth.ulg (not a run folder with ULog logs)")
    try:
        from common.logs import ulog
    except ImportError:
        raise ViewError("replay needs common/logs/ulog.py (ULog reader)") from None
    try:
        tc, truth = ulog.read_topic(truth_path, "dq_truth")
        oc: tuple[str, ...] | None = None
        onboard = None
        if onboard_path.is_file():
            oc, onboard = onboard_on_truth_clock(*ulog.read_topic(onboard_path, "dq_onboard"))
    except (ulog.ULogError, OSError, ValueError) as exc:
        raise ViewError(str(exc)) from None
    log = ReplayLog.from_rows(tc, truth, oc, onboard)
    log.span_us  # noqa: B018  (refuses an empty log now)
    return log
