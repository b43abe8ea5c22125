"""Suite-wide set-up: the flight core's kernels are compiled (a clean clone) or loaded once
in the controlling process before any worker starts, so that the workers and the `fcu` and
`sitl` processes the tests start load them from the cache instead of each compiling them."""

from __future__ import annotations

from pathlib import Path

import pytest

CASE1 = Path(__file__).resolve().parents[1] / "config" / "scenarios" / "case1_figure8.toml"


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker: the controller has done it
        return
    from common.config import load_scenario
    from gcs.inprocess import fcu_pipeline
    from sitl.plant import Plant

    scenario = load_scenario(CASE1)
    Plant(scenario.vehicle)
    fcu_pipeline(scenario)
