"""One composition everywhere: `gcs run --in-process` and `gcs run` through sitl and fcu
processes fly the same pipeline, so the same scenario gives the same status, events and
figures either way (the in-process runner applies the simulator link's float32 rounding)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from common.logs.ulog import read_topic

from .waits import file_size, run_progressing

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"
LINK_NOTICES = ("simulator not responding", "simulator responding again")


def _run(scenario: str, out: Path, *extra: str) -> dict:
    """`gcs run` of a scenario, waited for while its truth log grows or `gcs` works (in
    process the logs are written at the end): a loaded machine makes the lockstep flight
    slower, never different (at a load of 8 on 2 cores the mission tour through processes
    took over 280 s)."""
    proc = run_progressing([sys.executable, "-m", "gcs.cli", "run", str(SCENARIOS / scenario),
                            "--out", str(out), *extra], lambda: file_size(out / "truth.ulg"),
                           f"gcs run {scenario}", cpu=True, cwd=ROOT)
    metrics = json.loads((out / "metrics.json").read_text())
    assert proc.returncode == (0 if metrics["status"] == "completed" else 1), proc.stderr
    return metrics


def _events(m: dict) -> list[tuple]:
    return [(round(e["t_s"], 6), e["severity"], e["text"], e["kind"]) for e in m["events"]
            if e["text"] not in LINK_NOTICES]


@pytest.mark.slow
@pytest.mark.timeout(3600)  # a ceiling: each run is judged by its progress (_run)
@pytest.mark.parametrize(("scenario", "duration"), [("case1_figure8.toml", "30"),
                                                    ("mission_tour.toml", None)])
def test_in_process_equals_processes(tmp_path, scenario, duration):
    """Given a scenario (Case I; a mission with takeoff, waypoints, a keyframe, the
    figure-infinity and a landing), when flown in-process and through processes, then the
    status, the events and every figure agree, and so do the logs sample for sample."""
    cut = ("--duration", duration) if duration else ()
    ip = _run(scenario, tmp_path / "ip", "--in-process", *cut)
    pr = _run(scenario, tmp_path / "pr", *cut)
    assert ip["status"] == pr["status"]
    assert ip["mission_completed"] == pr["mission_completed"]
    assert _events(ip) == _events(pr)
    for key in ("position_error_m", "attitude_error_rad"):
        for stat in ("max", "mean", "rmse"):
            assert ip[key][stat] == pytest.approx(pr[key][stat], rel=1e-9, abs=1e-12), key
    assert ip["samples"] == pr["samples"] and ip["saturated_steps"] == pr["saturated_steps"]
    for name, topic in (("truth.ulg", "dq_truth"), ("onboard.ulg", "dq_onboard")):
        cols, a = read_topic(tmp_path / "ip" / name, topic)
        _, b = read_topic(tmp_path / "pr" / name, topic)
        keep = [i for i, c in enumerate(cols) if c != "step_us"]
        assert a.shape == b.shape, name
        assert np.array_equal(a[:, keep], b[:, keep]), name
