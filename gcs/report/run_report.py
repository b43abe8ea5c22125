"""One run folder's report: its figures under figures/ and report.md (status, events, the
Table I figures beside the paper's, the Z-Y-X Euler events, the estimation error)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from common.outcome import DIVERGENCE_ATTITUDE_HOLD_S, DIVERGENCE_ATTITUDE_RAD
from gcs.report.disturbance_figures import fig78_disturbance
from gcs.report.estimation_figures import estimation_figures
from gcs.report.euler import zyx_events
from gcs.report.names import (
    CAPTIONS,
    FIG3,
    FIG4,
    FIG5,
    FIG6,
    FIG78,
    FIG_DIR,
    FIG_ESTIMATION,
    FIG_INNOVATIONS,
    REPORT,
    SEVERITY,
)
from gcs.report.rundata import RunData, cut_short, load_run
from gcs.report.table1 import PAPER, STATS
from gcs.report.tracking_figures import (
    fig3_tilt,
    fig4_tracking,
    fig5_errors,
    fig6_path,
    is_case1_pd,
)


def fmt(x: Any) -> str:
    return f"{x:.4g}" if isinstance(x, int | float) else "—"


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
            lines.append(f"| {label} | {fmt(row.get('max'))} | {fmt(row.get('mean'))} | "
                         f"{fmt(row.get('rmse'))} |")
    lines.append("")
    for fig in figures:
        if fig.name in (FIG_ESTIMATION, FIG_INNOVATIONS):
            lines.append(f"- [{CAPTIONS[fig.name]}]({FIG_DIR}/{fig.name})")
    return lines


def _report_md(data: RunData, events: list[tuple[float, str]], figures: list[Path]) -> str:
    """report.md of a run: its summary, what it said, its errors beside the paper's, the
    desired attitude's Euler events, its estimation and its figures."""
    m = data.metrics
    lines = [*_summary_md(data), *_said_md(data), *_errors_md(data), *_euler_md(events)]
    est = m.get("estimation_error")
    if isinstance(est, dict):
        lines += _estimation_md(est, figures)
    lines += ["", "## Figures", ""]
    for fig in figures:
        rel = f"{FIG_DIR}/{fig.name}"
        cap = CAPTIONS.get(fig.name, fig.stem)
        lines.append(f"- [{cap}]({rel})")
    return "\n".join(lines).rstrip() + "\n"


def _summary_md(data: RunData) -> list[str]:
    """The report's title and summary list: scenario, controller, status, transport, time,
    step time, disturbances."""
    m = data.metrics
    lines = [f"# Run report: {data.name} [{data.controller.upper()}]", ""]
    scen = data.scenario
    traj = scen.get("trajectory", {}).get("kind", "?")
    lines += [
        f"- scenario: `{data.name}` (trajectory `{traj}`, scenario duration "
        f"{fmt(scen.get('duration_s'))} s"
        + (f", run cut to {fmt(m['overrides']['duration_s'])} s" if cut_short(data)
           else "") + ")",
        f"- controller: {data.controller.upper()}",
        f"- status: **{data.status}**"
        + (f" ({m['status_reason']})" if m.get("status_reason") else "")
        + (f"; failsafe: {m['failsafe']}" if m.get("failsafe") else ""),
        f"- mission completed: {str(m.get('mission_completed', '?')).lower()}",
        f"- transport: {m.get('transport', '?')}, lockstep: "
        f"{str(m.get('lockstep', '?')).lower()}",
        f"- simulated time: {fmt(m.get('sim_time_s'))} s"
        + (f" in {m['wall_time_s']:.1f} s wall time" if "wall_time_s" in m else ""),
    ]
    steps = m.get("fcu_step_us", {})
    if steps:
        lines.append(f"- FCU step time: p50 {fmt(steps.get('p50'))} µs, "
                     f"p99 {fmt(steps.get('p99'))} µs, max {fmt(steps.get('max'))} µs")
    if data.force_terms or data.torque_terms:
        desc = [f"{kind} {x.get('kind')} {x.get('amplitude')}"
                + (f" on [{x.get('start_s', 0)}, {x['end_s']}) s" if "end_s" in x else "")
                + (f" ω = {x['omega_rad_s']:.4g} rad/s" if "omega_rad_s" in x else "")
                for kind, terms in (("force (N)", data.force_terms),
                                    ("torque (N m)", data.torque_terms)) for x in terms]
        lines.append("- disturbances (body frame): " + "; ".join(desc))
    lines.append("")
    return lines


def _said_md(data: RunData) -> list[str]:
    """The events the vehicle said, the divergence and the run's notes."""
    m = data.metrics
    lines: list[str] = []
    run_events = m.get("events", [])
    if run_events:
        lines += ["## Events", "", "Everything the vehicle said, on the flight clock.", "",
                  "| t (s) | severity | event |", "|---:|---|---|"]
        lines += [f"| {e['t_s']:.3f} | {SEVERITY.get(e['severity'], e['severity'])} | "
                  f"{e['text']} |" for e in run_events]
        lines.append("")
    if data.diverged:
        limit_rad = data.scenario.get("divergence_attitude_rad", DIVERGENCE_ATTITUDE_RAD)
        hold_s = data.scenario.get("divergence_attitude_hold_s", DIVERGENCE_ATTITUDE_HOLD_S)
        lines += [f"**The run diverged at t = {fmt(m.get('divergence_t_s'))} s** "
                  "(position error beyond the scenario's limit, attitude error above "
                  f"{limit_rad:g} rad for {hold_s:g} s, or a "
                  "non-finite state). The error statistics below and the plots cover the run "
                  "up to that instant only.", ""]
    lines += [f"_{n}_" for n in data.notes]
    if data.notes:
        lines.append("")
    return lines


def _errors_md(data: RunData) -> list[str]:
    """The tracking errors' table (Table I), beside the paper's where it has the scenario."""
    m = data.metrics
    paper = PAPER.get(data.name, {}).get(data.controller)
    lines = ["## Tracking errors (Table I)", "",
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
            lines.append(f"| {label} | {fmt(pos.get(stat))} | {paper[0][k]:.4f} "
                         f"| {fmt(att.get(stat))} | {paper[1][k]:.4f} |")
        else:
            lines.append(f"| {label} | {fmt(pos.get(stat))} | {fmt(att.get(stat))} |")
    lines.append("")
    if not paper:
        lines += [f"(The paper has no figures for scenario `{data.name}`.)", ""]
    elif cut_short(data):
        lines += ["(The paper's figures are for the full scenario; this run was cut short.)",
                  ""]
    return lines


def _euler_md(events: list[tuple[float, str]]) -> list[str]:
    """Where a Z-Y-X description of the desired attitude is singular or jumps."""
    lines = ["## Z-Y-X Euler events of the desired attitude", ""]
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
    return lines


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
