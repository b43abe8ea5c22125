"""The paper's Table I beside our figures: Case I and three Case II variants, PID and PD.

Each case is flown twice by default (`lag_comp="both"`): with the FCU's default allocation,
which leads its commands for the rotor lag and the tilt rate limit (CA_LAG_COMP 1, the run
folders `<scenario>_<controller>`), and with the paper's plain allocation of eqs. (28-29)
(CA_LAG_COMP 0, the run folders `plain/<scenario>_<controller>`); table1.json's rows carry the
second as "plain" and table1.md shows it in columns of its own.
"""

from __future__ import annotations

import dataclasses
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
LAG_COMP = ("both", "on", "off")  # which allocations run_table1 flies (module docstring)
PLAIN_DIR = "plain"  # the run folders of the plain allocation (CA_LAG_COMP 0), in a table1 folder

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


def table_json(results: dict[tuple[str, str], dict[str, Any]],
               plain: dict[tuple[str, str], dict[str, Any]] | None = None) -> dict[str, Any]:
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


def _run_one(job: tuple[str, str, bool, float | None, str, bool, float | None, str | None,
                        int | None]) -> dict[str, Any]:
    from common.config import load_scenario
    from gcs.inprocess import apply_overrides, run_scenario
    from gcs.process_run import run_processes
    from gcs.runio import prepare_run_dir, write_run

    path, ctrl, ideal, duration, out, in_process, lag_comp, sensors, seed = job
    prepare_run_dir(Path(out), force=True)  # table1 owns its run folders
    scenario = apply_overrides(load_scenario(path), controller=ctrl,
                               ideal_actuators=ideal or None, duration_s=duration,
                               sensors=sensors, seed=seed)
    if lag_comp is not None:
        scenario = dataclasses.replace(scenario,
                                       params={**scenario.params, "CA_LAG_COMP": lag_comp})
    if not in_process:
        return run_processes(scenario, Path(out))
    result = run_scenario(scenario)
    write_run(Path(out), scenario, result)
    return result.metrics


def run_table1(config_dir: Path, out_dir: Path, *, ideal: bool = False,
               duration_s: float | None = None, workers: int | None = None,
               in_process: bool = False, progress=None,
               lag_comp: str = "both", sensors: str | None = None,
               seed: int | None = None) -> dict[str, Any]:
    """Run the 8 cases in parallel (through sitl + fcu processes unless `in_process`), with
    the default allocation (`lag_comp` "on"), the plain one (CA_LAG_COMP 0: "off") or both
    (16 runs, the plain ones in DIR/plain/), on the sensor profile `sensors` (default: the
    scenarios', truth) with `seed`; write table1.md and table1.json."""
    if lag_comp not in LAG_COMP:
        raise ValueError(f"lag_comp must be one of {', '.join(LAG_COMP)}, got {lag_comp!r}")
    out_dir.mkdir(parents=True, exist_ok=True)
    keys = [(scen, ctrl) for _, scen in CASES for ctrl in CONTROLLERS]
    sets: list[tuple[bool, float | None, Path]] = []  # (plain set?, CA_LAG_COMP, folder)
    if lag_comp != "off":
        sets.append((False, None, out_dir))
    if lag_comp != "on":
        sets.append((lag_comp == "both", 0.0, out_dir / PLAIN_DIR if lag_comp == "both"
                     else out_dir))
    jobs = [((str(config_dir / f"{scen}.toml"), ctrl, ideal, duration_s,
              str(folder / f"{scen}_{ctrl}"), in_process, value, sensors, seed),
             (is_plain, scen, ctrl))
            for is_plain, value, folder in sets for scen, ctrl in keys]
    results: dict[tuple[str, str], dict[str, Any]] = {}
    plain: dict[tuple[str, str], dict[str, Any]] = {}
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_run_one, job): key for job, key in jobs}
        done = 0
        for future in as_completed(futures):
            is_plain, scen, ctrl = futures[future]
            (plain if is_plain else results)[(scen, ctrl)] = future.result()
            done += 1
            if progress is not None:
                progress(f"table1: {done}/{len(jobs)} runs done "
                         f"(last: {scen} {ctrl.upper()}{' plain' if is_plain else ''})")
    table = table_json(results, plain or None)
    profiles = {m.get("sensors", "truth") for m in (*results.values(), *plain.values())}
    table["sensors"] = ", ".join(sorted(profiles))
    (out_dir / "table1.json").write_text(json.dumps(table, indent=2) + "\n")
    (out_dir / "table1.md").write_text(table_markdown(table))
    from gcs.report import table1_chart  # matplotlib only where a chart is drawn

    table1_chart(table, out_dir / "table1.png")
    return table
