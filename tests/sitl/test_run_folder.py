"""A run folder holds one run and says how it ended: non-empty folders are refused unless
--force, Ctrl-C leaves an aborted run, and a report refuses logs from another run."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from gcs.report.run_metrics import RunMetrics, metrics_from_json

from ..terminal import sigint_default

ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"


def _gcs(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, check=False)


def _flown_s(tlog: Path) -> float:
    """The newest flight-clock time (s) in the run's telemetry so far: LOCAL_POSITION_NED's
    time_boot_ms, which stays 0 until the flight starts (lockstep)."""
    if not tlog.exists():
        return 0.0
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    newest = 0.0
    try:
        while (msg := log.recv_match(type="LOCAL_POSITION_NED")) is not None:
            newest = max(newest, msg.time_boot_ms / 1000.0)
    finally:
        log.close()
    return newest


@pytest.mark.timeout(240)
def test_one_run_per_folder(tmp_path):
    """Given a folder holding anything, then `gcs run` refuses it (exit 2) and touches
    nothing; with --force it empties it first; a report refuses logs of another run."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    refused = _gcs("run", str(CASE1), "--in-process", "--duration", "2", "--out", str(out))
    assert refused.returncode == 2 and "not empty" in refused.stderr
    assert (out / "notes.txt").read_text() == "mine"
    first = _gcs("run", str(CASE1), "--in-process", "--duration", "2", "--out", str(out),
                 "--force")
    assert first.returncode == 0, first.stderr
    assert not (out / "notes.txt").exists()
    other = tmp_path / "other"
    assert _gcs("run", str(CASE1), "--in-process", "--duration", "3", "--out",
                str(other)).returncode == 0
    shutil.copyfile(other / "truth.ulg", out / "truth.ulg")
    report = _gcs("report", str(out))
    assert report.returncode == 2 and "truth.ulg" in report.stderr
    onto_file = _gcs("run", str(CASE1), "--in-process", "--out", str(out / "notes"),
                     "--duration", "1")
    assert onto_file.returncode == 0  # a new folder inside is fine
    (tmp_path / "afile").write_text("x")
    assert _gcs("run", str(CASE1), "--in-process", "--out",
                str(tmp_path / "afile")).returncode == 2


@pytest.mark.timeout(180)
def test_ctrl_c_leaves_an_aborted_run(tmp_path):
    """Given a run through processes, when the ground station gets SIGINT mid-flight, then
    it stops its children, writes metrics.json with status aborted and exits 1."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "run", str(CASE1), "--out",
                             str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=sigint_default)
    try:
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline and _flown_s(out / "flight.tlog") < 1.0:
            time.sleep(0.2)  # the flight's start: simulated time stands still before it
        assert _flown_s(out / "flight.tlog") >= 1.0, "the flight did not start in 90 s"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1, err
    m = metrics_from_json(json.loads((out / "metrics.json").read_text()))
    assert m.keys() <= RunMetrics.__annotations__.keys()  # the record holds every key written
    assert m["status"] == "aborted" and "interrupted" in m["error"]
    assert 0.0 < m["sim_time_s"] < 160.0 and m["wall_time_s"] > 0.0
    for log in ("sitl.log", "fcu.log"):
        assert "stopped" in (out / log).read_text()  # each child stopped cleanly
