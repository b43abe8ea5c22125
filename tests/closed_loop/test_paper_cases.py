"""The paper's cases with the default actuators (lag, limits, 500 Hz); the `gcs` CLI's runs as a
program are in tests/sitl/test_gcs_runs.py."""

from __future__ import annotations

import pytest

from gcs.report.metrics import rank_key
from gcs.report.table1 import PAPER
from gcs.run.inprocess import run_scenario

from .. import reference_runs
from .conftest import scenario


@pytest.mark.xdist_group(reference_runs.GROUP)
def test_case1_pid_default_actuators_beats_table1():
    """Given Case I with rotor lag, rate-limited tilts and 500 Hz control, then the PID
    tracker is at or below the paper's Table I on all six figures."""
    m = reference_runs.case1_metrics()
    assert m["status"] == "completed" and m["sim_time_s"] == pytest.approx(160.0)
    pos, att = PAPER["case1_figure8"]["pid"]
    for stat, paper_pos, paper_att in zip(("max", "mean", "rmse"), pos, att, strict=True):
        assert m["position_error_m"][stat] <= paper_pos
        assert m["attitude_error_rad"][stat] <= paper_att
    # The resolved model allows millimetres (docs/model.md#scenarios): far inside the table.
    assert m["position_error_m"]["max"] < 0.01


@pytest.mark.parametrize("name", ["case2_sine", "case2_irregular"])
@pytest.mark.parametrize("ideal", [False, True])
def test_case2_pid_beats_pd_on_rmse(name, ideal):
    """Given the time-varying disturbances of Case II, then PID ranks above PD on position
    and attitude RMSE (with the default actuators PD loses the vehicle: it ranks last). Under
    the sinusoidal disturbance neither controller keeps its attitude (above 2 rad for 1 s:
    diverged, common.outcome, both before 5 s); up to its divergence PID's errors are still
    below PD's up to PD's."""
    # Under the sine both diverge before 5 s and a run's figures stop at its divergence
    # (gcs.report.metrics): 8 s of it give the 60 s run's figures, to the bit.
    cut = {"duration_s": 8.0} if name == "case2_sine" else {}
    pid = run_scenario(scenario(name, controller="pid", ideal_actuators=ideal, **cut)).metrics
    pd = run_scenario(scenario(name, controller="pd", ideal_actuators=ideal, **cut)).metrics
    if name == "case2_sine":
        assert pid["status"] == pd["status"] == "diverged"
        assert pid["divergence_t_s"] < 5.0 and pd["divergence_t_s"] < 5.0
        assert "attitude error above" in pid["status_reason"]
        assert pid["position_error_m"]["rmse"] < pd["position_error_m"]["rmse"]
        assert pid["attitude_error_rad"]["rmse"] < pd["attitude_error_rad"]["rmse"]
        assert rank_key(pid) < rank_key(pd)
        return
    assert pid["status"] == "completed"
    assert rank_key(pid) < rank_key(pd)
    if pd["status"] in ("completed", "limited"):  # ideal servos: the FCU's 4 rad/s model
        assert pid["position_error_m"]["rmse"] < pd["position_error_m"]["rmse"]
        assert pid["attitude_error_rad"]["rmse"] < pd["attitude_error_rad"]["rmse"]
    else:
        assert not ideal and pd["status"] == "diverged"
