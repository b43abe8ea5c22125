"""`gcs replay` on the onboard.ulg of a run through the processes (sitl and fcu over UDP in
lockstep, the estimator on the motion-capture profile): the log holds the estimator's
inputs and state topics at their rates, and the replay reproduces the logged estimate bit
for bit; a changed parameter makes it differ."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common.logs.ulog import open_ulog
from gcs.run.replay import STATE_COLUMNS

from .conftest import ROOT, SCENARIOS

CASE1 = SCENARIOS / "case1_figure8.toml"
RATES = {"sensor_combined": 1000, "vehicle_visual_odometry": 200, "estimator_states": 50,
         "estimator_innovations": 50, "estimator_innovation_test_ratios": 50,
         "estimator_status": 50}


def _gcs(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=240, check=False)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("replay") / "run"
    proc = _gcs("run", str(CASE1), "--sensors", "mocap-indoor", "--duration", "4",
                "--out", str(out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert json.loads((out / "metrics.json").read_text())["transport"] == "udp"
    return out


@pytest.mark.timeout(300)
def test_the_process_log_holds_the_estimator_topics_at_their_rates(run_dir):
    u = open_ulog(run_dir / "onboard.ulg")
    assert not u.file_corruption
    for name, rate in RATES.items():
        ts = u.get_dataset(name).data["timestamp"].astype(np.int64)
        assert np.all(np.diff(ts) > 0), name
        assert (len(ts) - 1) / ((ts[-1] - ts[0]) * 1e-6) == pytest.approx(rate, rel=0.01), name
    # the FCU process opened its log before the estimator was switched on
    assert u.initial_parameters["EKF_EN"] == 0.0
    assert ("EKF_EN", 1.0) in [(n, v) for _, n, v in u.changed_parameters]


@pytest.mark.timeout(300)
def test_replay_of_the_process_log(run_dir, tmp_path):
    log = str(run_dir / "onboard.ulg")
    proc = _gcs("replay", log, "--out", str(tmp_path / "r.json"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "bit-identical" in proc.stdout
    doc = json.loads((tmp_path / "r.json").read_text())
    logged = open_ulog(run_dir / "onboard.ulg", ["dq_onboard"]).get_dataset("dq_onboard").data
    rows = np.array(doc["rows"], dtype=float)
    assert np.array_equal(rows[:, 0], logged["timestamp"].astype(float))
    for k, c in enumerate(STATE_COLUMNS):
        assert np.array_equal(rows[:, 1 + k], logged[c]), c
    proc = _gcs("replay", log, "--param", "EKF_EVP_NOISE=0.01")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "position difference" in proc.stdout
    proc = _gcs("replay", str(run_dir / "truth.ulg"))
    assert proc.returncode == 2 and "gcs replay:" in proc.stderr
