"""Two checkouts' in-process mocap flights at the same moment: a change's speed on a shared
host whose own speed drifts.

On a machine that shares its host, the speed of one process moves by 10-30 % within
minutes, more than most changes do, so runs one after the other compare the moments more
than the code. Here each round flies the same in-process flight (Case I with
`mocap-indoor` and its logs, as `gcs run --in-process` does) from checkout A and from
checkout B at once, each pinned to a core of its own, the cores swapped every round: both
see the same moment of the host. Each prints its flight's wall time (after a 2 s flight in
the same process, which loads the kernels); the ratio B / A per round and their median say
how much faster B is.

Usage: bench_paired.py DIR_A DIR_B [--rounds N] [--duration S] [--python-a PY]
[--python-b PY]  (needs two cores). Each DIR is a checkout whose package imports (a git
worktree of another commit, say); each side runs on this interpreter unless `--python-a` /
`--python-b` name another, a venv's python with the project's packages installed (two
builds of CPython, say, with one checkout given twice).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

# The flight, run in the checkout's own directory with its own code.
_FLIGHT = """
import dataclasses, sys
from common.config.scenario import load_scenario
from common.config.sensors import resolve_sensor_profile
from gcs.run.inprocess import run_scenario
sc = dataclasses.replace(load_scenario("config/scenarios/case1_figure8.toml"),
                         sensors=resolve_sensor_profile("mocap-indoor"))
run_scenario(dataclasses.replace(sc, duration_s=2.0))
m = run_scenario(dataclasses.replace(sc, duration_s=float(sys.argv[1]))).metrics
print(m["wall_time_s"], m["status"])
"""


def _start(checkout: Path, python: str, cpu: int, duration_s: float
           ) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    return subprocess.Popen(
        [python, "-c", _FLIGHT, str(duration_s)], cwd=checkout, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: os.sched_setaffinity(0, {cpu}))


def _wall(proc: subprocess.Popen[str], checkout: Path) -> float:
    out, err = proc.communicate(timeout=600)
    if proc.returncode != 0:
        raise SystemExit(f"bench_paired: the flight in {checkout} failed "
                         f"(exit {proc.returncode}):\n{err.strip()}")
    wall, status = out.strip().splitlines()[-1].split()  # the flight's last line
    if status != "completed":
        raise SystemExit(f"bench_paired: the flight in {checkout} ended {status}")
    return float(wall)


def main(a: Path, b: Path, rounds: int, duration_s: float, python_a: str = sys.executable,
         python_b: str = sys.executable) -> list[tuple[float, float]]:
    """(wall A, wall B) of each round."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        raise SystemExit("bench_paired: needs two cores (one for each checkout)")
    walls = []
    for k in range(rounds):
        ca, cb = (cpus[0], cpus[1]) if k % 2 == 0 else (cpus[1], cpus[0])
        pa, pb = _start(a, python_a, ca, duration_s), _start(b, python_b, cb, duration_s)
        wa, wb = _wall(pa, a), _wall(pb, b)
        walls.append((wa, wb))
        print(f"round {k + 1}: A {wa:.3f} s, B {wb:.3f} s, B/A {wb / wa:.3f}", flush=True)
    return walls


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("a", type=Path, help="checkout A (the reference)")
    p.add_argument("b", type=Path, help="checkout B")
    p.add_argument("--rounds", type=int, default=10, help="rounds (default 10)")
    p.add_argument("--duration", type=float, default=40.0,
                   help="simulated seconds of each timed flight (default 40)")
    p.add_argument("--python-a", default=sys.executable,
                   help="A's interpreter (default: this one)")
    p.add_argument("--python-b", default=sys.executable,
                   help="B's interpreter (default: this one)")
    return p


if __name__ == "__main__":
    args = _parser().parse_args()
    for d in (args.a, args.b):
        if not (d / "gcs" / "run" / "inprocess.py").is_file():
            raise SystemExit(f"bench_paired: {d} is not a checkout of this project")
    if args.rounds < 1 or not args.duration > 0.0:
        raise SystemExit("bench_paired: --rounds must be >= 1 and --duration > 0")
    for py in (args.python_a, args.python_b):
        if not os.access(py, os.X_OK):
            raise SystemExit(f"bench_paired: {py} is not an interpreter this user can run")
    w = main(args.a.resolve(), args.b.resolve(), args.rounds, args.duration, args.python_a,
             args.python_b)
    ratios = [wb / wa for wa, wb in w]
    print(f"{args.duration:g} s of in-process mocap flight, {len(w)} rounds: A median "
          f"{statistics.median(x for x, _ in w):.3f} s, B median "
          f"{statistics.median(y for _, y in w):.3f} s; B/A median "
          f"{statistics.median(ratios):.3f}, mean {statistics.fmean(ratios):.3f}, "
          f"range {min(ratios):.3f}-{max(ratios):.3f}")
