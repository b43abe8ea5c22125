"""Where a Z-Y-X (yaw-pitch-roll) Euler description of an attitude history breaks down.

The tracker never uses Euler angles; this is for reports (the paper's Fig. 4 marks such
instants). An instant is `singular` where |pitch| comes within `tol` of pi/2 (gimbal lock)
and a `jump` where roll or yaw wraps across +-pi between two samples.
"""

from __future__ import annotations

import numpy as np

from common.quaternion import zyx_euler_rows


def zyx_events(t_s: np.ndarray, q: np.ndarray, tol: float = 1e-3) -> list[tuple[float, str]]:
    """Sorted (time, kind) pairs, kind in {"singular", "jump"}; runs of samples collapse."""
    euler = zyx_euler_rows(q)
    events: list[tuple[float, str]] = []
    near = np.abs(np.abs(euler[:, 1]) - np.pi / 2) < tol
    starts = np.flatnonzero(near & ~np.concatenate([[False], near[:-1]]))
    events += [(float(t_s[i]), "singular") for i in starts]
    wraps = np.any(np.abs(np.diff(euler[:, [0, 2]], axis=0)) > np.pi, axis=1) & ~near[1:]
    events += [(float(t_s[i + 1]), "jump") for i in np.flatnonzero(wraps)]
    return sorted(events)
