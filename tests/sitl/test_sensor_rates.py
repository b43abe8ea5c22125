"""Motion capture off the physics grid through the processes: a 120 Hz and a 100 Hz
(jittered) profile fly Case I in `sitl` + `fcu` and in-process with the same figures and
logs, within the exact-state run's error and a few centimetres; a profile the plant cannot
serve is exit 2 before any process starts."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common.logs.ulog import read_topic

ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"
INDOOR = ROOT / "config" / "sensors" / "mocap-indoor.toml"
DURATION = "10"
MOCAP_RATE = "rate_hz = 200.0  # Qualisys"
TOLERANCE_M, TOLERANCE_RAD = 0.03, 0.02  # beyond the exact state's tracking error


def _profile(tmp_path: Path, name: str, mocap_lines: str) -> Path:
    text = INDOOR.read_text()
    assert MOCAP_RATE in text
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace(MOCAP_RATE, mocap_lines + "  #"))
    return path


def _gcs_run(out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "gcs.cli", "run", str(CASE1), "--out",
                           str(out), "--duration", DURATION, *extra], cwd=ROOT,
                          capture_output=True, text=True, timeout=200)


def _flown(out: Path, *extra: str) -> dict:
    proc = _gcs_run(out, *extra)
    assert proc.returncode == 0, proc.stderr
    metrics: dict = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "completed"
    return metrics


@pytest.mark.timeout(300)
@pytest.mark.parametrize("profile", ["mocap-120hz", "100hz-jittered"])
def test_off_grid_motion_capture_flies_case1_the_same_in_process_and_through_processes(
        tmp_path, profile):
    """Given mocap-120hz (frames every 8333.3 us) or a 100 Hz capture jittered by up to
    2 ms, when Case I flies in-process and through sitl and fcu, then the figures agree to
    1e-9, the logs sample for sample, and the errors stay within the exact state's and a
    few centimetres."""
    sensors = profile if profile.startswith("mocap") else str(
        _profile(tmp_path, profile, "rate_hz = 100.0\njitter_s = 0.002\n"))
    ip = _flown(tmp_path / "ip", "--in-process", "--sensors", sensors)
    pr = _flown(tmp_path / "pr", "--sensors", sensors)
    truth = _flown(tmp_path / "truth", "--in-process", "--sensors", "truth")
    for key in ("position_error_m", "attitude_error_rad"):
        for stat in ("max", "mean", "rmse"):
            assert ip[key][stat] == pytest.approx(pr[key][stat], rel=1e-9, abs=1e-12), key
    assert ip["samples"] == pr["samples"]
    assert ip["position_error_m"]["max"] <= truth["position_error_m"]["max"] + TOLERANCE_M
    assert ip["attitude_error_rad"]["max"] <= \
        truth["attitude_error_rad"]["max"] + TOLERANCE_RAD
    for name, topic in (("truth.ulg", "dq_truth"), ("onboard.ulg", "dq_onboard")):
        cols, a = read_topic(tmp_path / "ip" / name, topic)
        _, b = read_topic(tmp_path / "pr" / name, topic)
        keep = [i for i, c in enumerate(cols) if c != "step_us"]
        assert a.shape == b.shape, name
        assert np.array_equal(a[:, keep], b[:, keep]), name


@pytest.mark.timeout(120)
def test_a_profile_the_plant_cannot_serve_is_exit_2_before_any_process_starts(tmp_path):
    """A 5 kHz motion capture on the 1 ms physics step: gcs run (processes and in-process,
    by --sensors or the scenario's key) and sitl refuse it with one line naming the file and
    the key; no run folder, so no metrics.json of a run that never flew."""
    fast = _profile(tmp_path, "mocap-fast", "rate_hz = 5000.0\n")
    want = f"{fast}: mocap.rate_hz = 5000 is faster than the physics step allows"
    text = CASE1.read_text().replace("seed = 0\n", f'seed = 0\nsensors = "{fast}"\n')
    for key in ("vehicle", "pid", "pd"):
        text = text.replace(f'{key} = "../', f'{key} = "{CASE1.parent.parent}/')
    scenario = tmp_path / "case1_fast.toml"
    scenario.write_text(text)
    runs = [[str(CASE1), "--sensors", str(fast)],
            [str(CASE1), "--sensors", str(fast), "--in-process"],
            [str(scenario)], [str(scenario), "--in-process"]]
    for i, args in enumerate(runs):
        out = tmp_path / f"run{i}"
        proc = subprocess.run([sys.executable, "-m", "gcs.cli", "run", *args, "--out",
                               str(out)], cwd=ROOT, capture_output=True, text=True,
                              timeout=60)
        assert proc.returncode == 2, (args, proc.stderr)
        assert proc.stderr.strip().splitlines() == [f"gcs run: {want} (1000 us: at most "
                                                    "1000 Hz)"], args
        assert not out.exists(), args
    proc = subprocess.run([sys.executable, "-m", "sitl.node", str(CASE1), "--sensors",
                           str(fast), "--link", "udpin:127.0.0.1:0"], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and want in proc.stderr and "serving" not in proc.stdout
