"""The paper's tracking figures of one run: Fig. 3 (tilt unwrapping), Fig. 4 (attitude and
position tracking), Fig. 5 (Case I, the PD controller's errors) and Fig. 6 (3D path)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from common.vehicle_constants import N_ROTORS
from gcs.report.names import CASE1
from gcs.report.plot import (
    AXIS_COLORS,
    QUAT_COLORS,
    ROTOR_COLORS,
    break_wraps,
    legend_right,
    log_axis,
    mark_end,
    new_figure,
    plot_attitude_error,
    plot_position_error,
    save_figure,
    stats_text,
    style_axis,
    thin,
    thin_indices,
)
from gcs.report.rundata import RunData


def fig3_tilt(data: RunData, path: Path) -> Path:
    """Tilt angles before (atan2 in [-pi, pi]) and after unwrapping, six rotors."""
    fig = new_figure(7.5)
    ax_raw, ax_cmd = fig.subplots(2, 1, sharex=True)
    t = data.t
    for i in range(N_ROTORS):
        tr, yr = thin(t, data.tilt_raw[:, i])
        ax_raw.plot(*break_wraps(tr, yr, math.pi), color=ROTOR_COLORS[i], lw=1.2,
                    label=f"rotor {i}")
        tc, yc = thin(t, data.tilt_cmd[:, i])
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
    style_axis(ax_raw, "tilt angle α (rad)")
    style_axis(ax_cmd, "tilt angle α (rad)", xlabel=True)
    for ax in (ax_raw, ax_cmd):
        mark_end(ax, data, label=ax is ax_raw)
    legend_right(ax_raw, title="log index")
    fig.suptitle(f"Fig. 3 – tilt angles of the six rotors: {data.title}")
    return save_figure(fig, path)


def fig4_tracking(data: RunData, events: list[tuple[float, str]], path: Path) -> Path:
    """(a) quaternion, (b) attitude error, (c) position, (d) position error."""
    fig = new_figure(13.0)
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
    end_line = mark_end(ax_q, data, label=True)
    legend_right(ax_q, handles=handles + ([end_line] if end_line else []))
    ax_q.set_ylim(-1.08, 1.08)
    opposite = bool(np.any(np.sum(data.q * data.q_d, axis=1) < 0.0))
    ax_q.set_title("(a) attitude quaternion q (world ← body), actual vs desired"
                   + ("; q and −q are the same attitude" if opposite else ""))
    style_axis(ax_q, "component (–)")

    # (b) attitude error angle, log scale.
    att = plot_attitude_error(ax_att, data)
    note = log_axis(ax_att, att)
    ax_att.set_title(f"(b) attitude error angle: {stats_text(att, 'rad')}" + note)
    legend_right(ax_att)
    style_axis(ax_att, "error angle (rad)")

    # (c) position, actual solid, desired dashed.
    idx = thin_indices(np.hstack([data.p, data.p_d]))
    for k in range(3):
        ax_p.plot(t[idx], data.p_d[idx, k], color=AXIS_COLORS[k], lw=2.4, ls="--", alpha=0.8)
        ax_p.plot(t[idx], data.p[idx, k], color=AXIS_COLORS[k], lw=1.1)
    handles = [Line2D([], [], color=AXIS_COLORS[k], lw=2, label=f"{name} ({d})")
               for k, (name, d) in enumerate(zip("xyz", ("east", "north", "up"), strict=True))]
    handles += [Line2D([], [], color="k", lw=1.1, label="actual"),
                Line2D([], [], color="k", lw=2.4, ls="--", alpha=0.8, label="desired")]
    legend_right(ax_p, handles=handles)
    ax_p.set_title("(c) position, actual vs desired")
    style_axis(ax_p, "position (m)")

    # (d) position error norm and per axis.
    norm = plot_position_error(ax_ep, data)
    legend_right(ax_ep)
    ax_ep.set_title(f"(d) position error: {stats_text(norm, 'm')}")
    style_axis(ax_ep, "error (m)", xlabel=True)

    for ax in (ax_att, ax_p, ax_ep):
        mark_end(ax, data)
    fig.suptitle(f"Fig. 4 – attitude and position tracking: {data.title}")
    return save_figure(fig, path)


def is_case1_pd(data: RunData) -> bool:
    """A Case I run (by scenario or trajectory) flown with the PD controller: Fig. 5's run."""
    kind = data.scenario.get("trajectory", {}).get("kind")
    return data.controller == "pd" and CASE1 in (data.name, kind)


def fig5_figure(data: RunData, reference: RunData | None = None) -> Figure:
    """Fig. 5: Case I tracking errors of the PD controller, as Fig. 4 (b) and (d): (a) the
    attitude error angle (log scale), (b) the position error per axis and its norm. A
    `reference` run (the PID run of the same case) is drawn in grey for comparison."""
    fig = new_figure(8.0)
    ax_att, ax_ep = fig.subplots(2, 1, sharex=True)
    ctrl = data.controller.upper()
    att = plot_attitude_error(ax_att, data, label=f"∠(q_d* q), {ctrl}")
    values = [att]
    if reference is not None and len(reference.t):
        ref = reference.controller.upper()
        values.append(plot_attitude_error(ax_att, reference, color="0.55", lw=0.9,
                                          label=f"∠(q_d* q), {ref}\n(Fig. 4), for comparison"))
    note = log_axis(ax_att, np.concatenate(values))
    ax_att.set_title(f"(a) attitude error angle: {stats_text(att, 'rad')}" + note)
    style_axis(ax_att, "error angle (rad)")

    norm = plot_position_error(ax_ep, data)
    if reference is not None and len(reference.t):
        tr, nr = thin(reference.t, np.linalg.norm(reference.p - reference.p_d, axis=1))
        ax_ep.plot(tr, nr, color="0.55", lw=1.2, ls="--",
                   label=f"|p − p_d|, {reference.controller.upper()}\n(Fig. 4), for comparison")
    ax_ep.set_title(f"(b) position error: {stats_text(norm, 'm')}")
    style_axis(ax_ep, "error (m)", xlabel=True)
    for ax in (ax_att, ax_ep):
        mark_end(ax, data, label=ax is ax_att)
        legend_right(ax)
    fig.suptitle(f"Fig. 5 – Case I, tracking errors of the {ctrl} controller: {data.title}")
    return fig


def fig5_errors(data: RunData, path: Path, reference: RunData | None = None) -> Path:
    return save_figure(fig5_figure(data, reference), path)


def fig6_path(data: RunData, path: Path) -> Path:
    """Desired vs flown path in 3D, equal aspect."""
    fig = new_figure(8.5)
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
    legend_right(ax, fontsize=10)
    ax.set_title(f"flown vs desired path (equal axis scales); max |p − p_d| = "
                 f"{np.max(err, initial=0):.3g} m", fontsize=11)
    fig.suptitle(f"Fig. 6 – 3D path: {data.title}")
    return save_figure(fig, path)
