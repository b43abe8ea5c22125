"""Tracking metrics of DESIGN.md section 6 and the paper's Table I.

Position error = |p - p_d|; attitude error = angle of q_d* q in [0, pi]; both sampled at the
control steps (the desired pose is the one the controller computed for that step).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

STATUSES = ("completed", "diverged", "timeout", "aborted")


def attitude_error_rad(q: np.ndarray, q_d: np.ndarray) -> np.ndarray:
    """Angle of q_d* q for rows of (w, x, y, z) quaternions, in [0, pi]."""
    dot = np.abs(np.sum(q * q_d, axis=1))  # |scalar part of q_d* q|
    # vector part of q_d* q
    w1, v1 = q_d[:, 0], -q_d[:, 1:]
    w2, v2 = q[:, 0], q[:, 1:]
    vec = w1[:, None] * v2 + w2[:, None] * v1 + np.cross(v1, v2)
    return 2.0 * np.arctan2(np.linalg.norm(vec, axis=1), dot)


def error_stats(err: np.ndarray) -> dict[str, float]:
    if err.size == 0:
        return {"max": 0.0, "mean": 0.0, "rmse": 0.0}
    return {"max": float(np.max(err)), "mean": float(np.mean(err)),
            "rmse": float(math.sqrt(float(np.mean(err * err))))}


def percentiles_us(samples: np.ndarray) -> dict[str, float]:
    if samples.size == 0:
        return {"p50": 0.0, "p99": 0.0, "max": 0.0}
    return {"p50": float(np.percentile(samples, 50)), "p99": float(np.percentile(samples, 99)),
            "max": float(np.max(samples))}


def tracking_metrics(p: np.ndarray, q: np.ndarray, p_d: np.ndarray,
                     q_d: np.ndarray) -> dict[str, Any]:
    """Table I figures; rows must be finite (a diverged run is cut at its last finite row)."""
    pos = np.linalg.norm(p - p_d, axis=1)
    att = attitude_error_rad(q, q_d)
    return {"position_error_m": error_stats(pos), "attitude_error_rad": error_stats(att)}


def rank_key(metrics: dict[str, Any]) -> tuple[int, float]:
    """Sort key: completed runs first, then by position RMSE (diverged ranks below all)."""
    return (0 if metrics.get("status") == "completed" else 1,
            float(metrics["position_error_m"]["rmse"]))
