"""Suite-wide set-up: the flight core's kernels are compiled (a clean clone) or loaded once
in the controlling process before any worker starts, so that the workers and the `fcu` and
`sitl` processes the tests start load them from the cache instead of each compiling them.

Tiers: every test that starts a program (`sitl`, `fcu`, `gcs`, a writer to kill) is marked
`process`: all of tests/sitl/, the README and docs blocks that run, tests using the module
fixtures that fly through `gcs` (PROCESS_FIXTURES), and the few marked by hand. `make
test-fast` runs the rest (`-m "not slow and not process"`); `make test` runs everything."""

from __future__ import annotations

from pathlib import Path

import pytest

CASE1 = Path(__file__).resolve().parents[1] / "config" / "scenarios" / "case1_figure8.toml"
TESTS = Path(__file__).resolve().parent
PROCESS_FIXTURES = {"est_run", "truth_run"}  # tests/unit/test_estimator_logs.py: `gcs run`


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests that start programs `process` (module docstring)."""
    for item in items:
        path = Path(str(item.fspath))
        if (TESTS / "sitl") in path.parents or \
                item.name.startswith("test_block_runs_as_written") or \
                PROCESS_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.process)


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):  # an xdist worker: the controller has done it
        return
    from common.config.scenario import load_scenario
    from gcs.run.inprocess import fcu_pipeline
    from sitl.plant import Plant

    scenario = load_scenario(CASE1)
    Plant(scenario.vehicle)
    fcu_pipeline(scenario)
    # Kernels compiled for a caller's types on first use (the mission executor samples a
    # rotation at many instants at once): flown here once, not first inside a real-time
    # flight of some test, where a compilation would stall the loop.
    from gcs.run.inprocess import apply_overrides, run_scenario

    run_scenario(apply_overrides(load_scenario(CASE1.parent / "mission_tour.toml"),
                                 duration_s=3.0), logs=False)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Under `--dist loadgroup` every xdist_group mark must reach the test's id (`@group`),
    or the groups the suite relies on (one campaign cluster at a time, one clock-discipline
    run at a time, one table1 build) would be scattered over the workers without a word:
    pytest 9.2 with pytest-xdist 3.8 did that."""
    config = session.config
    if not getattr(config.option, "loadgroup", False):
        return
    lost = [item.nodeid for item in session.items
            if any(True for _ in item.iter_markers("xdist_group")) and "@" not in item.nodeid]
    if lost:
        raise pytest.UsageError(f"--dist loadgroup lost the xdist_group of {len(lost)} tests "
                                f"(e.g. {lost[0]}): this pytest and pytest-xdist disagree")
