"""This stack's in-process simulation speed beside RotorPy's, on the same machine.

Both simulators fly the same simulated duration (`--duration`, 20 s by default), one after
the other, `--repeats` times each (3 by default); the script prints each figure, the median
and the ratio, in simulated seconds per wall second.

- This stack: Case I (`config/scenarios/case1_figure8.toml`, truth sensors, its two ULogs
  built in memory, `run_scenario`'s default) through `gcs.run.inprocess.run_scenario`,
  in this interpreter; control at 500 Hz, physics (RK4 plant) at 1 kHz. The figure is the
  run's own `real_time_factor` (its flight loop only). Case I rises for 10 s and hovers
  until 20 s; the figure-infinity starts at 20 s, so `--duration 40` or more includes it.
- RotorPy (the PyPI package, in its own interpreter, as a subprocess): its standard example,
  `Environment(Multirotor(crazyflie quad_params), SE3Control(quad_params),
  ThreeDCircularTraj())` with every other argument at its default: `sim_rate` 100 Hz (the
  controller runs once per simulation step, so at 100 Hz too; each step is integrated by
  its own `scipy.integrate.solve_ivp` call, RK45 with an adaptive step, in practice one
  RK45 step per 10 ms: about 8 derivative evaluations with the solver's start), no wind,
  its default IMU and motion capture evaluated every step, the null estimator, aerodynamic
  drag on. The vehicle starts on the circle with its velocity there. Only
  `env.run(t_final=D, terminate=False)` is timed (`terminate=False`: fly the whole
  duration; no plot, no animation); it includes RotorPy's own post-processing of the run's
  histories.

The RotorPy interpreter: `--rotorpy-python PATH`, else the environment variable
`ROTORPY_PYTHON`, else a virtual environment in `benchmarks/.rotorpy-venv` (git-ignored),
created and filled with `pip install rotorpy` on first use (network access to PyPI then).
RotorPy is not one of the project's dependencies and never enters the project's
environment.

    .venv/bin/python benchmarks/bench_rotorpy.py [--duration 20] [--repeats 3]
        [--rotorpy-python PATH]

Run it on an otherwise idle machine: the load average is printed before each simulator, and
each run's CPU time as a share of its wall time (well under 100 %: the run was kept waiting;
the table then warns). The table also gives simulated seconds per CPU second, which a busy
machine distorts less (this stack's CPU time there includes its run's setup and metrics).
The script measures the flight core of the checkout it is in (that checkout comes first on
`sys.path`), whatever it is.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
VENV = HERE / ".rotorpy-venv"
SCENARIO = ROOT / "config" / "scenarios" / "case1_figure8.toml"


# --- RotorPy's side: runs in RotorPy's interpreter (`--rotorpy-worker`) -------------------

def rotorpy_worker(duration_s: float, repeats: int) -> dict[str, Any]:
    """RotorPy's standard example at its default rates, `repeats` times; JSON-ready."""
    from importlib.metadata import version

    import numpy as np
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.environments import Environment
    from rotorpy.trajectories.circular_traj import ThreeDCircularTraj
    from rotorpy.vehicles.crazyflie_params import quad_params
    from rotorpy.vehicles.multirotor import Multirotor

    def environment() -> Environment:
        trajectory = ThreeDCircularTraj()
        vehicle = Multirotor(quad_params)
        start = trajectory.update(0.0)
        # On the circle at t = 0, with its velocity there, rotors at hover speed: the default
        # initial state moved onto the trajectory (the circle does not pass the origin).
        vehicle.initial_state = dict(vehicle.initial_state, x=np.asarray(start["x"], float),
                                     v=np.asarray(start["x_dot"], float))
        return Environment(vehicle=vehicle, controller=SE3Control(quad_params),
                           trajectory=trajectory)

    runs = []
    for _ in range(repeats):
        env = environment()
        c0, t0 = time.process_time(), time.perf_counter()
        result = env.run(t_final=duration_s, terminate=False)
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0
        sim = float(result["time"][-1])
        error = np.linalg.norm(result["state"]["x"] - result["flat"]["x"], axis=1)
        runs.append({"sim_time_s": sim, "wall_time_s": wall, "factor": sim / wall,
                     "exit": result["exit"].name, "position_error_max_m": float(error.max()),
                     "cpu_share": cpu / wall, "per_cpu_s": sim / cpu})

    # Untimed: how many derivative evaluations RK45 takes per simulation step.
    env = environment()
    step, evaluations = env.vehicle._s_dot_fn, [0]

    def counted(t: float, s: Any, cmd: Any) -> Any:
        evaluations[0] += 1
        return step(t, s, cmd)

    env.vehicle._s_dot_fn = counted
    count_s = min(duration_s, 5.0)
    steps = len(env.run(t_final=count_s, terminate=False)["time"]) - 1
    # statedot (for the IMU) evaluates the derivative once more per step and once at t = 0,
    # outside the integrator.
    per_step = (evaluations[0] - steps - 1) / steps if steps else float("nan")

    return {"runs": runs, "sim_rate_hz": env.sim_rate,
            "integrator": env.vehicle.integrator_kwargs,
            "rk45_evaluations_per_step": per_step, "counted_over_s": count_s,
            "wind": type(env.wind_profile).__name__, "imu": type(env.imu).__name__,
            "mocap": type(env.mocap).__name__, "estimator": type(env.estimator).__name__,
            "aero": bool(env.vehicle.aero),
            "versions": {name: version(name) for name in ("rotorpy", "numpy", "scipy")},
            "python": sys.version.split()[0]}


