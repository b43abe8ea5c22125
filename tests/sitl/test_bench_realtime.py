"""benchmarks/bench_realtime.py, shortened: real sitl and fcu processes in real time, two
ground stations with a 20-item upload, its download, the parameter list, 2 OFFBOARD steps,
a few mode changes and a log rotation (SIGHUP) while hovering, no busy processes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from common.logs.ulog import read_topic

from .conftest import ROOT

pytestmark = pytest.mark.timeout(240)
BENCH = ROOT / "benchmarks" / "bench_realtime.py"
FIGURE_KEYS = ("p50_ms", "p99_ms", "p999_ms", "longest_gap_ms", "deadline_misses",
               "deadline_misses_pct", "max_position_error_m", "max_attitude_error_deg")


def test_short_benchmark_flies_its_timeline_airborne_and_reports_every_figure(tmp_path):
    """Given the benchmark shortened (20 items, 2 OFFBOARD steps, POSCTL, OFFBOARD and
    HOLD, idle only), when it runs, then it exits 0, every piece of ground-station work of
    both stations and the log rotation succeeded, the JSON holds every figure (numbers), and
    the onboard logs (both files of the rotation) show the vehicle armed and above 0.5 m at
    every control step of the timeline, the steps covering it without a pause of 0.5 s."""
    out = tmp_path / "figures.json"
    proc = subprocess.run(
        [sys.executable, str(BENCH), "--loads", "idle", "--items", "20",
         "--offboard-steps", "2", "--modes", "POSCTL,OFFBOARD,HOLD", "--hover-s", "1",
         "--json", str(out), "--out", str(tmp_path / "runs")],
        cwd=ROOT, capture_output=True, text=True, timeout=220)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    report = json.loads(out.read_text())
    assert set(report["targets"]) == {"idle", "hogs"}
    (result,) = report["results"]
    assert result["condition"] == "idle" and not result["failure"]
    figures = result["figures"]
    for key in FIGURE_KEYS:
        assert isinstance(figures[key], int | float), (key, figures[key])
    events = result["run"]["events"]
    stations = {e["station"] for e in events} - {0}  # 0: the benchmark's own (SIGHUP)
    assert stations == {255, 254}
    assert [e["what"] for e in events if e["station"] == 0] == ["log rotation (SIGHUP to fcu)"]
    failed = [e for e in events if not e["ok"]]
    assert not failed, failed
    for station in stations:
        done = [e["what"] for e in events if e["station"] == station]
        assert "mission upload (20 items)" in done and "mission download" in done
        assert "parameter list" in done
        assert [w for w in done if w.startswith("mode ")][-1] == "mode HOLD"
    assert figures["airborne"] is True
    assert result["run"]["rotated"] and figures["onboard_logs"] == 2

    # Airborne throughout, judged again here from the log (not from wall time).
    marks = result["run"]["marks"]
    start, end = marks["start_us"], marks["end_us"]
    assert end - start > 5e6  # the timeline: uploads, 2 s of OFFBOARD, 3 modes
    folder = tmp_path / "runs" / "idle"
    parts = [read_topic(folder / name, "dq_onboard") for name in ("onboard.1.ulg",
                                                                   "onboard.ulg")]
    columns = parts[0][0]
    rows = np.concatenate([r for _, r in parts])
    c = {name: i for i, name in enumerate(columns)}
    t = rows[:, c["time_us"]]
    sel = rows[(t >= start) & (t <= end)]
    stamps = np.concatenate(([start], np.unique(sel[:, c["time_us"]]), [end]))
    assert np.diff(stamps).max() < 0.5e6
    assert sel[:, c["pz"]].min() > 0.5
    assert sel[:, c["armed"]].min() == 1.0
