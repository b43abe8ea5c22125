"""`gcs run` of every shipped scenario (config/scenarios/), through the sitl and fcu processes
in lockstep as a user runs them, beside a CPU load.

    .venv/bin/python benchmarks/scenarios_under_load.py [--busy K] [--nice P] [--jobs J]
        [--sensors PROFILE] [--out DIR] [scenario.toml ...]

First flies each scenario in-process (`gcs run --in-process`, before any load): its status
there is the flight's own outcome (Case II sine diverges by design). Then starts K
busy-looping children at nice P (default 8 at nice 0: a normal-priority load of 8), runs
`gcs run SCENARIO --out DIR/NAME` through the processes for each scenario, J at a time
(default 2), and prints each run's exit code, the status its metrics.json gives, the
simulated and wall time. In lockstep a loaded machine makes a flight slower, never
different: a run passes when its status is the in-process one and its exit code says so (0
for `completed`, else 1); the script exits 1 when any run did not pass. The busy children
are this script's own and are stopped, by their process ids, on every way out, Ctrl-C
included.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.suite_under_load import ROOT, busy_children, stop_children

SCENARIOS = ROOT / "config" / "scenarios"


def _run(scenario: Path, out: Path, sensors: str | None, *extra: str
         ) -> tuple[str, int, str, float, float, str]:
    """(name, exit code, status, simulated s, wall s, the last line of its stderr) of one
    `gcs run`."""
    argv = [str(ROOT / ".venv" / "bin" / "gcs"), "run", str(scenario), "--out",
            str(out / scenario.stem), "--force", "-q", *extra]
    if sensors:
        argv += ["--sensors", sensors]
    start = time.monotonic()
    proc = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True)
    wall = time.monotonic() - start
    status, sim = "no metrics.json", float("nan")
    metrics = out / scenario.stem / "metrics.json"
    if metrics.is_file():
        m = json.loads(metrics.read_text())
        status, sim = str(m.get("status")), float(m.get("sim_time_s", float("nan")))
    tail = (proc.stderr.strip().splitlines() or [""])[-1]
    return scenario.stem, proc.returncode, status, sim, wall, tail


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenarios", nargs="*", type=Path,
                        help="scenario files (default: every config/scenarios/*.toml)")
    parser.add_argument("--busy", type=int, default=8, help="busy processes (default 8)")
    parser.add_argument("--nice", type=int, default=0, choices=range(20), metavar="P",
                        help="their niceness, 0..19 (default 0)")
    parser.add_argument("--jobs", type=int, default=2, help="runs at a time (default 2)")
    parser.add_argument("--sensors", default=None, help="sensor profile for every run")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for the runs (default: a temporary one, removed)")
    args = parser.parse_args(argv)
    if args.busy < 0 or args.jobs < 1:
        parser.error("--busy must be at least 0 and --jobs at least 1")
    scenarios = args.scenarios or sorted(SCENARIOS.glob("*.toml"))
    missing = [str(s) for s in scenarios if not s.is_file()]
    if missing:
        parser.error(f"no such scenario: {', '.join(missing)}")
    print(f"{len(scenarios)} scenarios beside {args.busy} busy at nice {args.nice}, "
          f"{args.jobs} at a time; load average "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        expected = {name: status for name, _, status, _, _, _ in (
            _run(s, Path(tmp) / "in-process", args.sensors, "--in-process") for s in scenarios)}
    print("in-process: " + ", ".join(f"{k} {v}" for k, v in expected.items()), flush=True)
    busy = busy_children(args.busy, args.nice)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = args.out or Path(tmp)
            with ThreadPoolExecutor(args.jobs) as pool:
                for name, code, status, sim, wall, tail in pool.map(
                        lambda s: _run(s, out, args.sensors), scenarios):
                    ok = status == expected[name] and code == (status != "completed")
                    failed += not ok
                    print(f"{name:18s} exit {code}  {status:10s}  {sim:6.1f} s simulated in "
                          f"{wall:6.1f} s wall" + ("" if ok else f"  FAILED: {tail}"),
                          flush=True)
    except KeyboardInterrupt:
        return 130
    finally:
        stop_children(busy)
    print(f"{len(scenarios) - failed} of {len(scenarios)} passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
