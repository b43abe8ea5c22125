"""The paper's Table I beside our figures: Case I and three Case II variants, PID and PD."""

from __future__ import annotations

import json
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

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


def table_json(results: dict[tuple[str, str], dict[str, Any]]) -> dict[str, Any]:
    rows = []
    for label, scen in CASES:
        for ctrl in CONTROLLERS:
            m = results.get((scen, ctrl))
            if m is None:
                continue
            rows.append({
                "case": label, "scenario": scen, "controller": ctrl,
                "status": m["status"], "sim_time_s": m["sim_time_s"],
                "divergence_t_s": m.get("divergence_t_s"),
                "ours": {"position_error_m": m["position_error_m"],
                         "attitude_error_rad": m["attitude_error_rad"]},
                "paper": paper_figures(scen, ctrl),
            })
    return {"rows": rows}


def table_markdown(table: dict[str, Any]) -> str:
    lines = [
        "# Table I: ours beside the paper",
        "",
        "Position error norm in m, attitude error angle in rad; max / mean / RMSE over the run.",
        "",
        "| case | controller | statistic | position (ours) | position (paper) "
        "| attitude (ours) | attitude (paper) |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for row in table["rows"]:
        status = "" if row["status"] == "completed" else f" ({row['status']})"
        for stat in STATS:
            ours, paper = row["ours"], row["paper"]
            lines.append(
                f"| {row['case']} | {row['controller'].upper()}{status} | {stat} "
                f"| {ours['position_error_m'][stat]:.4g} | {paper['position_error_m'][stat]:.4f} "
                f"| {ours['attitude_error_rad'][stat]:.4g} "
                f"| {paper['attitude_error_rad'][stat]:.4f} |")
    return "\n".join(lines) + "\n"


def _run_one(job: tuple[str, str, bool, float | None, str, bool]) -> dict[str, Any]:
    from common.config import load_scenario
    from gcs.inprocess import apply_overrides, run_scenario
    from gcs.process_run import run_processes
    from gcs.runio import prepare_run_dir, write_run

    path, ctrl, ideal, duration, out, in_process = job
    prepare_run_dir(Path(out), force=True)  # table1 owns its run folders
    scenario = apply_overrides(load_scenario(path), controller=ctrl,
                               ideal_actuators=ideal or None, duration_s=duration)
    if not in_process:
        return run_processes(scenario, Path(out))
    result = run_scenario(scenario)
    write_run(Path(out), scenario, result)
    return result.metrics


def run_table1(config_dir: Path, out_dir: Path, *, ideal: bool = False,
               duration_s: float | None = None, workers: int | None = None,
               in_process: bool = False, progress=None) -> dict[str, Any]:
    """Run the 8 cases in parallel (through sitl + fcu processes unless `in_process`);
    write table1.md and table1.json."""
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = [(scen, ctrl) for _, scen in CASES for ctrl in CONTROLLERS]
    jobs = [(str(config_dir / f"{scen}.toml"), ctrl, ideal, duration_s,
             str(out_dir / f"{scen}_{ctrl}"), in_process) for scen, ctrl in keys]
    results: dict[tuple[str, str], dict[str, Any]] = {}
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_run_one, job): key for job, key in zip(jobs, keys, strict=True)}
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            if progress is not None:
                scen, ctrl = futures[future]
                progress(f"table1: {len(results)}/{len(jobs)} runs done "
                         f"(last: {scen} {ctrl.upper()})")
    table = table_json(results)
    (out_dir / "table1.json").write_text(json.dumps(table, indent=2) + "\n")
    (out_dir / "table1.md").write_text(table_markdown(table))
    from gcs.report import table1_chart  # matplotlib only where a chart is drawn

    table1_chart(table, out_dir / "table1.png")
    return table
