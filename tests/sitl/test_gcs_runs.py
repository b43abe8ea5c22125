"""The `gcs` CLI's in-process runs as a program: `gcs run` writes metrics.json and the
logs, reports a divergence with finite figures, takes overrides and refuses a broken file;
`gcs table1` writes the table beside the paper's values."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from common.logs.ulog import read_topic
from gcs.report.table1 import PAPER

from ..closed_loop.conftest import ROOT, SCENARIOS

DESIGN_KEYS = {"scenario", "controller", "lockstep", "transport", "sim_time_s", "wall_time_s",
               "control_rate_hz", "physics_rate_hz", "position_error_m", "attitude_error_rad",
               "fcu_step_us", "deadline_misses", "mission_completed", "status"}


def _gcs(*args: str, timeout: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT, timeout=timeout,
                          capture_output=True, text=True, check=False)


def _all_finite(obj) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(_all_finite(v) for v in obj.values())
    return True


def test_gcs_run_writes_metrics_for_a_completed_run(tmp_path):
    """Given `gcs run --in-process --duration`, then metrics.json has the DESIGN keys,
    status completed, and the logs are written beside it."""
    out = tmp_path / "run"
    proc = _gcs("run", str(SCENARIOS / "case1_figure8.toml"), "--in-process",
                "--duration", "3", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert DESIGN_KEYS <= set(m)
    assert m["status"] == "completed" and m["transport"] == "in-process" and m["lockstep"]
    assert m["sim_time_s"] == pytest.approx(3.0)
    assert m["control_rate_hz"] == 500 and m["physics_rate_hz"] == 1000
    columns, truth = read_topic(out / "truth.ulg", "dq_truth")
    assert columns[0] == "time_us" and truth[-1, 0] == 3_000_000
    columns, onboard = read_topic(out / "onboard.ulg", "dq_onboard")
    assert len(onboard) == len(truth) == 1501 and "tilt_raw5" in columns
    assert (out / "scenario.toml").read_text() == (SCENARIOS / "case1_figure8.toml").read_text()


def test_gcs_run_reports_divergence_with_finite_figures(tmp_path):
    """Given the PD baseline under the sinusoidal disturbance with rate-limited tilt servos,
    then the vehicle is lost: its attitude first (above 2 rad for 1 s: status diverged, the
    figures finite up to that instant), then its position (the FCU's divergence event).
    Both happen before 5 s (at 4.1 and 4.2 s): 8 s of the 60 s scenario show them, and the
    world running on after them."""
    out = tmp_path / "lost"
    proc = _gcs("run", str(SCENARIOS / "case2_sine.toml"), "--in-process", "--controller",
                "pd", "--duration", "8", "--out", str(out))
    assert proc.returncode == 1
    text = (out / "metrics.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    m = json.loads(text)
    assert m["status"] == "diverged" and m["mission_completed"] is False
    assert m["divergence_t_s"] < 5.0 and m["sim_time_s"] == 8.0  # the world runs on
    assert any(e["kind"] == "diverged" for e in m["events"])
    assert "attitude error above" in m["status_reason"]
    assert m["attitude_error_rad"]["max"] > 3.0 and m["position_error_m"]["max"] > 5.0
    assert _all_finite(m)


def test_gcs_overrides_and_bad_config(tmp_path):
    """--controller and --ideal-actuators override the scenario; a broken file is refused."""
    out = tmp_path / "pd"
    proc = _gcs("run", str(SCENARIOS / "case2_sine.toml"), "--in-process", "--controller",
                "pd", "--ideal-actuators", "--duration", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["controller"] == "pd" and m["ideal_actuators"] is True and m["damping"] == "twist"

    bad = tmp_path / "bad.toml"
    bad.write_text((SCENARIOS / "case2_sine.toml").read_text().replace(
        "duration_s = 60.0", "duration_s = \"long\""))
    proc = _gcs("run", str(bad), "--in-process", "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert "duration_s" in proc.stderr and "number" in proc.stderr


def test_gcs_table1_writes_markdown_and_json(tmp_path):
    """Given `gcs table1 --in-process`, then the 8 runs land in table1.md/json beside the
    paper's values."""
    out = tmp_path / "t1"
    proc = _gcs("table1", "--in-process", "--duration", "1.5", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    table = json.loads((out / "table1.json").read_text())
    assert len(table["rows"]) == 8
    assert {(r["scenario"], r["controller"]) for r in table["rows"]} == {
        (s, c) for s in PAPER for c in ("pid", "pd")}
    row = next(r for r in table["rows"] if r["scenario"] == "case1_figure8"
               and r["controller"] == "pid")
    assert row["paper"]["position_error_m"]["max"] == 0.0694
    md = (out / "table1.md").read_text()
    assert "0.0694" in md and md.count("\n| ") == 8 * 3 + 1
