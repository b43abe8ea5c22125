"""The flight's figures pinned: Case I (truth sensors, default actuators) with PID and PD,
Case II's sinusoidal disturbance and Case I on the mocap-indoor profile (estimator on, its
first 30 s) give the figures recorded in tests/data/reference_figures.json to 1e-9
relative. They were recorded before the flight core was compiled (numba), so any change
of the maths' result (a sign, a dropped term, another order of operations beyond
rounding) shows here."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from common.config.scenario import load_scenario
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides

from .. import reference_runs
from .conftest import SCENARIOS

FIGURES = json.loads(
    (Path(__file__).resolve().parents[1] / "data" / "reference_figures.json").read_text())
REL = 1e-9


def assert_same(got: Any, want: Any, path: str = "") -> None:
    if isinstance(want, dict):
        assert set(got) >= set(want), path
        for key, value in want.items():
            assert_same(got[key], value, f"{path}.{key}")
    elif isinstance(want, float) and not isinstance(got, bool):
        assert math.isclose(got, want, rel_tol=REL, abs_tol=0.0), (path, got, want)
    else:
        assert got == want, (path, got, want)


@pytest.mark.xdist_group(reference_runs.GROUP)
def test_case1_pid_figures_are_pinned():
    assert_same(reference_runs.case1_metrics(), FIGURES["case1_pid"])


@pytest.mark.parametrize(("name", "overrides"), [
    ("case1_pd", {"scenario": "case1_figure8", "controller": "pd"}),
    ("case2_sine_pid", {"scenario": "case2_sine", "controller": "pid"}),
    ("case1_mocap_indoor_30s", {"scenario": "case1_figure8", "controller": "pid",
                                "sensors": "mocap-indoor", "duration_s": 30.0}),
])
def test_figures_are_pinned(name, overrides):
    options = dict(overrides)
    base = load_scenario(SCENARIOS / f"{options.pop('scenario')}.toml")
    m = run_scenario(apply_overrides(base, **options), logs=False).metrics
    assert_same(m, FIGURES[name])
