"""What the ULog logs cost: per control step in flight, on disk, and to read back.

Flies Case I in-process with and without its logs (the same logger classes the `sitl` and
`fcu` processes use), writes the full 160 s run's logs and reads them back with pyulog as
metrics and reports do. Prints:

- overhead: extra wall time per control step with both logs (truth and onboard records,
  PX4 topics at their rates), best of 3;
- size of truth.ulg and onboard.ulg for 160 s, and the time to read the float64 topics
  (`read_run_logs`) and every topic (`open_ulog`).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from common.config.scenario import load_scenario
from common.logs.ulog import open_ulog
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides
from gcs.run.runio import ONBOARD_LOG, TRUTH_LOG, read_run_logs, write_run

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"


def main() -> None:
    short = apply_overrides(load_scenario(CASE1), duration_s=20.0)
    steps = round(short.duration_s * short.control_rate_hz)
    best: dict[bool, float] = {}
    for logs in (False, True) * 3:
        t0 = time.perf_counter()
        run_scenario(short, logs=logs)
        wall = time.perf_counter() - t0
        best[logs] = min(best.get(logs, wall), wall)
    per_step = (best[True] - best[False]) / steps * 1e6
    print(f"logs: Case I 20 s in-process, best of 3: {best[False]:.2f} s without logs, "
          f"{best[True]:.2f} s with; {per_step:.1f} us per control step "
          f"({100 * (best[True] / best[False] - 1):.0f} %)")

    full = load_scenario(CASE1)
    result = run_scenario(full)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        write_run(out, full, result)
        sizes = {name: (out / name).stat().st_size / 1e6 for name in (TRUTH_LOG, ONBOARD_LOG)}
        t0 = time.perf_counter()
        read_run_logs(out)
        t_dq = time.perf_counter() - t0
        t0 = time.perf_counter()
        for name in (TRUTH_LOG, ONBOARD_LOG):
            open_ulog(out / name)
        t_all = time.perf_counter() - t0
    print(f"logs: Case I 160 s: {TRUTH_LOG} {sizes[TRUTH_LOG]:.1f} MB, {ONBOARD_LOG} "
          f"{sizes[ONBOARD_LOG]:.1f} MB; pyulog reads dq_truth + dq_onboard in {t_dq:.2f} s, "
          f"every topic of both in {t_all:.2f} s")


if __name__ == "__main__":
    main()
