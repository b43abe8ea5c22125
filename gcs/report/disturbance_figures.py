"""Case II figures: one run's response to its [[disturbance.*]] tables (fig7_8_disturbance.png)
and the paper's Figs. 7 (PID) and 8 (PD) from the three Case II runs of a controller."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from gcs.report.names import CASE2_ROWS, FIG78_BY_CONTROLLER
from gcs.report.plot import (
    end_time,
    legend_right,
    mark_end,
    new_figure,
    plot_attitude_error,
    plot_position_error,
    plot_vec,
    save_figure,
    stats_text,
    style_axis,
)
from gcs.report.rundata import RunData


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


def _profiles(data: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, force, torque) of the run's disturbances on a regular grid, so pulses' edges are
    exact, cut at the run's end."""
    tg = np.linspace(0.0, end_time(data), 4001)
    return tg, disturbance_profile(data.force_terms, tg), \
        disturbance_profile(data.torque_terms, tg)


def _shade_pulses(axes: Sequence[Any], data: RunData, *, named: Any = None,
                  intervals_in_label: bool = True) -> None:
    """Pulse intervals shaded on every axis of `axes` (up to the run's end); legend entries
    only on `named`."""
    end = end_time(data)
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
    fig = new_figure(11.0)
    ax_p, ax_a, ax_f, ax_m = fig.subplots(4, 1, sharex=True,
                                          gridspec_kw={"height_ratios": [1.3, 1.3, 1, 1]})
    tg, force, torque = _profiles(data)

    plot_position_error(ax_p, data)
    ax_p.set_title("(a) position error")
    style_axis(ax_p, "error (m)")

    plot_attitude_error(ax_a, data)
    ax_a.set_title("(b) attitude error angle")
    style_axis(ax_a, "error angle (rad)")

    plot_vec(ax_f, tg, force, "N", "F")
    ax_f.set_title("(c) applied force disturbance, body frame (FLU)")
    style_axis(ax_f, "force (N)")
    plot_vec(ax_m, tg, torque, "N m", "τ")
    ax_m.set_title("(d) applied torque disturbance, body frame (FLU)")
    style_axis(ax_m, "torque (N m)", xlabel=True)

    _shade_pulses((ax_p, ax_a, ax_f, ax_m), data, named=ax_p)
    for ax in (ax_p, ax_a, ax_f, ax_m):
        mark_end(ax, data, label=ax is ax_p)
        legend_right(ax)
    kinds = sorted({x.get("kind", "?") for x in data.force_terms + data.torque_terms})
    fig.suptitle(f"Fig. 7/8 – response to {' + '.join(kinds)} disturbances: {data.title}")
    return save_figure(fig, path)


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
    fig = new_figure(13.0)
    axes = fig.subplots(rows, 3, sharex="row")
    diverged_any = False
    for r, ((scen, label), data) in enumerate(zip(CASE2_ROWS, runs, strict=True)):
        heads = [f"({'abcdefghi'[c * rows + r]}) {label}" for c in range(3)]
        if data is None:
            _missing_row(axes[r], heads, f"{scen}_{controller}")
            continue
        if data.name != scen:
            raise ValueError(f"Fig. {number}, row {r + 1} ({label}) takes a {scen} run, "
                             f"not {data.name}")
        diverged_any |= _run_row(axes[r], heads, data, last=r == rows - 1)
    _figure_legend(fig, axes, diverged_any)
    name = "the PID tracker (eq. 16)" if controller == "pid" else \
        "the PD controller (eq. 33)"
    fig.suptitle(f"Fig. {number} – Case II, robustness to disturbance: tracking errors of "
                 f"{name}")
    return fig


def _missing_row(row: Sequence[Any], heads: list[str], run_name: str) -> None:
    """A row whose run is missing: its three axes say so, in red, without ticks."""
    for ax, head in zip(row, heads, strict=True):
        ax.set_title(f"{head}\nno run: {run_name} is missing", fontsize=9.5, color="red")
        ax.text(0.5, 0.5, "no run", transform=ax.transAxes, ha="center",
                va="center", color="red", fontsize=12)
        ax.set_xticks([])
        ax.set_yticks([])


def _run_row(row: Sequence[Any], heads: list[str], data: RunData, *, last: bool) -> bool:
    """A run's row: attitude error, position error and the applied disturbance, pulses
    shaded, its statistics and status in the titles (x labels on the `last` row); whether
    the run diverged."""
    ylabels = ("error angle (rad)", "error (m)", "F (N), τ (N m)")
    ax_a, ax_p, ax_d = row
    att = plot_attitude_error(ax_a, data)
    norm = plot_position_error(ax_p, data)
    tg, force, torque = _profiles(data)
    plot_vec(ax_d, tg, force, "N", "F", color="darkorange")
    plot_vec(ax_d, tg, torque, "N m", "τ", color="teal", ls="--")
    ax_d.axhline(0.0, color="k", lw=0.6, alpha=0.5)
    _shade_pulses(row, data, named=ax_a, intervals_in_label=False)
    pulses = _pulse_intervals(data.force_terms) + _pulse_intervals(data.torque_terms)
    texts = [f"attitude error: {stats_text(att, 'rad')}",
             f"position error: {stats_text(norm, 'm')}",
             "disturbance applied" + (
                 "" if pulses else f" from t = {_disturbance_start(data):g} s")
             + " (body FLU)"]
    diverged = data.diverged and len(data.t) > 0
    for c, ax in enumerate(row):
        title = f"{heads[c]}\n{texts[c]}"
        if diverged:
            title += f"\nDIVERGED at t = {end_time(data):.2f} s (the run ends there)"
        elif data.status not in ("completed", "unknown"):
            title += f"\n{data.status}"
        ax.set_title(title, fontsize=9.5, color="red" if diverged else "black")
        mark_end(ax, data)
        style_axis(ax, ylabels[c], xlabel=last)
    return diverged


def _figure_legend(fig: Figure, axes: Any, diverged_any: bool) -> None:
    """One legend below the figure: every entry of its axes once, and the divergence line
    where a run diverged."""
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


def _disturbance_start(data: RunData) -> float:
    starts = [float(x.get("start_s", 0.0)) for x in data.force_terms + data.torque_terms]
    return min(starts, default=0.0)


def fig7_8_case2(runs: Sequence[RunData | None], controller: str, path: Path) -> Path:
    """Fig. 7 (PID) or Fig. 8 (PD) from the three Case II runs, written to `path`."""
    return save_figure(fig7_8_figure(runs, controller), path)
