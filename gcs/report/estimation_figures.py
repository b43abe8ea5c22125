"""The estimator's figures (runs with a sensor profile): the estimate minus the truth
(estimation.png) and the pose's innovations and test ratios (innovations.png)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.logs.ulog import ULogError, open_ulog, topic_rows
from gcs.report.names import FIG_ESTIMATION, FIG_INNOVATIONS
from gcs.report.plot import (
    AXIS_COLORS,
    legend_right,
    mark_end,
    new_figure,
    save_figure,
    stats_text,
    style_axis,
    thin,
    thin_indices,
)
from gcs.report.rundata import RunData, estimation_errors
from gcs.run.runio import ONBOARD_LOG


def fig_estimation(data: RunData, path: Path) -> Path:
    """The estimate minus the truth: position error norm, velocity error norm (world frame)
    and attitude error angle over time."""
    t, dp, dv, da = estimation_errors(data)
    fig = new_figure(7.5)
    axes = fig.subplots(3, 1, sharex=True)
    for ax, y, color, label, unit in (
            (axes[0], dp, "tab:blue", "|p̂ − p|", "m"),
            (axes[1], dv, "tab:green", "|v̂ − v|", "m/s"),
            (axes[2], da, "tab:purple", "∠(q* q̂)", "rad")):
        tt, yy = thin(t, y)
        ax.plot(tt, yy, color=color, lw=1.0, label=label)
        ax.set_title(f"{label}: {stats_text(y, unit)}", fontsize=10, loc="left")
        style_axis(ax, f"{label} ({unit})", xlabel=ax is axes[2])
        legend_right(ax)
        mark_end(ax, data)
    fig.suptitle(f"{data.title}: estimation error (estimate minus truth)")
    return save_figure(fig, path)


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
    fig = new_figure(7.5)
    axes = fig.subplots(3, 1, sharex=True)
    ti = innov[:, ic.index("time_us")] * 1e-6
    pos = np.column_stack([innov[:, ic.index(c)] for c in ("ev_hpos[0]", "ev_hpos[1]",
                                                          "ev_vpos")])
    idx = thin_indices(pos)
    for k, name in enumerate("NED"):
        axes[0].plot(ti[idx], pos[idx, k], color=AXIS_COLORS[k], lw=0.9, label=f"{name}")
    axes[0].axhline(0.0, color="k", lw=0.6, alpha=0.5)
    axes[0].set_title("position innovation (prediction − pose), NED", fontsize=10, loc="left")
    style_axis(axes[0], "m")
    legend_right(axes[0])
    hd = innov[:, ic.index("heading")]
    th, yh = thin(ti, hd)
    axes[1].plot(th, yh, color="tab:purple", lw=0.9, label="heading")
    axes[1].axhline(0.0, color="k", lw=0.6, alpha=0.5)
    axes[1].set_title("attitude innovation about NED down (heading)", fontsize=10, loc="left")
    style_axis(axes[1], "rad")
    legend_right(axes[1])
    tr = ratio[:, rc.index("time_us")] * 1e-6
    for col, color, label in (("ev_vpos", "tab:blue", "position"),
                              ("heading", "tab:purple", "attitude")):
        if len(ratio):
            tt, yy = thin(tr, ratio[:, rc.index(col)])
            axes[2].plot(tt, yy, color=color, lw=0.9, label=label)
    axes[2].axhline(1.0, color="red", lw=1.0, ls="--", label="gate")
    axes[2].set_yscale("log")
    axes[2].set_title("test ratios innov² / (gate² S): refused above 1", fontsize=10,
                      loc="left")
    style_axis(axes[2], "ratio", xlabel=True)
    legend_right(axes[2])
    for ax in axes:
        mark_end(ax, data)
    fig.suptitle(f"{data.title}: the motion-capture pose's innovations")
    return save_figure(fig, path)


def estimation_figures(data: RunData, out: Path) -> list[Path]:
    """estimation.png and, when the log has them, innovations.png."""
    figures = [fig_estimation(data, out / FIG_ESTIMATION)]
    innov = fig_innovations(data, out / FIG_INNOVATIONS)
    if innov is not None:
        figures.append(innov)
    return figures
