"""An honest outcome, flown in-process: a flight the actuator monitor reported at a limit
ends `limited` and `gcs run` exits 1 for it; the errors of a landing leave out the rows on
the ground with the set-point sunk below it (metrics.json's error_rows), and Case I's climb
from the ground still counts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario
from gcs import cli
from gcs.report.metrics import ERROR_ROWS_RULE
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides

from .. import reference_runs
from .conftest import SCENARIOS
from .test_actuator_limits import LEG

# LEG: a takeoff to 3 m, then a 2 m leg in 1 s flown as timed (the envelope check off)


def _leg_scenario(tmp_path: Path) -> Path:
    (tmp_path / "leg.toml").write_text(LEG)
    tour = (SCENARIOS / "mission_tour.toml").read_text()
    text = tour.replace('name = "mission_tour"', 'name = "leg"') \
        .replace("duration_s = 60.0", "duration_s = 8.0") \
        .replace('"../vehicles/', f'"{SCENARIOS.parent}/vehicles/') \
        .replace('"../gains/', f'"{SCENARIOS.parent}/gains/') \
        .replace('mission = "../missions/tour.toml"', 'mission = "leg.toml"')
    path = tmp_path / "leg_scenario.toml"
    path.write_text(text + "\n[params]\nMIS_ENV_CHK = 0\nMIS_TKO_SPD = 1.875\n"
                    "MIS_CRUISE_SPD = 3.75\n")  # the leg in 1 s, the climb in 3 s
    return path


def test_gcs_run_of_a_limited_flight_says_limited_and_exits_1(tmp_path, capsys):
    """Given the leg beyond the tilt rate, when `gcs run --in-process` flies it to its end,
    then metrics.json says limited with the first report as the reason, the first line
    printed says so, and the exit status is 1 (not completed); no failsafe, no
    divergence."""
    out = tmp_path / "out"
    code = cli.main(["run", str(_leg_scenario(tmp_path)), "--in-process", "--out", str(out)])
    m = json.loads((out / "metrics.json").read_text())
    assert code == 1, m["status_reason"]
    assert m["status"] == "limited" and m["failsafe"] == "" and m["divergence_t_s"] is None
    assert m["sim_time_s"] >= 8.0 and m["mission_completed"]
    first = min((e for e in m["events"] if e["kind"] == "limit"), key=lambda e: e["t_s"])
    assert " rate-limited " in first["text"]
    assert m["status_reason"].startswith(f"actuator limit at t = {first['t_s']:.3f} s: "
                                         f"{first['text']}")
    assert capsys.readouterr().out.splitlines()[0] == \
        f"leg [pid] limited ({m['status_reason']})"


@pytest.mark.xdist_group(reference_runs.TOUR_GROUP)
def test_a_landing_is_judged_in_the_air_not_pressed_into_the_ground():
    """Given the tour mission (it lands and disarms), then its errors are those of the rows
    error_rows counts, which are every joined row but those on the ground (the plant's
    contact) with the set-point below it; recomputed here from the logs, and within
    centimetres (counting the ground rows gave 0.151 m: the landing set-point's sink)."""
    r = reference_runs.tour_run()  # flown once with test_landing's
    m = r.metrics
    assert m["status"] == "completed" and m["mission_completed"], m["status_reason"]
    rows = m["error_rows"]
    assert rows["rule"] == ERROR_ROWS_RULE
    assert rows["counted"] + rows["on_ground_reference_below"] == m["samples"]
    t_truth = r.truth_col("time_us")[:, 0]
    t_onb = r.onboard_col("time_us")[:, 0]
    at = np.searchsorted(t_truth, t_onb)
    assert np.array_equal(t_truth[at], t_onb) and len(t_onb) == m["samples"]
    p = r.truth_col("px", "py", "pz")[at]
    landed = r.truth_col("landed")[at, 0] > 0.5
    p_d = r.onboard_col("pdx", "pdy", "pdz")
    err = np.linalg.norm(p - p_d, axis=1)
    left_out = landed & (p_d[:, 2] < 0.0)
    assert int(np.sum(left_out)) == rows["on_ground_reference_below"]
    assert m["position_error_m"]["max"] == float(np.max(err[~left_out]))
    assert np.any(landed & ~left_out)  # the rest before the take-off counts
    assert m["position_error_m"]["max"] < 0.02


def test_case1_climb_from_the_ground_counts():
    """Given Case I's first 2 s (on the ground, rotors stopped, the reference rising), then
    its rows on the ground count: every joined row is counted."""
    r = run_scenario(apply_overrides(load_scenario(SCENARIOS / "case1_figure8.toml"),
                                     duration_s=2.0), logs=False)
    m = r.metrics
    assert np.sum(r.truth_col("landed") > 0.5) > 10  # it rests before it lifts off
    assert m["error_rows"] == {"rule": ERROR_ROWS_RULE, "counted": m["samples"],
                               "on_ground_reference_below": 0}
