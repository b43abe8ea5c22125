"""Plot helpers shared by the report's figures: matplotlib's Agg canvas (never pyplot, never
a screen), the thinning of long series (every bucket's first, minimum and maximum sample, so
peaks survive), axis styling and the attitude and position error traces."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import rc_context
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from gcs.report.metrics import attitude_error_rad
from gcs.report.rundata import RunData

DPI = 150
WIDTH_IN = 11.0  # 1650 px at DPI
PNG_COMPRESS_LEVEL = 3  # zlib 1-3: its fast deflate; 4-9 (Pillow's default 6) its slow one
BUCKETS = 2000  # thinning: at most ~2000 buckets per series (about one per pixel column)
AXIS_COLORS = ("tab:red", "tab:green", "tab:blue")  # x, y, z
QUAT_COLORS = ("tab:gray", "tab:red", "tab:green", "tab:blue")  # w, x, y, z
ROTOR_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


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


def thin(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = thin_indices(y)
    return t[idx], y[idx]


def break_wraps(t: np.ndarray, y: np.ndarray,
                threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Insert a gap wherever y jumps by more than threshold (no vertical connecting line)."""
    j = np.flatnonzero(np.abs(np.diff(y)) > threshold) + 1
    return np.insert(t.astype(float), j, np.nan), np.insert(y.astype(float), j, np.nan)


def new_figure(height_in: float) -> Figure:
    # Constrained layout: a tight layout that also makes room for legends outside the axes.
    fig = Figure(figsize=(WIDTH_IN, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: Path) -> Path:
    """The figure as a PNG at DPI, drawn once. Its constrained layout is computed here and
    the engine then taken off (`Figure.savefig` would otherwise draw a figure that has a
    layout engine once without output, to lay it out, then again to render it; the pixels
    are the same). zlib's level PNG_COMPRESS_LEVEL, not Pillow's default 6: the same
    pixels, compressed in about two thirds of the time, in a file about an eighth larger."""
    engine = fig.get_layout_engine()
    if engine is not None:
        if fig.axes:  # as `Figure.draw` lays a figure out: one it cannot is drawn as it is
            with contextlib.suppress(ValueError):
                engine.execute(fig)
        with rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)  # no engine (`"none"` would leave a placeholder)
    fig.savefig(path, dpi=DPI, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return path


def mark_end(ax: Axes, data: RunData, *, label: bool = False) -> Line2D | None:
    """Time axis from 0 to the run's end; a diverged run's end drawn as a red dotted line
    (named in the legend when `label`), which is returned."""
    end = end_time(data)
    if not (data.diverged and len(data.t)):
        ax.set_xlim(0.0, end)
        return None
    ax.set_xlim(0.0, end * 1.02)
    line: Line2D = ax.axvline(end, color="red", lw=1.6, ls=":", zorder=1,
                              label=f"diverged\n(t = {end:.2f} s)" if label else None)
    return line


def legend_right(ax: Axes, **kwargs: Any) -> None:
    """Legend outside the axes on the right, so it never hides data."""
    kwargs.setdefault("fontsize", 9)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
              framealpha=0.9, **kwargs)


def style_axis(ax: Axes, ylabel: str, *, xlabel: bool = False) -> None:
    ax.set_ylabel(ylabel)
    if xlabel:
        ax.set_xlabel("time t (s)")
    ax.grid(True, alpha=0.3)


def end_time(data: RunData) -> float:
    return float(data.t[-1]) if len(data.t) and data.t[-1] > 0 else 1.0


def _rmse(x: np.ndarray) -> float:
    return math.sqrt(float(np.mean(x ** 2))) if x.size else 0.0


def stats_text(x: np.ndarray, unit: str) -> str:
    return f"max {np.max(x, initial=0):.3g} {unit}, RMSE {_rmse(x):.3g} {unit}"


def plot_attitude_error(ax: Axes, data: RunData, *, color: str = "tab:purple",
                        lw: float = 1.1, label: str = "∠(q_d* q)") -> np.ndarray:
    """The attitude error angle of q_d* q over time (thinned); returns the whole series."""
    att = attitude_error_rad(data.q, data.q_d)
    ta, ya = thin(data.t, att)
    ax.plot(ta, ya, color=color, lw=lw, label=label)
    return att


def plot_position_error(ax: Axes, data: RunData) -> np.ndarray:
    """Per-axis position errors and their norm over time (thinned); returns the norm."""
    err = data.p - data.p_d
    norm: np.ndarray = np.linalg.norm(err, axis=1)
    idx = thin_indices(np.column_stack([norm, err]))
    t = data.t
    for k, name in enumerate("xyz"):
        ax.plot(t[idx], err[idx, k], color=AXIS_COLORS[k], lw=0.9,
                label=f"e_{name} = {name} − {name}_d")
    ax.plot(t[idx], norm[idx], color="k", lw=1.4, label="|p − p_d|")
    ax.axhline(0.0, color="k", lw=0.6, alpha=0.5)
    return norm


def log_axis(ax: Axes, values: np.ndarray, decades: float = 4.0) -> str:
    """Log y axis over the top `decades` of the data; returns a note when values fall below."""
    pos = values[values > 0]
    if pos.size == 0:
        return ""
    ax.set_yscale("log", nonpositive="mask")
    top = float(pos.max())
    floor = 10.0 ** math.floor(math.log10(max(float(pos.min()), top * 10.0 ** -decades)))
    ax.set_ylim(floor, 10.0 ** math.ceil(math.log10(top) + 1e-9))
    return f"; axis floor {floor:.0e} rad" if pos.min() < floor else ""


def plot_vec(ax: Axes, t: np.ndarray, v: np.ndarray, unit: str, sym: str, *,
             color: str = "k", ls: str = "-") -> None:
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