# --- this stack's side: runs in this interpreter ------------------------------------------

def stack_runs(duration_s: float, repeats: int) -> list[dict[str, float]]:
    # This checkout's code, whichever checkout an installed copy of the project points to.
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from common.config.scenario import load_scenario
    from gcs.run.inprocess import run_scenario
    from gcs.run.overrides import apply_overrides

    runs = []
    for _ in range(repeats):
        scenario = apply_overrides(load_scenario(SCENARIO), duration_s=duration_s,
                                   sensors="truth")
        c0, t0 = time.process_time(), time.perf_counter()
        m = run_scenario(scenario).metrics
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        runs.append({"sim_time_s": m["sim_time_s"], "wall_time_s": m["wall_time_s"],
                     "factor": m["real_time_factor"],
                     "control_rate_hz": m["control_rate_hz"],
                     "physics_rate_hz": m["physics_rate_hz"],
                     "position_error_max_m": m["position_error_m"]["max"],
                     # the whole call's (setup and metrics included: a little low)
                     "cpu_share": cpu / wall, "per_cpu_s": m["sim_time_s"] / cpu})
    return runs


# --- the RotorPy interpreter ---------------------------------------------------------------

def venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def rotorpy_python(given: str | None) -> Path:
    """The interpreter to run RotorPy in; creates and fills the cache venv when none is given."""
    if given:
        return Path(given)
    python = venv_python(VENV)
    if not python.exists():
        print(f"creating {VENV.relative_to(ROOT)} (python -m venv) ...", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(VENV)], check=True)
    probe = subprocess.run([str(python), "-c", "import rotorpy"], capture_output=True,
                           check=False)
    if probe.returncode != 0:
        print("pip install rotorpy into it ...", flush=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "rotorpy"],
                       check=True)
    return python


