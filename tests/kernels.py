"""The suite's kernels compiled into numba's on-disk cache once (`build_kernels`): by the
first test that flies (`tests/conftest.py`, `compiled_kernels`), or before pytest starts:

    .venv/bin/python -m tests.kernels

which `make test` runs beside mypy. On a fresh cache that is a minute of compilation, more
on a busy machine; inside a test it counted against the test's timeout, and a timeout that
stopped numba half-way through loading its registries left the worker unable to compile
anything after (`No definition for lowering ...` in every later test of that worker).
"""

from __future__ import annotations

import fcntl
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"


def _kernel_stamps() -> dict[str, list[float]]:
    """What numba checks a cached kernel against: each kernel module's mtime and size."""
    from common.jit import KERNEL_MODULES

    return {name: [(ROOT / name).stat().st_mtime, (ROOT / name).stat().st_size]
            for name in KERNEL_MODULES}


def _fly_warm_up() -> None:
    """Every kernel the suite's programs load, compiled here once rather than by several
    programs at once on a fresh cache: the plant's and the pipeline's warm-ups, the planners'
    (`fcu.warm`: missions, approach, POSCTL) and the estimator's, then a 3 s mission (the
    mission executor's kernels compile for their callers' types, a rotation sampled at many
    instants at once, on first use) and 1 s on mocap-indoor sensors (the sensor feed's and
    the estimator's in flight)."""
    import dataclasses

    from common.config.scenario import load_scenario
    from common.config.sensors import resolve_sensor_profile
    from fcu.estimator.ekf import warm as warm_estimator
    from fcu.warm import warm as warm_plans
    from gcs.run.inprocess import fcu_pipeline, run_scenario
    from gcs.run.overrides import apply_overrides
    from sitl.plant import Plant

    scenario = load_scenario(CASE1)
    Plant(scenario.vehicle)
    pipeline, _ = fcu_pipeline(scenario)
    warm_plans(pipeline.commander.limits)
    warm_estimator()
    run_scenario(apply_overrides(load_scenario(CASE1.parent / "mission_tour.toml"),
                                 duration_s=3.0), logs=False)
    run_scenario(dataclasses.replace(scenario, duration_s=1.0,
                                     sensors=resolve_sensor_profile("mocap-indoor")),
                 logs=True)


def build_kernels() -> bool:
    """Compile the kernels into numba's cache unless a run already did for these sources
    (a stamp file beside them); True if this call flew the warm-up. One process at a time:
    the others wait on the lock, then find the stamp."""
    import numba

    import common.jit  # noqa: F401  (sets numba's cache folder)

    cache = Path(numba.config.CACHE_DIR)
    cache.mkdir(parents=True, exist_ok=True)
    stamp = cache / "warm-up.json"
    with (cache / "warm-up.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        want = _kernel_stamps()
        if stamp.exists() and json.loads(stamp.read_text()) == want:
            return False
        _fly_warm_up()
        stamp.write_text(json.dumps(want))
        return True


if __name__ == "__main__":
    print("kernels: compiled into numba's cache" if build_kernels() else
          "kernels: in numba's cache already")
