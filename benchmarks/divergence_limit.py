"""Case II: the constant body-frame force at which the PID-tracked vehicle is lost.

The paper reports divergence at a force of about 1.2 times the weight. Bisects the
magnitude of a constant force (in units of the weight m g) applied from t = 1 s along a
body-frame direction, under the default actuator limits, and prints the limit per direction.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from common.config.scenario import DisturbanceTerm, Scenario, load_scenario
from common.quaternion import Vec3
from gcs.run.inprocess import run_scenario

ROOT = Path(__file__).resolve().parent.parent
DIRECTIONS: dict[str, Vec3] = {"-z (down)": (0.0, 0.0, -1.0), "+x (forward)": (1.0, 0.0, 0.0),
              "xyz (each axis)": (1.0 / math.sqrt(3), 1.0 / math.sqrt(3), 1.0 / math.sqrt(3))}


def survives(scenario: Scenario, direction: Vec3, ratio: float) -> bool:
    weight = scenario.vehicle.mass_kg * scenario.vehicle.gravity_m_s2
    force = (ratio * weight * direction[0], ratio * weight * direction[1],
             ratio * weight * direction[2])
    term = DisturbanceTerm("pulse", force, 1.0, 1e9)
    sc = dataclasses.replace(scenario, force_terms=(term,), torque_terms=(), duration_s=15.0)
    return bool(run_scenario(sc).metrics["status"] == "completed")


def limit(scenario: Scenario, direction: Vec3, lo: float = 0.0, hi: float = 4.0,
          tol: float = 0.01) -> float:
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if survives(scenario, direction, mid) else (lo, mid)
    return 0.5 * (lo + hi)


def main() -> dict[str, float]:
    scenario = load_scenario(ROOT / "config" / "scenarios" / "case2_impulse.toml")
    return {name: limit(scenario, d) for name, d in DIRECTIONS.items()}


if __name__ == "__main__":
    for name, ratio in main().items():
        print(f"divergence limit, constant force along {name}: {ratio:.2f} x weight")
