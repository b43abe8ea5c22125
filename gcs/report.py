"""Run reports: the paper's figures and a one-page report.md for a run folder or for a
folder written by `gcs table1 --out DIR`.

`make_report(run_dir)` reads metrics.json, scenario.toml and the two ULogs written by
`gcs run ... --out DIR` (in-process or through processes) and writes `DIR/figures/*.png`
and `DIR/report.md`:

- fig3_tilt_unwrapping.png: tilt angles before (atan2, jumping at +-pi) and after unwrapping.
- fig4_tracking.png: (a) quaternion actual vs desired with the instants where a Z-Y-X Euler
  description of the desired attitude is singular or jumps, (b) attitude error angle,
  (c) position actual vs desired, (d) position error norm and per-axis errors.
- fig5_pd_tracking_errors.png (Case I runs with the PD controller only): the paper's Fig. 5,
  "tracking errors for the PD controller": (a) attitude error angle and (b) position error,
  drawn as Fig. 4 (b) and (d). It comes in addition to Fig. 4, which every run gets (the
  paper draws Fig. 4 for PID only, but a PD run's quaternion and position traces are worth
  having too); a PID Case I run has no Fig. 5 (its errors are Fig. 4 (b) and (d)).
- fig6_path_3d.png: desired vs flown path in 3D.
- fig7_8_disturbance.png (runs with [[disturbance.*]] tables only): one run's position and
  attitude error with the pulse intervals shaded and the applied body-frame force and torque.
- estimation.png and innovations.png (runs with the estimator only: metrics.json has
  `estimation_error`): the estimate (dq_onboard's state) minus the truth (dq_truth, joined on
  time_us): position and velocity error norms and the attitude error angle; the pose's
  innovations (estimator_innovations: position NED, heading) and test ratios
  (estimator_innovation_test_ratios, the gate at 1). report.md gets the estimation_error
  figures beside them.

`make_table1_report(dir)` does the above for each of the 8 run folders of a table1 folder
(`<scenario>_<controller>`, e.g. `case2_impulse_pd`) and writes, in the table1 folder itself:

- table1.png: the Table I chart (`table1_chart`), redrawn from the run folders.
- fig5_pd_tracking_errors.png: Fig. 5 from `case1_figure8_pd`, with the PID run's errors
  (`case1_figure8_pid`, Fig. 4) in grey for comparison, as the paper's text compares them.
- fig7_disturbance_pid.png and fig8_disturbance_pd.png: the paper's Figs. 7 (PID) and 8
  (PD), drawn from the three Case II runs of that controller: one row per disturbance
  (impulse, sinusoidal ("regular" in Table I), irregular) and three columns lettered down
  the columns, as the paper's text reads them ("Figs. 7 (a) and (d)" are both the impulse
  row): attitude error angle (a-c), position error (d-f) and the applied disturbance (g-i);
  pulse intervals are shaded on the whole row. A diverged run is drawn up to its divergence
  (`divergence_t_s`), marked by a red dotted line and named in its row's titles; a missing
  run leaves its row empty and says so.
- report.md: Table I (ours beside the paper), every run's status, why, and its events, links
  to every figure, and the run folders that are missing or could not be read.

`table1_chart(table, png)` draws `gcs.table1.table_json` output as grouped bars.

Figures are drawn on matplotlib's Agg canvas directly (never pyplot, never a screen); long
series are thinned to every bucket's first, minimum and maximum sample, so peaks survive.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from common.quaternion import rotate_rows
from common.ulog import ULogError, open_ulog, topic_rows
from gcs.euler import zyx_events
from gcs.metrics import attitude_error_rad, join_logs, log_columns
from gcs.runio import ONBOARD_LOG, check_run_dir, read_run_logs
from gcs.table1 import CASES, CONTROLLERS, PAPER, STATS, table_json, table_markdown

FIG_DIR = "figures"
FIG3 = "fig3_tilt_unwrapping.png"
FIG4 = "fig4_tracking.png"
FIG5 = "fig5_pd_tracking_errors.png"
FIG6 = "fig6_path_3d.png"
FIG7 = "fig7_disturbance_pid.png"
FIG8 = "fig8_disturbance_pd.png"
FIG78 = "fig7_8_disturbance.png"
FIG_ESTIMATION = "estimation.png"
FIG_INNOVATIONS = "innovations.png"
REPORT = "report.md"
TABLE1_JSON = "table1.json"  # what makes a folder a table1 folder
TABLE1_PNG = "table1.png"

CASE1 = "case1_figure8"
# The rows of Figs. 7 and 8, in the paper's order: (scenario, what the row shows).
CASE2_ROWS = (("case2_impulse", "impulse disturbance"),
              ("case2_sine", "sinusoidal (regular) disturbance"),
              ("case2_irregular", "irregular disturbance"))
FIG78_BY_CONTROLLER = {"pid": (7, FIG7), "pd": (8, FIG8)}  # figure number, file

DPI = 150
WIDTH_IN = 11.0  # 1650 px at DPI
BUCKETS = 2000  # thinning: at most ~2000 buckets per series (about one per pixel column)
AXIS_COLORS = ("tab:red", "tab:green", "tab:blue")  # x, y, z
QUAT_COLORS = ("tab:gray", "tab:red", "tab:green", "tab:blue")  # w, x, y, z
ROTOR_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


# ---------------------------------------------------------------------------------------------
# Loading a run folder
# ---------------------------------------------------------------------------------------------

@dataclass
class RunData:
    """A run folder's logs joined on time_us, non-finite rows dropped, cut at divergence."""

    run_dir: Path
    metrics: dict[str, Any]
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


SEVERITY = {0: "emergency", 1: "alert", 2: "critical", 3: "error", 4: "warning", 5: "notice",
            6: "info", 7: "debug"}


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
    tilt_raw = log_columns(oc, onboard, *(f"tilt_raw{i}" for i in range(6)))
    tilt_cmd = log_columns(oc, onboard, *(f"tilt_cmd{i}" for i in range(6)))

    keep = np.all(np.isfinite(np.hstack([p, q, p_d, q_d, tilt_raw, tilt_cmd])), axis=1)
    notes: list[str] = []
    if metrics.get("divergence_t_s") is not None:
        # metrics.json ends a diverged run at its first divergent sample; so do the figures.
        keep &= t <= float(metrics["divergence_t_s"]) + 1e-9
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


# ---------------------------------------------------------------------------------------------
# Plot helpers
# ---------------------------------------------------------------------------------------------

