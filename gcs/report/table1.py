"""The paper's Table I beside our figures: Case I and three Case II variants, PID and PD;
the table's rows from the runs' metrics (`table_json`) and as markdown (`table_markdown`).
gcs.run.table1_run flies the runs.

Each case is flown twice by default (`lag_comp="both"`): with the FCU's default
allocation, which leads its commands for the rotor lag and the tilt rate limit (CA_LAG_COMP
1, the run folders `<scenario>_<controller>`), and with the paper's plain allocation of
eqs. (28-29) (CA_LAG_COMP 0, the run folders `plain/<scenario>_<controller>`); table1.json's
rows carry the second as "plain" and table1.md shows it in columns of its own.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gcs.report.run_metrics import RunMetrics

CASES = (
    ("I", "case1_figure8"),
    ("II (impulse)", "case2_impulse"),
    ("II (regular)", "case2_sine"),
    ("II (irregular)", "case2_irregular"),
)
CONTROLLERS = ("pid", "pd")
STATS = ("max", "mean", "rmse")

# Table I of the paper: PAPER[case][controller] = (position (max, mean, rmse),
# attitude (max, mean, rmse)). Printed as is, including its inconsistencies (PD Case I:
# attitude mean and RMSE above the maximum).
PAPER: dict[str, dict[str, tuple[tuple[float, ...], tuple[float, ...]]]] = {
    "case1_figure8": {"pid": ((0.0694, 0.0102, 0.0166), (0.0050, 0.0008, 0.0015)),
                      "pd": ((0.1683, 0.0532, 0.0839), (0.0138, 0.0466, 0.0656))},
    "case2_impulse": {"pid": ((0.1686, 0.0129, 0.0358), (2.1360, 0.1164, 0.3431)),
                      "pd": ((0.2135, 0.0123, 0.0413), (3.1120, 0.1002, 0.3823))},
    "case2_sine": {"pid": ((0.0525, 0.0062, 0.0082), (0.2229, 0.0641, 0.0799)),
                   "pd": ((0.0743, 0.0183, 0.0168), (0.6345, 0.2278, 0.2625))},
    "case2_irregular": {"pid": ((0.0098, 0.0000, 0.0049), (0.0235, 0.0001, 0.0106)),
                        "pd": ((0.0722, 0.0005, 0.0316), (0.2792, 0.0011, 0.0826))},
}


def paper_figures(scenario: str, controller: str) -> dict[str, dict[str, float]]:
    pos, att = PAPER[scenario][controller]
    return {"position_error_m": dict(zip(STATS, pos, strict=True)),
            "attitude_error_rad": dict(zip(STATS, att, strict=True))}


def table_json(results: Mapping[tuple[str, str], RunMetrics],
               plain: Mapping[tuple[str, str], RunMetrics] | None = None) -> dict[str, Any]:
    """Rows of Table I from the runs' metrics; `plain` (the runs with CA_LAG_COMP 0), when
    given, adds each row's "plain" figures and status."""
    rows = []
    for label, scen in CASES:
        for ctrl in CONTROLLERS:
            m = results.get((scen, ctrl))
            if m is None:
                continue
            row = {
                "case": label, "scenario": scen, "controller": ctrl,
                "status": m["status"], "sim_time_s": m["sim_time_s"],
                "divergence_t_s": m.get("divergence_t_s"),
                "ours": {"position_error_m": m["position_error_m"],
                         "attitude_error_rad": m["attitude_error_rad"]},
                "paper": paper_figures(scen, ctrl),
            }
            p = (plain or {}).get((scen, ctrl))
            if p is not None:
                row["plain"] = {"status": p["status"], "sim_time_s": p["sim_time_s"],
                                "divergence_t_s": p.get("divergence_t_s"),
                                "position_error_m": p["position_error_m"],
                                "attitude_error_rad": p["attitude_error_rad"]}
            rows.append(row)
    return {"rows": rows}


def table_markdown(table: dict[str, Any]) -> str:
    """Table I as markdown; with columns of the plain allocation (CA_LAG_COMP 0) when some
    row has them ("—" where a row has none)."""
    plain = any("plain" in row for row in table["rows"])
    lines = [
        "# Table I: ours beside the paper",
        "",
        "Position error norm in m, attitude error angle in rad; max / mean / RMSE over the run.",
    ]
    if table.get("sensors", "truth") != "truth":
        lines += ["", f"Sensor profile: {table['sensors']} (the FCU flies on its estimator)."]
    if plain:
        lines += [
            "",
            "ours: the FCU's allocation, led for the rotor lag and the tilt rate limit "
            "(CA_LAG_COMP 1, the default); plain: the paper's allocation, eqs. (28-29) "
            "(CA_LAG_COMP 0).",
            "",
            "| case | controller | statistic | position (ours) | position (plain) "
            "| position (paper) | attitude (ours) | attitude (plain) | attitude (paper) |",
            "|---|---|---|---:|---:|---:|---:|---:|---:|",
        ]
    else:
        lines += [
            "",
            "| case | controller | statistic | position (ours) | position (paper) "
            "| attitude (ours) | attitude (paper) |",
            "|---|---|---|---:|---:|---:|---:|",
        ]
    for row in table["rows"]:
        status = "" if row["status"] == "completed" else f" ({row['status']})"
        p = row.get("plain")
        if p is not None and p["status"] != "completed":
            status += f" (plain: {p['status']})"
        for stat in STATS:
            ours, paper = row["ours"], row["paper"]
            pos = f"| {ours['position_error_m'][stat]:.4g} "
            att = f"| {ours['attitude_error_rad'][stat]:.4g} "
            if plain:
                pos += f"| {p['position_error_m'][stat]:.4g} " if p is not None else "| — "
                att += f"| {p['attitude_error_rad'][stat]:.4g} " if p is not None else "| — "
            lines.append(
                f"| {row['case']} | {row['controller'].upper()}{status} | {stat} "
                f"{pos}| {paper['position_error_m'][stat]:.4f} "
                f"{att}| {paper['attitude_error_rad'][stat]:.4f} |")
    return "\n".join(lines) + "\n"
