"""Run reports: the paper's figures and a one-page report.md for a run folder.

`make_report(run_dir)` reads metrics.json, scenario.toml and the two binary logs written by
`gcs run ... --out DIR` (in-process or through processes) and writes `DIR/figures/*.png`
and `DIR/report.md`:

- fig3_tilt_unwrapping.png: tilt angles before (atan2, jumping at +-pi) and after unwrapping.
- fig4_tracking.png: (a) quaternion actual vs desired with the instants where a Z-Y-X Euler
  description of the desired attitude is singular or jumps, (b) attitude error angle,
  (c) position actual vs desired, (d) position error norm and per-axis errors.
- fig6_path_3d.png: desired vs flown path in 3D.
- fig7_8_disturbance.png (runs with [[disturbance.*]] tables only): position and attitude
  error with the pulse intervals shaded and the applied body-frame force and torque.

`table1_chart(table, png)` draws `gcs.table1.table_json` output as grouped bars.

Figures are drawn on matplotlib's Agg canvas directly (never pyplot, never a screen); long
series are thinned to every bucket's first, minimum and maximum sample, so peaks survive.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from common.binlog import read_log
from gcs.euler import zyx_events
from gcs.metrics import attitude_error_rad, join_logs, log_columns
from gcs.runio import ONBOARD_LOG, TRUTH_LOG, check_run_dir
from gcs.table1 import CASES, CONTROLLERS, PAPER, STATS

FIG_DIR = "figures"
FIG3 = "fig3_tilt_unwrapping.png"
FIG4 = "fig4_tracking.png"
FIG6 = "fig6_path_3d.png"
FIG78 = "fig7_8_disturbance.png"
REPORT = "report.md"

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
    tc, truth = read_log(run_dir / TRUTH_LOG)
    oc, onboard = read_log(run_dir / ONBOARD_LOG)
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
    att = attitude_error_rad(data.q, data.q_d)
    ta, ya = _thin(t, att)
    ax_att.plot(ta, ya, color="tab:purple", lw=1.1, label="∠(q_d* q)")
    note = _log_axis(ax_att, att)
    ax_att.set_title(f"(b) attitude error angle: max {np.max(att, initial=0):.3g} rad, "
                     f"RMSE {math.sqrt(float(np.mean(att ** 2))) if att.size else 0:.3g} rad"
                     + note)
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
    err = data.p - data.p_d
    norm = np.linalg.norm(err, axis=1)
    idx = thin_indices(np.column_stack([norm, err]))
    for k, name in enumerate("xyz"):
        ax_ep.plot(t[idx], err[idx, k], color=AXIS_COLORS[k], lw=0.9,
                   label=f"e_{name} = {name} − {name}_d")
    ax_ep.plot(t[idx], norm[idx], color="k", lw=1.4, label="|p − p_d|")
    ax_ep.axhline(0.0, color="k", lw=0.6, alpha=0.5)
    _legend_right(ax_ep)
    ax_ep.set_title(f"(d) position error: max {np.max(norm, initial=0):.3g} m, "
                    f"RMSE {math.sqrt(float(np.mean(norm ** 2))) if norm.size else 0:.3g} m")
    _style(ax_ep, "error (m)", xlabel=True)

    for ax in (ax_att, ax_p, ax_ep):
        _mark_end(ax, data)
    fig.suptitle(f"Fig. 4 – attitude and position tracking: {data.title}")
    return _save(fig, path)


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


def _plot_vec(ax, t: np.ndarray, v: np.ndarray, unit: str, sym: str) -> None:
    """x, y, z components; identical components share one line and one legend entry."""
    idx = thin_indices(v)
    drawn: list[int] = []
    for k in range(3):
        same = [j for j in drawn if np.allclose(v[:, k], v[:, j])]
        if same:
            continue
        group = [n for j, n in enumerate("xyz") if np.allclose(v[:, k], v[:, j])]
        label = " = ".join(f"{sym}_{n}" for n in group) + f" ({unit})"
        ax.plot(t[idx], v[idx, k], color=AXIS_COLORS[k] if len(group) == 1 else "k",
                lw=1.2, label=label)
        drawn.append(k)


def fig78_disturbance(data: RunData, path: Path) -> Path:
    """Position and attitude error under the disturbances, the disturbance applied."""
    fig = _new_figure(11.0)
    ax_p, ax_a, ax_f, ax_m = fig.subplots(4, 1, sharex=True,
                                          gridspec_kw={"height_ratios": [1.3, 1.3, 1, 1]})
    t = data.t
    end = _end_time(data)
    # Profiles on a regular grid so pulses' edges are exact, cut at the run's end.
    tg = np.linspace(0.0, end, 4001)
    force = disturbance_profile(data.force_terms, tg)
    torque = disturbance_profile(data.torque_terms, tg)

    err = data.p - data.p_d
    norm = np.linalg.norm(err, axis=1)
    idx = thin_indices(np.column_stack([norm, err]))
    for k, name in enumerate("xyz"):
        ax_p.plot(t[idx], err[idx, k], color=AXIS_COLORS[k], lw=0.9, label=f"e_{name}")
    ax_p.plot(t[idx], norm[idx], color="k", lw=1.4, label="|p − p_d|")
    ax_p.axhline(0.0, color="k", lw=0.6, alpha=0.5)
    ax_p.set_title("(a) position error")
    _style(ax_p, "error (m)")

    att = attitude_error_rad(data.q, data.q_d)
    ta, ya = _thin(t, att)
    ax_a.plot(ta, ya, color="tab:purple", lw=1.1, label="∠(q_d* q)")
    ax_a.set_title("(b) attitude error angle")
    _style(ax_a, "error angle (rad)")

    _plot_vec(ax_f, tg, force, "N", "F")
    ax_f.set_title("(c) applied force disturbance, body frame (FLU)")
    _style(ax_f, "force (N)")
    _plot_vec(ax_m, tg, torque, "N m", "τ")
    ax_m.set_title("(d) applied torque disturbance, body frame (FLU)")
    _style(ax_m, "torque (N m)", xlabel=True)

    shades = [(iv, "tab:orange", "force pulse") for iv in _pulse_intervals(data.force_terms)]
    shades += [(iv, "tab:cyan", "torque pulse") for iv in _pulse_intervals(data.torque_terms)]
    for ax in (ax_p, ax_a, ax_f, ax_m):
        for (a, b), color, label in shades:
            if a < end:  # pulse intervals shaded on every panel, named once
                ax.axvspan(a, min(b, end), color=color, alpha=0.22, lw=0, zorder=0,
                           label=f"{label}\n{a:g}–{b:g} s" if ax is ax_p else None)
        _mark_end(ax, data, label=ax is ax_p)
        _legend_right(ax)
    kinds = sorted({x.get("kind", "?") for x in data.force_terms + data.torque_terms})
    fig.suptitle(f"Fig. 7/8 – response to {' + '.join(kinds)} disturbances: {data.title}")
    return _save(fig, path)


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
    lines += ["", "## Figures", ""]
    captions = {FIG3: "Fig. 3: tilt angles before and after unwrapping",
                FIG4: "Fig. 4: attitude and position tracking",
                FIG6: "Fig. 6: 3D path, desired vs flown",
                FIG78: "Fig. 7/8: response to the disturbances"}
    for fig in figures:
        rel = f"{FIG_DIR}/{fig.name}"
        cap = captions.get(fig.name, fig.stem)
        lines.append(f"- [{cap}]({rel})")
    return "\n".join(lines).rstrip() + "\n"


def make_report(run_dir: Path) -> list[Path]:
    """Write run_dir/figures/*.png and run_dir/report.md; return their paths."""
    run_dir = Path(run_dir)
    data = load_run(run_dir)
    out = run_dir / FIG_DIR
    out.mkdir(parents=True, exist_ok=True)
    events = zyx_events(data.t, data.q_d) if len(data.t) > 1 else []
    figures = [fig3_tilt(data, out / FIG3), fig4_tracking(data, events, out / FIG4),
               fig6_path(data, out / FIG6)]
    if data.disturbed:
        figures.append(fig78_disturbance(data, out / FIG78))
    report = run_dir / REPORT
    report.write_text(_report_md(data, events, figures))
    return [*figures, report]


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