def thin_indices(y: np.ndarray, buckets: int = BUCKETS) -> np.ndarray:
    """Sorted row indices keeping, per bucket of rows, the first sample and every column's
    minimum and maximum (so peaks and dips survive); all rows when there are few."""
    n = len(y)
    if n <= 3 * buckets:
        return np.arange(n)
    y2 = np.asarray(y, dtype=float).reshape(n, -1)
    size = -(-n // buckets)
    m = n // size * size
    blocks = y2[:m].reshape(-1, size, y2.shape[1])
    base = np.arange(0, m, size)
    parts = [base, np.arange(m, n), np.array([n - 1]),
             (base[:, None] + np.argmax(blocks, axis=1)).ravel(),
             (base[:, None] + np.argmin(blocks, axis=1)).ravel()]
    return np.unique(np.concatenate(parts))


def _thin(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = thin_indices(y)
    return t[idx], y[idx]


def _break_wraps(t: np.ndarray, y: np.ndarray, threshold: float) -> tuple[np.ndarray,
                                                                          np.ndarray]:
    """Insert a gap wherever y jumps by more than threshold (no vertical connecting line)."""
    j = np.flatnonzero(np.abs(np.diff(y)) > threshold) + 1
    return np.insert(t.astype(float), j, np.nan), np.insert(y.astype(float), j, np.nan)


def _new_figure(height_in: float) -> Figure:
    # Constrained layout: a tight layout that also makes room for legends outside the axes.
    fig = Figure(figsize=(WIDTH_IN, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    return path


def _mark_end(ax, data: RunData, *, label: bool = False) -> Line2D | None:
    """Time axis from 0 to the run's end; a diverged run's end drawn as a red dotted line
    (named in the legend when `label`), which is returned."""
    end = _end_time(data)
    if not (data.diverged and len(data.t)):
        ax.set_xlim(0.0, end)
        return None
    ax.set_xlim(0.0, end * 1.02)
    return ax.axvline(end, color="red", lw=1.6, ls=":", zorder=1,
                      label=f"diverged\n(t = {end:.2f} s)" if label else None)


def _legend_right(ax, **kwargs) -> None:
    """Legend outside the axes on the right, so it never hides data."""
    kwargs.setdefault("fontsize", 9)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
              framealpha=0.9, **kwargs)


def _style(ax, ylabel: str, *, xlabel: bool = False) -> None:
    ax.set_ylabel(ylabel)
    if xlabel:
        ax.set_xlabel("time t (s)")
    ax.grid(True, alpha=0.3)


def _end_time(data: RunData) -> float:
    return float(data.t[-1]) if len(data.t) and data.t[-1] > 0 else 1.0


def _rmse(x: np.ndarray) -> float:
    return math.sqrt(float(np.mean(x ** 2))) if x.size else 0.0


def _stats_text(x: np.ndarray, unit: str) -> str:
    return f"max {np.max(x, initial=0):.3g} {unit}, RMSE {_rmse(x):.3g} {unit}"


def _plot_attitude_error(ax, data: RunData, *, color: str = "tab:purple", lw: float = 1.1,
                         label: str = "∠(q_d* q)") -> np.ndarray:
    """The attitude error angle of q_d* q over time (thinned); returns the whole series."""
    att = attitude_error_rad(data.q, data.q_d)
    ta, ya = _thin(data.t, att)
    ax.plot(ta, ya, color=color, lw=lw, label=label)
    return att


def _plot_position_error(ax, data: RunData) -> np.ndarray:
    """Per-axis position errors and their norm over time (thinned); returns the norm."""
    err = data.p - data.p_d
    norm = np.linalg.norm(err, axis=1)
    idx = thin_indices(np.column_stack([norm, err]))
    t = data.t
    for k, name in enumerate("xyz"):
        ax.plot(t[idx], err[idx, k], color=AXIS_COLORS[k], lw=0.9,
                label=f"e_{name} = {name} − {name}_d")
    ax.plot(t[idx], norm[idx], color="k", lw=1.4, label="|p − p_d|")
    ax.axhline(0.0, color="k", lw=0.6, alpha=0.5)
    return norm


# ---------------------------------------------------------------------------------------------
# Figures
# ---------------------------------------------------------------------------------------------

def fig3_tilt(data: RunData, path: Path) -> Path:
    """Tilt angles before (atan2 in [-pi, pi]) and after unwrapping, six rotors."""
    fig = _new_figure(7.5)
    ax_raw, ax_cmd = fig.subplots(2, 1, sharex=True)
    t = data.t
    for i in range(6):
        tr, yr = _thin(t, data.tilt_raw[:, i])
        ax_raw.plot(*_break_wraps(tr, yr, math.pi), color=ROTOR_COLORS[i], lw=1.2,
                    label=f"rotor {i}")
        tc, yc = _thin(t, data.tilt_cmd[:, i])
        ax_cmd.plot(tc, yc, color=ROTOR_COLORS[i], lw=1.2, label=f"rotor {i}")
    jumps = int(np.sum(np.abs(np.diff(data.tilt_raw, axis=0)) > math.pi))
    for y in (-math.pi, math.pi):
        ax_raw.axhline(y, color="k", lw=0.8, ls="--", alpha=0.6)
    ax_raw.set_yticks([-math.pi, -math.pi / 2, 0.0, math.pi / 2, math.pi],
                      ["−π", "−π/2", "0", "π/2", "π"])
    ax_raw.set_ylim(-math.pi * 1.12, math.pi * 1.12)
    ax_raw.set_title(f"(a) before unwrapping: atan2 in [−π, π], {jumps} jumps of 2π "
                     "(drawn as gaps)")
    ax_cmd.set_title("(b) after unwrapping: commanded tilt, continuous")
    _style(ax_raw, "tilt angle α (rad)")
    _style(ax_cmd, "tilt angle α (rad)", xlabel=True)
    for ax in (ax_raw, ax_cmd):
        _mark_end(ax, data, label=ax is ax_raw)
    _legend_right(ax_raw, title="log index")
    fig.suptitle(f"Fig. 3 – tilt angles of the six rotors: {data.title}")
    return _save(fig, path)


def _log_axis(ax, values: np.ndarray, decades: float = 4.0) -> str:
    """Log y axis over the top `decades` of the data; returns a note when values fall below."""
    pos = values[values > 0]
    if pos.size == 0:
        return ""
    ax.set_yscale("log", nonpositive="mask")
    top = float(pos.max())
    floor = 10.0 ** math.floor(math.log10(max(float(pos.min()), top * 10.0 ** -decades)))
    ax.set_ylim(floor, 10.0 ** math.ceil(math.log10(top) + 1e-9))
    return f"; axis floor {floor:.0e} rad" if pos.min() < floor else ""


def fig4_tracking(data: RunData, events: list[tuple[float, str]], path: Path) -> Path:
    """(a) quaternion, (b) attitude error, (c) position, (d) position error."""
    fig = _new_figure(13.0)
    ax_q, ax_att, ax_p, ax_ep = fig.subplots(4, 1, sharex=True)
    t = data.t

    # (a) quaternion components, actual solid, desired dashed; Euler events as red x.
    idx = thin_indices(np.hstack([data.q, data.q_d]))
    for k in range(4):
        ax_q.plot(t[idx], data.q_d[idx, k], color=QUAT_COLORS[k], lw=2.4, ls="--", alpha=0.8)
        ax_q.plot(t[idx], data.q[idx, k], color=QUAT_COLORS[k], lw=1.1)
    handles = [Line2D([], [], color=QUAT_COLORS[k], lw=2, label=f"q_{name}")
               for k, name in enumerate("wxyz")]
    handles += [Line2D([], [], color="k", lw=1.1, label="actual"),
                Line2D([], [], color="k", lw=2.4, ls="--", alpha=0.8, label="desired")]
    kinds = {"jump": ("x", "Z-Y-X Euler jump\n(roll/yaw wraps ±π)"),
             "singular": ("+", "Z-Y-X Euler singular\n(|pitch| = π/2)")}
    for kind, (marker, label) in kinds.items():
        times = np.array([te for te, k in events if k == kind])
        if times.size == 0:
            continue
        j = np.clip(np.searchsorted(t, times), 0, len(t) - 1)
        for tt in times:
            ax_q.axvline(tt, color="red", lw=0.8, alpha=0.3, zorder=0)
        ax_q.plot(np.repeat(t[j], 4), data.q_d[j].ravel(), ls="none", marker=marker,
                  color="red", ms=8, mew=1.8, zorder=5)
        handles.append(Line2D([], [], ls="none", marker=marker, color="red", ms=8, mew=1.8,
                              label=f"{label}: {times.size}"))
    if not events:
        handles.append(Line2D([], [], ls="none", marker="x", color="red", ms=8, mew=1.8,
                              label="Z-Y-X Euler\nsingular/jump: none"))
    end_line = _mark_end(ax_q, data, label=True)
    _legend_right(ax_q, handles=handles + ([end_line] if end_line else []))
    ax_q.set_ylim(-1.08, 1.08)
    opposite = bool(np.any(np.sum(data.q * data.q_d, axis=1) < 0.0))
    ax_q.set_title("(a) attitude quaternion q (world ← body), actual vs desired"
                   + ("; q and −q are the same attitude" if opposite else ""))
    _style(ax_q, "component (–)")

    # (b) attitude error angle, log scale.
    att = _plot_attitude_error(ax_att, data)
    note = _log_axis(ax_att, att)
    ax_att.set_title(f"(b) attitude error angle: {_stats_text(att, 'rad')}" + note)
    _legend_right(ax_att)
    _style(ax_att, "error angle (rad)")

    # (c) position, actual solid, desired dashed.
    idx = thin_indices(np.hstack([data.p, data.p_d]))
    for k in range(3):
        ax_p.plot(t[idx], data.p_d[idx, k], color=AXIS_COLORS[k], lw=2.4, ls="--", alpha=0.8)
        ax_p.plot(t[idx], data.p[idx, k], color=AXIS_COLORS[k], lw=1.1)
    handles = [Line2D([], [], color=AXIS_COLORS[k], lw=2, label=f"{name} ({d})")
               for k, (name, d) in enumerate(zip("xyz", ("east", "north", "up"), strict=True))]
    handles += [Line2D([], [], color="k", lw=1.1, label="actual"),
                Line2D([], [], color="k", lw=2.4, ls="--", alpha=0.8, label="desired")]
    _legend_right(ax_p, handles=handles)
    ax_p.set_title("(c) position, actual vs desired")
    _style(ax_p, "position (m)")

    # (d) position error norm and per axis.
    norm = _plot_position_error(ax_ep, data)
    _legend_right(ax_ep)
    ax_ep.set_title(f"(d) position error: {_stats_text(norm, 'm')}")
    _style(ax_ep, "error (m)", xlabel=True)

    for ax in (ax_att, ax_p, ax_ep):
        _mark_end(ax, data)
    fig.suptitle(f"Fig. 4 – attitude and position tracking: {data.title}")
    return _save(fig, path)


def is_case1_pd(data: RunData) -> bool:
    """A Case I run (by scenario or trajectory) flown with the PD controller: Fig. 5's run."""
    kind = data.scenario.get("trajectory", {}).get("kind")
    return data.controller == "pd" and CASE1 in (data.name, kind)


def fig5_figure(data: RunData, reference: RunData | None = None) -> Figure:
    """Fig. 5: Case I tracking errors of the PD controller, as Fig. 4 (b) and (d): (a) the
    attitude error angle (log scale), (b) the position error per axis and its norm. A
    `reference` run (the PID run of the same case) is drawn in grey for comparison."""
    fig = _new_figure(8.0)
    ax_att, ax_ep = fig.subplots(2, 1, sharex=True)
    ctrl = data.controller.upper()
    att = _plot_attitude_error(ax_att, data, label=f"∠(q_d* q), {ctrl}")
    values = [att]
    if reference is not None and len(reference.t):
        ref = reference.controller.upper()
        values.append(_plot_attitude_error(ax_att, reference, color="0.55", lw=0.9,
                                           label=f"∠(q_d* q), {ref}\n(Fig. 4), for comparison"))
    note = _log_axis(ax_att, np.concatenate(values))
    ax_att.set_title(f"(a) attitude error angle: {_stats_text(att, 'rad')}" + note)
    _style(ax_att, "error angle (rad)")

    norm = _plot_position_error(ax_ep, data)
    if reference is not None and len(reference.t):
        tr, nr = _thin(reference.t, np.linalg.norm(reference.p - reference.p_d, axis=1))
        ax_ep.plot(tr, nr, color="0.55", lw=1.2, ls="--",
                   label=f"|p − p_d|, {reference.controller.upper()}\n(Fig. 4), for comparison")
    ax_ep.set_title(f"(b) position error: {_stats_text(norm, 'm')}")
    _style(ax_ep, "error (m)", xlabel=True)
    for ax in (ax_att, ax_ep):
        _mark_end(ax, data, label=ax is ax_att)
        _legend_right(ax)
    fig.suptitle(f"Fig. 5 – Case I, tracking errors of the {ctrl} controller: {data.title}")
    return fig


def fig5_errors(data: RunData, path: Path, reference: RunData | None = None) -> Path:
    return _save(fig5_figure(data, reference), path)


def fig6_path(data: RunData, path: Path) -> Path:
    """Desired vs flown path in 3D, equal aspect."""
    fig = _new_figure(8.5)
    ax = fig.add_subplot(projection="3d")
    idx = thin_indices(np.hstack([data.p, data.p_d]), buckets=3000)
    p, p_d = data.p[idx], data.p_d[idx]
    if len(p_d) and np.ptp(p_d, axis=0).max() < 1e-9:
        ax.plot(*p_d[:1].T, ls="none", marker="*", ms=18, mfc="none", mew=1.5, color="k",
                label="desired (hover)", zorder=4)
    else:
        ax.plot(*p_d.T, color="k", lw=2.6, ls="--", label="desired", zorder=2)
    ax.plot(*p.T, color="tab:orange", lw=1.2, label="flown (truth)", zorder=3)
    if len(p):
        ax.plot(*p[:1].T, ls="none", marker="o", ms=8, color="tab:green", label="start")
        ax.plot(*p[-1:].T, ls="none", marker="s", ms=8,
                color="red" if data.diverged else "tab:blue",
                label="divergence" if data.diverged else "end")
        pts = np.vstack([p, p_d])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        span = np.maximum(hi - lo, 1e-3)
        pad = 0.05 * span.max()
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_zlim(lo[2] - pad, hi[2] + pad)
        ax.set_box_aspect(tuple(span + 2 * pad), zoom=0.9)  # equal scales, labels inside
    ax.set_xlabel("x east (m)", labelpad=8)
    ax.set_ylabel("y north (m)", labelpad=8)
    ax.set_zlabel("z up (m)", labelpad=8)
    ax.view_init(elev=25, azim=-60)
    err = np.linalg.norm(data.p - data.p_d, axis=1)
    _legend_right(ax, fontsize=10)
    ax.set_title(f"flown vs desired path (equal axis scales); max |p − p_d| = "
                 f"{np.max(err, initial=0):.3g} m", fontsize=11)
    fig.suptitle(f"Fig. 6 – 3D path: {data.title}")
    return _save(fig, path)


def disturbance_profile(terms: list[dict[str, Any]], t: np.ndarray) -> np.ndarray:
    """Body-frame disturbance (N, 3) at times t from a scenario's [[disturbance.*]] tables:
    pulse = amplitude on [start_s, end_s); sine = amplitude sin(omega t + phase) from start_s
    (to end_s when given), as sitl.disturbance applies them."""
    out = np.zeros((len(t), 3))
    for term in terms:
        amp = np.broadcast_to(np.asarray(term.get("amplitude", 0.0), dtype=float), (3,))
        on = (t >= float(term.get("start_s", 0.0))) & (t < float(term.get("end_s", math.inf)))
        if term.get("kind") == "pulse":
            k = on.astype(float)
        else:
            k = np.where(on, np.sin(float(term.get("omega_rad_s", 0.0)) * t
                                    + float(term.get("phase_rad", 0.0))), 0.0)
        out += k[:, None] * amp[None, :]
    return out


def _pulse_intervals(terms: list[dict[str, Any]]) -> list[tuple[float, float]]:
    return [(float(x.get("start_s", 0.0)), float(x["end_s"])) for x in terms
            if x.get("kind") == "pulse" and "end_s" in x]


def _plot_vec(ax, t: np.ndarray, v: np.ndarray, unit: str, sym: str, *, color: str = "k",
              ls: str = "-") -> None:
    """x, y, z components; identical components share one line (in `color`) and one legend
    entry."""
    idx = thin_indices(v)
    drawn: list[int] = []
    for k in range(3):
        same = [j for j in drawn if np.allclose(v[:, k], v[:, j])]
        if same:
            continue
        group = [n for j, n in enumerate("xyz") if np.allclose(v[:, k], v[:, j])]
        label = " = ".join(f"{sym}_{n}" for n in group) + f" ({unit})"
        ax.plot(t[idx], v[idx, k], color=AXIS_COLORS[k] if len(group) == 1 else color,
                lw=1.2, ls=ls, label=label)
        drawn.append(k)


def _profiles(data: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, force, torque) of the run's disturbances on a regular grid, so pulses' edges are
    exact, cut at the run's end."""
    tg = np.linspace(0.0, _end_time(data), 4001)
    return tg, disturbance_profile(data.force_terms, tg), \
        disturbance_profile(data.torque_terms, tg)


def _shade_pulses(axes: Sequence[Any], data: RunData, *, named: Any = None,
                  intervals_in_label: bool = True) -> None:
    """Pulse intervals shaded on every axis of `axes` (up to the run's end); legend entries
    only on `named`."""
    end = _end_time(data)
    shades = [(iv, "tab:orange", "force pulse") for iv in _pulse_intervals(data.force_terms)]
    shades += [(iv, "tab:cyan", "torque pulse") for iv in _pulse_intervals(data.torque_terms)]
    for ax in axes:
        for (a, b), color, label in shades:
            if a < end:
                text = f"{label}\n{a:g}–{b:g} s" if intervals_in_label else label
                ax.axvspan(a, min(b, end), color=color, alpha=0.22, lw=0, zorder=0,
                           label=text if ax is named else None)


def fig78_disturbance(data: RunData, path: Path) -> Path:
    """Position and attitude error under the disturbances, the disturbance applied."""
    fig = _new_figure(11.0)
    ax_p, ax_a, ax_f, ax_m = fig.subplots(4, 1, sharex=True,
                                          gridspec_kw={"height_ratios": [1.3, 1.3, 1, 1]})
    tg, force, torque = _profiles(data)

    _plot_position_error(ax_p, data)
    ax_p.set_title("(a) position error")
    _style(ax_p, "error (m)")

    _plot_attitude_error(ax_a, data)
    ax_a.set_title("(b) attitude error angle")
    _style(ax_a, "error angle (rad)")

    _plot_vec(ax_f, tg, force, "N", "F")
    ax_f.set_title("(c) applied force disturbance, body frame (FLU)")
    _style(ax_f, "force (N)")
    _plot_vec(ax_m, tg, torque, "N m", "τ")
    ax_m.set_title("(d) applied torque disturbance, body frame (FLU)")
    _style(ax_m, "torque (N m)", xlabel=True)

    _shade_pulses((ax_p, ax_a, ax_f, ax_m), data, named=ax_p)
    for ax in (ax_p, ax_a, ax_f, ax_m):
        _mark_end(ax, data, label=ax is ax_p)
        _legend_right(ax)
    kinds = sorted({x.get("kind", "?") for x in data.force_terms + data.torque_terms})
    fig.suptitle(f"Fig. 7/8 – response to {' + '.join(kinds)} disturbances: {data.title}")
    return _save(fig, path)


def fig7_8_figure(runs: Sequence[RunData | None], controller: str) -> Figure:
    """The paper's Fig. 7 (`controller` "pid") or Fig. 8 ("pd"): Case II, one row per run of
    `runs`, given in the order of CASE2_ROWS (impulse, sinusoidal, irregular; None: missing),
    columns attitude error angle (a-c), position error (d-f), applied disturbance (g-i).

    Each row has its own time axis, from 0 to its run's end; a diverged run ends at its
    divergence (`load_run` cuts it there), marked by a red dotted line and named in red in
    the row's titles. Pulse intervals are shaded across the row."""
    number = FIG78_BY_CONTROLLER[controller][0]
    rows = len(CASE2_ROWS)
    if len(runs) != rows:
        raise ValueError(f"Fig. {number} takes {rows} runs (None for a missing one)")
    fig = _new_figure(13.0)
    axes = fig.subplots(rows, 3, sharex="row")
    ylabels = ("error angle (rad)", "error (m)", "F (N), τ (N m)")
    diverged_any = False
    for r, ((scen, label), data) in enumerate(zip(CASE2_ROWS, runs, strict=True)):
        heads = [f"({'abcdefghi'[c * rows + r]}) {label}" for c in range(3)]
        if data is None:
            for ax, head in zip(axes[r], heads, strict=True):
                ax.set_title(f"{head}\nno run: {scen}_{controller} is missing", fontsize=9.5,
                             color="red")
                ax.text(0.5, 0.5, "no run", transform=ax.transAxes, ha="center",
                        va="center", color="red", fontsize=12)
                ax.set_xticks([])
                ax.set_yticks([])
            continue
        if data.name != scen:
            raise ValueError(f"Fig. {number}, row {r + 1} ({label}) takes a {scen} run, "
                             f"not {data.name}")
        ax_a, ax_p, ax_d = axes[r]
        att = _plot_attitude_error(ax_a, data)
        norm = _plot_position_error(ax_p, data)
        tg, force, torque = _profiles(data)
        _plot_vec(ax_d, tg, force, "N", "F", color="darkorange")
        _plot_vec(ax_d, tg, torque, "N m", "τ", color="teal", ls="--")
        ax_d.axhline(0.0, color="k", lw=0.6, alpha=0.5)
        _shade_pulses(axes[r], data, named=ax_a, intervals_in_label=False)
        pulses = _pulse_intervals(data.force_terms) + _pulse_intervals(data.torque_terms)
        texts = [f"attitude error: {_stats_text(att, 'rad')}",
                 f"position error: {_stats_text(norm, 'm')}",
                 "disturbance applied" + (
                     "" if pulses else f" from t = {_disturbance_start(data):g} s")
                 + " (body FLU)"]
        diverged = data.diverged and len(data.t) > 0
        diverged_any |= diverged
        for c, ax in enumerate(axes[r]):
            title = f"{heads[c]}\n{texts[c]}"
            if diverged:
                title += f"\nDIVERGED at t = {_end_time(data):.2f} s (the run ends there)"
            elif data.status not in ("completed", "unknown"):
                title += f"\n{data.status}"
            ax.set_title(title, fontsize=9.5, color="red" if diverged else "black")
            _mark_end(ax, data)
            _style(ax, ylabels[c], xlabel=r == rows - 1)
    handles: dict[str, Any] = {}
    for ax in axes.ravel():
        for handle, text in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(text, handle)
    if diverged_any:
        handles["divergence (the run ends there)"] = Line2D([], [], color="red", lw=1.6,
                                                            ls=":")
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="outside lower center", ncol=5,
                   fontsize=9)
    name = "the PID tracker (eq. 16)" if controller == "pid" else \
        "the PD controller (eq. 33)"
    fig.suptitle(f"Fig. {number} – Case II, robustness to disturbance: tracking errors of "
                 f"{name}")
    return fig


def _disturbance_start(data: RunData) -> float:
    starts = [float(x.get("start_s", 0.0)) for x in data.force_terms + data.torque_terms]
    return min(starts, default=0.0)


def fig7_8_case2(runs: Sequence[RunData | None], controller: str, path: Path) -> Path:
    """Fig. 7 (PID) or Fig. 8 (PD) from the three Case II runs, written to `path`."""
    return _save(fig7_8_figure(runs, controller), path)


# ---------------------------------------------------------------------------------------------
# The estimator (runs with a sensor profile)
# ---------------------------------------------------------------------------------------------

def estimation_errors(data: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t s, position error norm m, world velocity error norm m/s, attitude error angle rad)
    of the estimate (dq_onboard's state) against the truth at the same control steps, as
    gcs.metrics.estimation_error computes them; non-finite rows dropped, cut at divergence."""
    tc, truth, oc, onboard = read_run_logs(data.run_dir)
    truth = truth[np.isfinite(truth[:, tc.index("time_us")])]
    onboard = onboard[np.isfinite(onboard[:, oc.index("time_us")])]
    common_t, truth, onboard = join_logs(tc, truth, oc, onboard)
    q_e = log_columns(oc, onboard, "qw", "qx", "qy", "qz")
    dp = np.linalg.norm(log_columns(oc, onboard, "px", "py", "pz")
                        - log_columns(tc, truth, "px", "py", "pz"), axis=1)
    dv = np.linalg.norm(rotate_rows(q_e, log_columns(oc, onboard, "vbx", "vby", "vbz"))
                        - log_columns(tc, truth, "vx", "vy", "vz"), axis=1)
    da = attitude_error_rad(q_e, log_columns(tc, truth, "qw", "qx", "qy", "qz"))
    t = common_t * 1e-6
    keep = np.isfinite(dp) & np.isfinite(dv) & np.isfinite(da)
    if data.metrics.get("divergence_t_s") is not None:
        keep &= t <= float(data.metrics["divergence_t_s"]) + 1e-9
    return t[keep], dp[keep], dv[keep], da[keep]


def fig_estimation(data: RunData, path: Path) -> Path:
    """The estimate minus the truth: position error norm, velocity error norm (world frame)
    and attitude error angle over time."""
    t, dp, dv, da = estimation_errors(data)
    fig = _new_figure(7.5)
    axes = fig.subplots(3, 1, sharex=True)
    for ax, y, color, label, unit in (
            (axes[0], dp, "tab:blue", "|p̂ − p|", "m"),
            (axes[1], dv, "tab:green", "|v̂ − v|", "m/s"),
            (axes[2], da, "tab:purple", "∠(q* q̂)", "rad")):
        tt, yy = _thin(t, y)
        ax.plot(tt, yy, color=color, lw=1.0, label=label)
        ax.set_title(f"{label}: {_stats_text(y, unit)}", fontsize=10, loc="left")
        _style(ax, f"{label} ({unit})", xlabel=ax is axes[2])
        _legend_right(ax)
        _mark_end(ax, data)
    fig.suptitle(f"{data.title}: estimation error (estimate minus truth)")
    return _save(fig, path)


def _innovation_rows(data: RunData) -> tuple[tuple[str, ...], np.ndarray, tuple[str, ...],
                                             np.ndarray]:
    path = data.run_dir / ONBOARD_LOG
    ulog = open_ulog(path, ["estimator_innovations", "estimator_innovation_test_ratios"])
    ic, innov = topic_rows(ulog, "estimator_innovations")
    rc, ratio = topic_rows(ulog, "estimator_innovation_test_ratios")
    return ic, innov, rc, ratio


def fig_innovations(data: RunData, path: Path) -> Path | None:
    """The pose's innovations (EKF2's sign: prediction minus measurement; position NED, the
    attitude's about NED down as heading) and their test ratios (fused while <= 1)."""
    try:
        ic, innov, rc, ratio = _innovation_rows(data)
    except ULogError as exc:
        data.notes.append(f"innovations not drawn: {exc}")
        return None
    if not len(innov):
        data.notes.append("innovations not drawn: estimator_innovations is empty")
        return None
    fig = _new_figure(7.5)
    axes = fig.subplots(3, 1, sharex=True)
    ti = innov[:, ic.index("time_us")] * 1e-6
    pos = np.column_stack([innov[:, ic.index(c)] for c in ("ev_hpos[0]", "ev_hpos[1]",
                                                          "ev_vpos")])
    idx = thin_indices(pos)
    for k, name in enumerate("NED"):
        axes[0].plot(ti[idx], pos[idx, k], color=AXIS_COLORS[k], lw=0.9, label=f"{name}")
    axes[0].axhline(0.0, color="k", lw=0.6, alpha=0.5)
    axes[0].set_title("position innovation (prediction − pose), NED", fontsize=10, loc="left")
    _style(axes[0], "m")
    _legend_right(axes[0])
    hd = innov[:, ic.index("heading")]
    th, yh = _thin(ti, hd)
    axes[1].plot(th, yh, color="tab:purple", lw=0.9, label="heading")
    axes[1].axhline(0.0, color="k", lw=0.6, alpha=0.5)
    axes[1].set_title("attitude innovation about NED down (heading)", fontsize=10, loc="left")
    _style(axes[1], "rad")
    _legend_right(axes[1])
    tr = ratio[:, rc.index("time_us")] * 1e-6
    for col, color, label in (("ev_vpos", "tab:blue", "position"),
                              ("heading", "tab:purple", "attitude")):
        if len(ratio):
            tt, yy = _thin(tr, ratio[:, rc.index(col)])
            axes[2].plot(tt, yy, color=color, lw=0.9, label=label)
    axes[2].axhline(1.0, color="red", lw=1.0, ls="--", label="gate")
    axes[2].set_yscale("log")
    axes[2].set_title("test ratios innov² / (gate² S): refused above 1", fontsize=10,
                      loc="left")
    _style(axes[2], "ratio", xlabel=True)
    _legend_right(axes[2])
    for ax in axes:
        _mark_end(ax, data)
    fig.suptitle(f"{data.title}: the motion-capture pose's innovations")
    return _save(fig, path)


def estimation_figures(data: RunData, out: Path) -> list[Path]:
    """estimation.png and, when the log has them, innovations.png."""
    figures = [fig_estimation(data, out / FIG_ESTIMATION)]
    innov = fig_innovations(data, out / FIG_INNOVATIONS)
    if innov is not None:
        figures.append(innov)
    return figures


def _estimation_md(est: dict[str, Any], figures: list[Path]) -> list[str]:
    """report.md's section on the estimator: metrics.json's estimation_error and the links
    to its figures."""
    lines = ["", "## Estimation error", "",
             "The estimate the controller flew on (dq_onboard) against the truth (dq_truth) "
             "at the same control steps.", "",
             "| quantity | max | mean | RMSE |", "|---|---:|---:|---:|"]
    for key, label in (("position_m", "position (m)"), ("velocity_m_s", "velocity (m/s)"),
                       ("attitude_rad", "attitude (rad)")):
        row = est.get(key, {})
        if isinstance(row, dict):
            lines.append(f"| {label} | {_fmt(row.get('max'))} | {_fmt(row.get('mean'))} | "
                         f"{_fmt(row.get('rmse'))} |")
    lines.append("")
    for fig in figures:
        if fig.name in (FIG_ESTIMATION, FIG_INNOVATIONS):
            lines.append(f"- [{CAPTIONS[fig.name]}]({FIG_DIR}/{fig.name})")
    return lines


# ---------------------------------------------------------------------------------------------
# report.md
# ---------------------------------------------------------------------------------------------

def _fmt(x: Any) -> str:
    return f"{x:.4g}" if isinstance(x, int | float) else "—"


def _cut_short(data: RunData) -> bool:
    run = data.metrics.get("overrides", {}).get("duration_s")
    full = data.scenario.get("duration_s")
    return isinstance(run, int | float) and isinstance(full, int | float) and run < full


def _report_md(data: RunData, events: list[tuple[float, str]], figures: list[Path]) -> str:
    m = data.metrics
    lines = [f"# Run report: {data.name} [{data.controller.upper()}]", ""]
    scen = data.scenario
    traj = scen.get("trajectory", {}).get("kind", "?")
    lines += [
        f"- scenario: `{data.name}` (trajectory `{traj}`, scenario duration "
        f"{_fmt(scen.get('duration_s'))} s"
        + (f", run cut to {_fmt(m['overrides']['duration_s'])} s" if _cut_short(data)
           else "") + ")",
        f"- controller: {data.controller.upper()}",
        f"- status: **{data.status}**"
        + (f" ({m['status_reason']})" if m.get("status_reason") else "")
        + (f"; failsafe: {m['failsafe']}" if m.get("failsafe") else ""),
        f"- mission completed: {str(m.get('mission_completed', '?')).lower()}",
        f"- transport: {m.get('transport', '?')}, lockstep: "
        f"{str(m.get('lockstep', '?')).lower()}",
        f"- simulated time: {_fmt(m.get('sim_time_s'))} s"
        + (f" in {m['wall_time_s']:.1f} s wall time" if "wall_time_s" in m else ""),
    ]
    steps = m.get("fcu_step_us", {})
    if steps:
        lines.append(f"- FCU step time: p50 {_fmt(steps.get('p50'))} µs, "
                     f"p99 {_fmt(steps.get('p99'))} µs, max {_fmt(steps.get('max'))} µs")
    if data.force_terms or data.torque_terms:
        desc = [f"{kind} {x.get('kind')} {x.get('amplitude')}"
                + (f" on [{x.get('start_s', 0)}, {x['end_s']}) s" if "end_s" in x else "")
                + (f" ω = {x['omega_rad_s']:.4g} rad/s" if "omega_rad_s" in x else "")
                for kind, terms in (("force (N)", data.force_terms),
                                    ("torque (N m)", data.torque_terms)) for x in terms]
        lines.append("- disturbances (body frame): " + "; ".join(desc))
    lines.append("")
    run_events = m.get("events", [])
    if run_events:
        lines += ["## Events", "", "Everything the vehicle said, on the flight clock.", "",
                  "| t (s) | severity | event |", "|---:|---|---|"]
        lines += [f"| {e['t_s']:.3f} | {SEVERITY.get(e['severity'], e['severity'])} | "
                  f"{e['text']} |" for e in run_events]
        lines.append("")
    if data.diverged:
        lines += [f"**The run diverged at t = {_fmt(m.get('divergence_t_s'))} s** "
                  "(position error "
                  "beyond the scenario's limit or a non-finite state). The error statistics "
                  "below and the plots cover the run up to that instant only.", ""]
    lines += [f"_{n}_" for n in data.notes]
    if data.notes:
        lines.append("")

    paper = PAPER.get(data.name, {}).get(data.controller)
    lines += ["## Tracking errors (Table I)", "",
              "Position error norm |p − p_d| in m, attitude error angle of q_d* q in rad, "
              "over the run" + (" (up to the divergence)" if data.diverged else "") + ".", ""]
    if paper:
        lines += ["| statistic | position ours (m) | position paper (m) | attitude ours (rad) "
                  "| attitude paper (rad) |", "|---|---:|---:|---:|---:|"]
    else:
        lines += ["| statistic | position ours (m) | attitude ours (rad) |", "|---|---:|---:|"]
    pos, att = m.get("position_error_m", {}), m.get("attitude_error_rad", {})
    for k, stat in enumerate(STATS):
        label = "RMSE" if stat == "rmse" else stat
        if paper:
            lines.append(f"| {label} | {_fmt(pos.get(stat))} | {paper[0][k]:.4f} "
                         f"| {_fmt(att.get(stat))} | {paper[1][k]:.4f} |")
        else:
            lines.append(f"| {label} | {_fmt(pos.get(stat))} | {_fmt(att.get(stat))} |")
    lines.append("")
    if not paper:
        lines += [f"(The paper has no figures for scenario `{data.name}`.)", ""]
    elif _cut_short(data):
        lines += ["(The paper's figures are for the full scenario; this run was cut short.)",
                  ""]

    lines += ["## Z-Y-X Euler events of the desired attitude", ""]
    if events:
        shown = events[:30]
        lines.append(", ".join(f"{te:.3f} s ({kind})" for te, kind in shown)
                     + (f", … ({len(events)} in all)" if len(events) > len(shown) else ""))
        lines += ["", "A Z-Y-X (yaw-pitch-roll) description would be singular (gimbal lock) or "
                  "jump by 2π at these instants (red x in Fig. 4a); the dual-quaternion "
                  "tracker uses no Euler angles."]
    else:
        lines.append("None: a Z-Y-X description of the desired attitude stays regular and "
                     "continuous over this run.")
    est = m.get("estimation_error")
    if isinstance(est, dict):
        lines += _estimation_md(est, figures)
    lines += ["", "## Figures", ""]
    for fig in figures:
        rel = f"{FIG_DIR}/{fig.name}"
        cap = CAPTIONS.get(fig.name, fig.stem)
        lines.append(f"- [{cap}]({rel})")
    return "\n".join(lines).rstrip() + "\n"


CAPTIONS = {FIG3: "Fig. 3: tilt angles before and after unwrapping",
            FIG4: "Fig. 4: attitude and position tracking",
            FIG5: "Fig. 5: Case I, tracking errors of the PD controller",
            FIG6: "Fig. 6: 3D path, desired vs flown",
            FIG7: "Fig. 7: Case II, robustness to disturbance, PID (impulse, sinusoidal, "
                  "irregular)",
            FIG8: "Fig. 8: Case II, robustness to disturbance, PD (impulse, sinusoidal, "
                  "irregular)",
            FIG78: "Fig. 7/8: response to the disturbances",
            FIG_ESTIMATION: "Estimation error: the estimate minus the truth",
            FIG_INNOVATIONS: "The pose's innovations and test ratios",
            TABLE1_PNG: "Table I: RMSE, ours vs the paper"}


def write_run_report(data: RunData) -> list[Path]:
    """Write the figures and report.md of a loaded run folder; return their paths."""
    out = data.run_dir / FIG_DIR
    out.mkdir(parents=True, exist_ok=True)
    events = zyx_events(data.t, data.q_d) if len(data.t) > 1 else []
    figures = [fig3_tilt(data, out / FIG3), fig4_tracking(data, events, out / FIG4)]
    if is_case1_pd(data):
        figures.append(fig5_errors(data, out / FIG5))
    figures.append(fig6_path(data, out / FIG6))
    if data.disturbed:
        figures.append(fig78_disturbance(data, out / FIG78))
    if isinstance(data.metrics.get("estimation_error"), dict):
        figures += estimation_figures(data, out)
    report = data.run_dir / REPORT
    report.write_text(_report_md(data, events, figures))
    return [*figures, report]


def make_report(run_dir: Path) -> list[Path]:
    """Write run_dir/figures/*.png and run_dir/report.md; return their paths."""
    return write_run_report(load_run(Path(run_dir)))


# ---------------------------------------------------------------------------------------------
# A table1 folder: every run's report, Table I, Figs. 5, 7 and 8
# ---------------------------------------------------------------------------------------------

def is_table1_dir(path: Path) -> bool:
    """A folder written by `gcs table1 --out DIR` (it holds table1.json)."""
    return (Path(path) / TABLE1_JSON).is_file()


def table1_run_name(scenario: str, controller: str) -> str:
    """The run folder of a case and controller in a table1 folder (`gcs.table1.run_table1`)."""
    return f"{scenario}_{controller}"


@dataclass
class Table1Report:
    """What `make_table1_report` wrote, and what it could not report (one line each, naming
    the run folder)."""

    written: list[Path]
    problems: list[str]


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _events_summary(events: list[dict[str, Any]], limit: int = 4) -> str:
    """One line: how many events, by severity, and the notable ones in time order: every
    reaction (failsafe, crash, divergence), then warnings up to `limit` in all (the rest
    counted), else the first few."""
    if not events:
        return "none"
    counts: dict[str, int] = {}
    for e in events:
        level = e.get("severity")
        sev = SEVERITY.get(level, str(level)) if isinstance(level, int) else str(level)
        counts[sev] = counts.get(sev, 0) + 1
    reactions = [e for e in events if e.get("kind", "info") != "info"]
    warnings = [e for e in events if e.get("kind", "info") == "info"
                and isinstance(e.get("severity"), int) and e["severity"] <= 4]
    notable = reactions + warnings  # failsafes, crashes, divergence always; then warnings
    shown = (notable or events)[:max(limit, len(reactions))]
    shown.sort(key=lambda e: e.get("t_s") or 0.0)
    parts = [f"{e.get('text', '?')} ({_fmt(e.get('t_s'))} s)" for e in shown]
    rest = len(notable or events) - len(shown)
    return (f"{len(events)} ({', '.join(f'{n} {s}' for s, n in counts.items())}): "
            + "; ".join(parts) + (f"; … {rest} more" if rest > 0 else ""))


def _status_text(m: dict[str, Any]) -> str:
    text = f"**{m.get('status', 'unknown')}**"
    if m.get("status") == "diverged" and m.get("divergence_t_s") is not None:
        text += f" at {_fmt(m['divergence_t_s'])} s"
    return text


def _table1_md(table_dir: Path, table: dict[str, Any], runs: dict[tuple[str, str], RunData],
               run_figures: dict[tuple[str, str], list[Path]], figures: list[Path],
               problems: dict[tuple[str, str], str], other_problems: list[str],
               notes: list[str], from_json: list[tuple[str, str]]) -> str:
    n_runs = len(CASES) * len(CONTROLLERS)
    lines = [f"# Table I report: {table_dir.name}", "",
             f"{len(runs)} of {n_runs} runs reported"
             + (f"; {len(problems)} missing or unreadable: "
                + ", ".join(f"`{table1_run_name(*k)}`" for k in problems) if problems else "")
             + "."]
    cut = sorted({_fmt(d.metrics.get("overrides", {}).get("duration_s"))
                  for d in runs.values() if _cut_short(d)})
    if cut:
        lines += ["", f"Runs cut short (to {', '.join(cut)} s of the scenarios' durations): "
                  "the paper's figures are for the full scenarios."]
    lines += [""]
    if problems or other_problems:
        lines += ["## Missing or unreadable", ""]
        lines += [f"- {_md_cell(p)}" for p in [*problems.values(), *other_problems]]
        lines.append("")
    lines += [f"_{n}_" for n in notes]
    if notes:
        lines.append("")

    table_md = table_markdown(table).replace("# Table I", "## Table I", 1)
    lines += [table_md.rstrip(), ""]
    if from_json:
        lines += ["Rows of run folders that are missing or unreadable are those of "
                  f"{TABLE1_JSON}: " + ", ".join(f"`{table1_run_name(*k)}`" for k in from_json)
                  + ".", ""]
    if (table_dir / TABLE1_PNG).exists():
        lines += [f"![{CAPTIONS[TABLE1_PNG]}]({TABLE1_PNG})", ""]

    lines += ["## Runs", "", "Status, why, and what the vehicle said (events on the flight "
              "clock, from each run's metrics.json).", "",
              "| case | controller | run folder | status | why | events |",
              "|---|---|---|---|---|---|"]
    for label, scen in CASES:
        for ctrl in CONTROLLERS:
            key = (scen, ctrl)
            name = table1_run_name(scen, ctrl)
            if key in runs:
                m = runs[key].metrics
                why = str(m.get("status_reason") or "")
                if m.get("failsafe"):
                    why += f"; failsafe: {m['failsafe']}"
                lines.append(f"| {label} | {ctrl.upper()} | [{name}]({name}/{REPORT}) | "
                             f"{_status_text(m)} | {_md_cell(why) or '—'} | "
                             f"{_md_cell(_events_summary(list(m.get('events', []))))} |")
            else:
                lines.append(f"| {label} | {ctrl.upper()} | `{name}` | **not reported** | "
                             f"{_md_cell(problems.get(key, 'missing'))} | — |")
    lines.append("")

    lines += ["## Figures", ""]
    for fig in figures:
        lines.append(f"- [{CAPTIONS.get(fig.name, fig.stem)}]({fig.name})")
    drawn = {f.name for f in figures}
    for name, source in ((FIG5, f"`{table1_run_name(CASE1, 'pd')}`"),
                         *((f, f"any `case2_*_{c}`") for c, (_, f) in
                           FIG78_BY_CONTROLLER.items())):
        if name not in drawn:
            lines.append(f"- {CAPTIONS[name].split(':')[0]}: not drawn (no run: {source} "
                         "is missing or unreadable)")
    lines += ["", "Each run's own figures and report:", ""]
    for label, scen in CASES:
        for ctrl in CONTROLLERS:
            key = (scen, ctrl)
            if key not in run_figures:
                continue
            name = table1_run_name(scen, ctrl)
            links = [f"[{CAPTIONS.get(p.name, p.stem).split(':')[0]}]"
                     f"({name}/{FIG_DIR}/{p.name})" for p in run_figures[key]]
            lines.append(f"- `{name}` (Case {label}, {ctrl.upper()}): " + ", ".join(links)
                         + f", [report]({name}/{REPORT})")
    return "\n".join(lines).rstrip() + "\n"


def _valid_row(row: Any) -> bool:
    try:
        return all(isinstance(row[side][metric][stat], int | float)
                   for side in ("ours", "paper")
                   for metric in ("position_error_m", "attitude_error_rad") for stat in STATS) \
            and isinstance(row["status"], str) and isinstance(row["case"], str)
    except (KeyError, TypeError):
        return False


def make_table1_report(table_dir: Path, *,
                       warn: Callable[[str], None] | None = None) -> Table1Report:
    """Report a table1 folder: each run folder's figures and report.md (as `make_report`),
    and in `table_dir` table1.png, Figs. 5, 7 and 8 and report.md. A run folder that is
    missing or cannot be read is named in `problems` (and passed to `warn` as it is found)
    and the rest is reported all the same."""
    table_dir = Path(table_dir)
    written: list[Path] = []
    problems: dict[tuple[str, str], str] = {}
    other: list[str] = []
    notes: list[str] = []

    def note(problem: str) -> None:
        if warn is not None:
            warn(problem)

    try:
        saved = json.loads((table_dir / TABLE1_JSON).read_text())
        saved_rows = {(r["scenario"], r["controller"]): r for r in saved["rows"]
                      if _valid_row(r)}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        other.append(f"{table_dir / TABLE1_JSON}: not readable ({exc}); the table is made "
                     "from the run folders")
        note(other[-1])
        saved_rows = {}

    runs: dict[tuple[str, str], RunData] = {}
    run_figures: dict[tuple[str, str], list[Path]] = {}
    for _, scen in CASES:
        for ctrl in CONTROLLERS:
            run_dir = table_dir / table1_run_name(scen, ctrl)
            if not run_dir.is_dir():
                problems[(scen, ctrl)] = f"{run_dir}: run folder missing"
                note(problems[(scen, ctrl)])
                continue
            try:
                data = load_run(run_dir)
                row = table_json({(scen, ctrl): data.metrics})["rows"]
            except Exception as exc:  # any reading failure: name it, report the rest
                problems[(scen, ctrl)] = f"{run_dir}: could not be read " \
                                         f"({type(exc).__name__}: {exc})"
                note(problems[(scen, ctrl)])
                continue
            runs[(scen, ctrl)] = data
            paths = write_run_report(data)
            run_figures[(scen, ctrl)] = paths[:-1]
            written += paths
            old = saved_rows.get((scen, ctrl))
            if old is not None and row and (old.get("status") != row[0]["status"] or old.get(
                    "ours") != row[0]["ours"]):
                notes.append(f"{run_dir.name}: its metrics.json differs from the row of "
                             f"{TABLE1_JSON} (status {old.get('status')} there, "
                             f"{row[0]['status']} here); the table shows the run folder's.")

    # The table: the run folders' metrics, and table1.json's rows for the runs not read.
    from_json = [k for k in problems if k in saved_rows]
    table = table_json({k: d.metrics for k, d in runs.items()})
    order = {(scen, ctrl): i for i, (scen, ctrl) in
             enumerate((s, c) for _, s in CASES for c in CONTROLLERS)}
    table["rows"] = sorted([*table["rows"], *(saved_rows[k] for k in from_json)],
                           key=lambda r: order[(r["scenario"], r["controller"])])
    for r in table["rows"]:  # the plain allocation's figures (CA_LAG_COMP 0), as table1 ran them
        plain = saved_rows.get((r["scenario"], r["controller"]), {}).get("plain")
        if plain is not None:
            r.setdefault("plain", plain)
    figures = [table1_chart(table, table_dir / TABLE1_PNG)]

    pd1 = runs.get((CASE1, "pd"))
    if pd1 is not None:
        figures.append(fig5_errors(pd1, table_dir / FIG5, reference=runs.get((CASE1, "pid"))))
    for ctrl, (_, name) in FIG78_BY_CONTROLLER.items():
        row_runs = [runs.get((scen, ctrl)) for scen, _ in CASE2_ROWS]
        if any(r is not None for r in row_runs):
            figures.append(fig7_8_case2(row_runs, ctrl, table_dir / name))
    report = table_dir / REPORT
    report.write_text(_table1_md(table_dir, table, runs, run_figures, figures, problems,
                                 other, notes, from_json))
    written += [*figures, report]
    return Table1Report(written, [*problems.values(), *other])


# ---------------------------------------------------------------------------------------------
# Table I chart
# ---------------------------------------------------------------------------------------------

def table1_chart(table: dict[str, Any], out_png: Path) -> Path:
    """Grouped bars (log y) of position and attitude RMSE, ours vs the paper, PID and PD, for
    the four cases of `gcs.table1.table_json` output; diverged runs hatched and labelled."""
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    rows = {(r["scenario"], r["controller"]): r for r in table.get("rows", [])}
    fig = _new_figure(9.0)
    axes = fig.subplots(2, 1)
    colors = {"pid": "tab:blue", "pd": "tab:orange"}
    series = [(ctrl, src) for ctrl in CONTROLLERS for src in ("ours", "paper")]
    width = 0.2
    x = np.arange(len(CASES))
    for ax, metric, unit in ((axes[0], "position_error_m", "m"),
                             (axes[1], "attitude_error_rad", "rad")):
        values = []
        for s, (ctrl, src) in enumerate(series):
            offset = (s - (len(series) - 1) / 2) * width
            for c, (_, scen) in enumerate(CASES):
                row = rows.get((scen, ctrl))
                if src == "paper":
                    val = row["paper"][metric]["rmse"] if row else \
                        PAPER[scen][ctrl][0 if metric == "position_error_m" else 1][2]
                    status = "completed"
                elif row is None:
                    xpos = x[c] + offset
                    ax.text(xpos, 0.02, "n/a", transform=ax.get_xaxis_transform(),
                            ha="center", fontsize=8, color="0.4")
                    continue
                else:
                    val, status = row["ours"][metric]["rmse"], row["status"]
                    if status == "diverged" and row.get("divergence_t_s") is not None:
                        status = f"diverged\nat {row['divergence_t_s']:.3g} s"
                if not (isinstance(val, int | float) and math.isfinite(val) and val > 0):
                    continue
                values.append(val)
                diverged = status != "completed"
                ax.bar(x[c] + offset, val, width * 0.92, color=colors[ctrl],
                       alpha=1.0 if src == "ours" else 0.38,
                       edgecolor="red" if diverged else colors[ctrl],
                       hatch="///" if diverged else None, lw=1.6 if diverged else 0.8)
                text = f"{val:.2g}" + (f"\n{status}" if diverged else "")
                ax.annotate(text, (x[c] + offset, val), xytext=(0, 2),
                            textcoords="offset points", ha="center", va="bottom",
                            fontsize=7.5, color="red" if diverged else "0.15",
                            fontweight="bold" if diverged else "normal")
        ax.set_yscale("log")
        if values:
            ax.set_ylim(min(values) / 3.0, max(values) * 8.0)
        ax.set_xticks(x, [f"Case {label}" for label, _ in CASES])
        ax.set_xlim(-0.6, len(CASES) - 0.4)
        name = "position error RMSE" if unit == "m" else "attitude error RMSE"
        ax.set_ylabel(f"{name} ({unit})")
        ax.set_title(f"({'ab'[unit == 'rad']}) {name}, log scale")
        ax.grid(True, axis="y", which="major", alpha=0.3)
    handles = [Patch(facecolor=colors[ctrl], alpha=1.0 if src == "ours" else 0.38,
                     edgecolor=colors[ctrl], label=f"{ctrl.upper()} {src}")
               for ctrl, src in series]
    handles.append(Patch(facecolor="white", edgecolor="red", hatch="///",
                         label="ours, diverged\n(RMSE up to the divergence)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=5, fontsize=9.5)
    fig.suptitle("Table I – RMSE, ours vs the paper (PID and PD)")
    return _save(fig, out_png)
