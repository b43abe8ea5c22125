"""`gcs table1`: fly Table I's 8 cases (gcs.report.table1) in parallel, with the FCU's default
allocation, the paper's plain one (CA_LAG_COMP 0) or both, and write table1.json, table1.md
and table1.png in the table1 folder (the run folders `<scenario>_<controller>` beside them,
the plain ones under plain/)."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from gcs.report.run_metrics import RunMetrics
from gcs.report.table1 import CASES, CONTROLLERS, table_json, table_markdown

LAG_COMP = ("both", "on", "off")  # which allocations run_table1 flies (module docstring)
PLAIN_DIR = "plain"  # the run folders of the plain allocation (CA_LAG_COMP 0), in a table1 folder


def _run_one(job: tuple[str, str, bool, float | None, str, bool, float | None, str | None,
                        int | None]) -> RunMetrics:
    from common.config.scenario import load_scenario
    from gcs.run.overrides import apply_overrides
    from gcs.run.process_run import one_vehicle, run_processes
    from gcs.run.runio import prepare_run_dir, write_run

    path, ctrl, ideal, duration, out, in_process, lag_comp, sensors, seed = job
    prepare_run_dir(Path(out), force=True)  # table1 owns its run folders
    scenario = apply_overrides(load_scenario(path), controller=ctrl,
                               ideal_actuators=ideal or None, duration_s=duration,
                               sensors=sensors, seed=seed)
    if lag_comp is not None:
        scenario = dataclasses.replace(scenario,
                                       params={**scenario.params, "CA_LAG_COMP": lag_comp})
    if not in_process:
        return one_vehicle(run_processes(scenario, Path(out)))
    from gcs.run.inprocess import run_scenario  # loads the FCU and the plant

    result = run_scenario(scenario)
    write_run(Path(out), scenario, result)
    return result.metrics


def run_table1(config_dir: Path, out_dir: Path, *, ideal: bool = False,
               duration_s: float | None = None, workers: int | None = None,
               in_process: bool = False, progress: Callable[[str], None] | None = None,
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
    results: dict[tuple[str, str], RunMetrics] = {}
    plain: dict[tuple[str, str], RunMetrics] = {}
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
    from gcs.report.chart import table1_chart  # matplotlib only where a chart is drawn

    table1_chart(table, out_dir / "table1.png")
    return table
