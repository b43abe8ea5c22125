"""The FCU's three planning computations, timed: the mission upload check of a 500-item
mission with its envelope stretching, the re-check at MISSION_START, OFFBOARD's / HOLD's
approach planner and POSCTL's envelope fit.

    .venv/bin/python benchmarks/bench_planning.py [--rounds N]

1. `check_mission` of `mission_envelope.mixed(500)` (a take-off, 498 items cycling 20 m legs
   to stretch, 20 s keyframes and 60 s figures, a landing) on the tilted vehicle with
   `mission_envelope.fast_limits`: what
   `fcu.edge.mission_protocol` calls when the last MISSION_ITEM_INT arrives. Each round starts
   with the planning caches emptied (`fcu.envelope.feasibility.clear_caches`), so nothing of an
   earlier round is reused. Then MISSION_START as `fcu.modes.commander` does it:
   `MissionExecutor(...)`, `set_current(0, ...)` from a pose 3 cm off the origin, slightly
   tilted and yawed, and `refusal()`; once right after the upload check (the caches as that
   left them, the order of a flight) and once with the caches emptied. The batch kernels
   (`fcu.mission.batches`) run on two threads as the FCU's worker process runs them
   (`fcu.edge.work_process`), and again in one thread.
2. `fcu.reference.approach.plan` over a spread of OFFBOARD and HOLD plans on both vehicle files
(steps
   from a hover up to 20 m and 180 deg, HOLD from a moving reference, OFFBOARD's entry, a new
   sample while an approach is under way, position-only and attitude-only samples), each
   call timed alone.
3. `fcu.modes.manual.fit_envelope` (POSCTL's entry) at 16 attitudes on both vehicle files.

Prints median, p95 and max of each, in milliseconds.
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.mission_envelope import fast_limits, mixed
from common.config.scenario import VehicleConfig, load_vehicle
from common.wire.mission_items import MissionItem
from fcu.control.dualquat import Quat, Vec3, q_exp
from fcu.edge.work_process import install_side_by_side
from fcu.envelope import feasibility
from fcu.envelope.feasibility import Envelope, envelope
from fcu.mission import batches
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission, refusal
from fcu.modes import manual, offboard
from fcu.modes.manual import StickSettings
from fcu.reference import approach
from fcu.stages import Reference

ROOT = Path(__file__).resolve().parents[1]
MISSION_ITEMS = 500
START_P: Vec3 = (0.03, -0.02, 0.0)
START_Q: Quat = q_exp((0.01, -0.02, 0.3))
_ZERO: Vec3 = (0.0, 0.0, 0.0)
PlanCall = tuple[Envelope | None, StickSettings, approach.Setpoint, approach.Offset,
                 tuple[bool, bool]]


def _vehicles() -> dict[str, VehicleConfig]:
    return {name: load_vehicle(ROOT / f"config/vehicles/{name}.toml")
            for name in ("hexa_tilted", "hexa_planar")}


def _clear() -> None:
    """Empty the planning caches (where the code has them)."""
    clear: Callable[[], None] | None = getattr(feasibility, "clear_caches", None)
    if clear is not None:
        clear()


def _ms(call: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    call()
    return (time.perf_counter() - t0) * 1e3


def _figures(samples: list[float]) -> str:
    a = np.asarray(samples)
    return (f"median {float(np.median(a)):.3f} ms, p95 {float(np.percentile(a, 95)):.3f} ms, "
            f"max {float(a.max()):.3f} ms ({len(a)} calls)")


def _mission_start(items: Sequence[MissionItem], limits: MissionLimits) -> str:
    ex = MissionExecutor(items, limits)
    ex.set_current(0, 1.0, START_P, START_Q)
    return ex.refusal()


def bench_mission(rounds: int, vehicle: VehicleConfig) -> dict[str, list[float]]:
    items = mixed(MISSION_ITEMS)
    limits = fast_limits(vehicle)
    check = check_mission(items, limits)  # warm-up: kernels compiled or loaded
    assert not refusal(check), refusal(check)
    assert _mission_start(items, limits) == ""
    out: dict[str, list[float]] = {"check": [], "start": [], "start_cold": []}
    for _ in range(rounds):
        _clear()
        out["check"].append(_ms(lambda: check_mission(items, limits)))
        out["start"].append(_ms(lambda: _mission_start(items, limits)))
        _clear()
        out["start_cold"].append(_ms(lambda: _mission_start(items, limits)))
    return out


def _rand_q(rng: random.Random, max_angle: float) -> Quat:
    axis = [rng.gauss(0.0, 1.0) for _ in range(3)]
    n = math.sqrt(sum(a * a for a in axis))
    angle = rng.uniform(0.0, max_angle)
    return q_exp((angle * axis[0] / n, angle * axis[1] / n, angle * axis[2] / n))


def _rvec(rng: random.Random, s: float) -> Vec3:
    return (rng.uniform(-s, s), rng.uniform(-s, s), rng.uniform(-s, s))


def plan_calls(vehicles: dict[str, VehicleConfig], per_vehicle: int = 120,
               seed: int = 17) -> list[PlanCall]:
    """The spread of `approach.plan` calls (module docstring), the same for a seed."""
    rng = random.Random(seed)
    lim = offboard.limits(StickSettings())
    calls: list[PlanCall] = []
    for vehicle in vehicles.values():
        env = envelope(vehicle)
        for k in range(per_vehicle):
            kind = k % 6
            ref_q = _rand_q(rng, 0.3) if k % 4 else (1.0, 0.0, 0.0, 0.0)
            free = (False, False)
            if kind in (0, 1):  # a step from a hover
                p_t = (rng.uniform(-20, 20), rng.uniform(-20, 20), 15.0 + rng.uniform(-10, 10))
                ref = Reference((0.0, 0.0, 15.0), ref_q, _ZERO, _ZERO, _ZERO, _ZERO)
                sp = approach.Setpoint(p_t, _ZERO, _ZERO, _rand_q(rng, math.pi), _ZERO)
            elif kind == 2:  # HOLD from a moving reference
                ref = Reference(_rvec(rng, 5), ref_q, _rvec(rng, 4), _rvec(rng, 2),
                                _rvec(rng, 0.8), _rvec(rng, 1.0))
                sp = approach.Setpoint(ref.p_enu_m, _ZERO, _ZERO, ref.q_enu_flu, _ZERO)
                free = (True, True)
            elif kind == 3:  # OFFBOARD's entry: the reference continues at its rates
                ref = Reference(_rvec(rng, 5), ref_q, _rvec(rng, 3), _rvec(rng, 2),
                                _rvec(rng, 0.5), _rvec(rng, 1.0))
                sp = approach.Setpoint(ref.p_enu_m, ref.v_enu_m_s, _ZERO, ref.q_enu_flu,
                                       ref.omega_flu_rad_s)
            elif kind == 4:  # a position-only sample during an approach, velocity fed
                ref = Reference(_rvec(rng, 5), ref_q, _rvec(rng, 2), _rvec(rng, 1),
                                _rvec(rng, 0.3), _rvec(rng, 0.5))
                sp = approach.Setpoint(_rvec(rng, 8), _rvec(rng, 1), _ZERO, ref.q_enu_flu,
                                       _ZERO)
                free = (False, True)
            else:  # an attitude-only sample
                ref = Reference(_rvec(rng, 5), ref_q, _rvec(rng, 1), _rvec(rng, 0.5),
                                _rvec(rng, 0.3), _rvec(rng, 0.5))
                sp = approach.Setpoint(ref.p_enu_m, _ZERO, _ZERO, _rand_q(rng, 1.5),
                                       _rvec(rng, 0.3))
                free = (True, False)
            calls.append((env, lim, sp, offboard._offset(ref, sp), free))
    return calls


def bench_approach(rounds: int, vehicles: dict[str, VehicleConfig]) -> list[float]:
    calls = plan_calls(vehicles)
    for env, lim, sp, x, free in calls:  # warm-up
        approach.plan(env, lim, sp, x, free)
    out: list[float] = []
    for _ in range(max(1, rounds // 5)):
        for env, lim, sp, x, free in calls:
            out.append(_ms(partial(approach.plan, env, lim, sp, x, free)))
    return out


def attitudes() -> list[Quat]:
    """Level, rolled 30-180 deg, pitched 45-135 deg and 5 random attitudes."""
    rng = random.Random(23)
    return [(1.0, 0.0, 0.0, 0.0),
            *(q_exp((math.radians(d), 0.0, 0.0)) for d in (30, 60, 90, 120, 150, 170, 180)),
            *(q_exp((0.0, math.radians(d), 0.0)) for d in (45, 90, 135)),
            *(_rand_q(rng, math.pi) for _ in range(5))]


def bench_fit(rounds: int, vehicles: dict[str, VehicleConfig]) -> list[float]:
    sticks = StickSettings()
    qs = attitudes()
    for vehicle in vehicles.values():  # warm-up
        manual.fit_envelope(sticks, vehicle, qs[0])
    out: list[float] = []
    for _ in range(max(1, rounds // 5)):
        for vehicle in vehicles.values():
            for q in qs:
                out.append(_ms(partial(manual.fit_envelope, sticks, vehicle, q)))
    return out


def main(rounds: int) -> None:
    vehicles = _vehicles()
    one = bench_mission(rounds, vehicles["hexa_tilted"])
    ways = install_side_by_side()  # as the FCU's worker process runs them
    mission = bench_mission(rounds, vehicles["hexa_tilted"])
    batches.install(batches.in_turn, 1)
    print(f"mission upload check, {MISSION_ITEMS} items (caches emptied): "
          f"{_figures(mission['check'])}")
    print(f"MISSION_START re-check after the upload check: {_figures(mission['start'])}")
    print(f"MISSION_START re-check, caches emptied: {_figures(mission['start_cold'])}")
    print(f"(the batch kernels on {ways} thread{'s' if ways > 1 else ''}, as the FCU's worker "
          f"runs them; in one thread: upload check {_figures(one['check'])}, re-check "
          f"{_figures(one['start'])}, caches emptied {_figures(one['start_cold'])})")
    print(f"approach.plan: {_figures(bench_approach(rounds, vehicles))}")
    print(f"manual.fit_envelope: {_figures(bench_fit(rounds, vehicles))}")
    print(f"(median of the mission check {statistics.median(mission['check']):.1f} ms; "
          f"target <= 20 ms each, approach and fit <= 2 ms median)", flush=True)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=15,
                   help="timed rounds of the mission check (default 15); the approach and "
                        "fit sets are timed rounds // 5 times")
    main(p.parse_args().rounds)