def run_rotorpy(python: Path, duration_s: float, repeats: int) -> dict[str, Any]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["MPLBACKEND"] = "Agg"
    out = subprocess.run([str(python), str(Path(__file__).resolve()), "--rotorpy-worker",
                          "--duration", repr(duration_s), "--repeats", str(repeats)],
                         capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        sys.exit(f"RotorPy run failed ({python}):\n{out.stderr}")
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def load() -> str:
    try:
        return " / ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0,
                        help="simulated seconds per run (default 20)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per simulator (default 3)")
    parser.add_argument("--rotorpy-python", default=os.environ.get("ROTORPY_PYTHON"),
                        help="the interpreter with rotorpy installed (default: $ROTORPY_PYTHON, "
                             "else benchmarks/.rotorpy-venv, created on first use)")
    parser.add_argument("--rotorpy-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.rotorpy_worker:
        print(json.dumps(rotorpy_worker(args.duration, args.repeats)))
        return

    python = rotorpy_python(args.rotorpy_python)
    d, n = args.duration, args.repeats

    print(f"this stack: Case I in-process, truth sensors, {d:g} s simulated, {n} runs "
          f"(load average {load()})", flush=True)
    stack = stack_runs(d, n)
    for r in stack:
        print(f"  {r['sim_time_s']:.1f} s in {r['wall_time_s']:.2f} s wall = "
              f"{r['factor']:.2f} sim s / wall s (position error max "
              f"{r['position_error_max_m'] * 1e3:.2f} mm; CPU {r['cpu_share']:.0%} of wall)",
              flush=True)

    print(f"RotorPy: crazyflie, SE3Control, ThreeDCircularTraj, {d:g} s simulated, {n} runs "
          f"(load average {load()})", flush=True)
    rp = run_rotorpy(python, d, n)
    rp_runs: list[dict[str, Any]] = rp["runs"]
    for r in rp_runs:
        print(f"  {r['sim_time_s']:.1f} s in {r['wall_time_s']:.2f} s wall = "
              f"{r['factor']:.2f} sim s / wall s (exit {r['exit']}, position error max "
              f"{r['position_error_max_m'] * 1e3:.1f} mm; CPU {r['cpu_share']:.0%} of wall)",
              flush=True)
    versions = ", ".join(f"{k} {v}" for k, v in rp["versions"].items())
    print(f"  RotorPy defaults: sim_rate {rp['sim_rate_hz']} Hz (controller every step), "
          f"solve_ivp {rp['integrator']} per step, {rp['rk45_evaluations_per_step']:.1f} "
          f"derivative evaluations per step (first {rp['counted_over_s']:g} s); "
          f"wind {rp['wind']}, {rp['imu']} and {rp['mocap']} every step, {rp['estimator']}, "
          f"aero {rp['aero']}; Python {rp['python']}, {versions}")

    s_med = statistics.median(r["factor"] for r in stack)
    r_med = statistics.median(r["factor"] for r in rp_runs)
    s_cpu = statistics.median(r["per_cpu_s"] for r in stack)
    r_cpu = statistics.median(r["per_cpu_s"] for r in rp_runs)
    rows = [("this stack (Case I)", f"{stack[0]['control_rate_hz']:g} Hz",
             f"{stack[0]['physics_rate_hz']:g} Hz (RK4)", s_med, s_cpu),
            ("RotorPy (crazyflie)", f"{rp['sim_rate_hz']:g} Hz",
             f"{rp['sim_rate_hz']:g} Hz (RK45, adaptive)", r_med, r_cpu),
            ("ratio", "", "", s_med / r_med, s_cpu / r_cpu)]
    print()
    print(f"| simulator | control | physics | sim s / wall s (median of {n}) | sim s / CPU s |")
    print("|---|---|---|---:|---:|")
    for name, control, physics, factor, per_cpu in rows:
        print(f"| {name} | {control} | {physics} | {factor:.2f} | {per_cpu:.2f} |")
    print("(sim s / CPU s: the process's CPU time, which a busy machine inflates less than "
          "the wall time; this stack's counts its setup and metrics too)")
    print(f"wall time per control step (medians): this stack "
          f"{1e6 / (s_med * stack[0]['control_rate_hz']):.0f} µs (of a "
          f"{1e3 / stack[0]['control_rate_hz']:g} ms step), RotorPy "
          f"{1e6 / (r_med * rp['sim_rate_hz']):.0f} µs (of a "
          f"{1e3 / rp['sim_rate_hz']:g} ms step)")
    waited = [r["cpu_share"] for r in (*stack, *rp_runs) if r["cpu_share"] < 0.9]
    if waited:
        print(f"warning: {len(waited)} of {2 * n} runs had the CPU for less than 90 % of their "
              f"wall time (lowest {min(waited):.0%}): the machine was not idle, their figures "
              f"are low")


if __name__ == "__main__":
    main()
