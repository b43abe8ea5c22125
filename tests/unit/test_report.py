"""Run reports: the paper's figures and report.md from a run folder, and the Table I chart."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import struct
import tomllib
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.logs.ulog import Topic, ULogWriter, read_topic
from gcs.report.chart import table1_chart
from gcs.report.disturbance_figures import disturbance_profile
from gcs.report.names import (
    FIG3,
    FIG4,
    FIG6,
    FIG78,
    REPORT,
)
from gcs.report.plot import thin_indices
from gcs.report.run_report import make_report
from gcs.report.table1 import CASES, CONTROLLERS, PAPER, table_json
from gcs.run.inprocess import run_scenario
from gcs.run.overrides import apply_overrides
from gcs.run.runio import RunDirError, write_metrics, write_run
from sitl.disturbance import Disturbance

from ..closed_loop.conftest import SCENARIOS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _run(out: Path, name: str, **overrides) -> Path:
    scenario = apply_overrides(load_scenario(SCENARIOS / f"{name}.toml"), **overrides)
    write_run(out, scenario, run_scenario(scenario))
    return out


@pytest.fixture(scope="module")
def case1_dir(tmp_path_factory) -> Path:
    return _run(tmp_path_factory.mktemp("case1"), "case1_figure8", duration_s=25.0)


@pytest.fixture(scope="module")
def impulse_dir(tmp_path_factory) -> Path:
    # 8 s: the torque pulse (5-7 s) is in, the force pulse (20-22 s) is not.
    return _run(tmp_path_factory.mktemp("impulse"), "case2_impulse", duration_s=8.0)


@pytest.fixture(scope="module")
def diverged_dir(tmp_path_factory) -> Path:
    # 8 s: PD diverges at 4.1 s, and the run's figures stop there (60 s give the same).
    out = _run(tmp_path_factory.mktemp("sine_pd"), "case2_sine", controller="pd",
               duration_s=8.0)
    assert json.loads((out / "metrics.json").read_text())["status"] == "diverged"
    return out


def _assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, path
    assert len(data) > 10_000, path
    width, height = struct.unpack(">II", data[16:24])  # IHDR
    assert 1400 <= width <= 2200 and height >= 600, (path, width, height)


def _assert_metrics_in(text: str, metrics: dict) -> None:
    for key in ("position_error_m", "attitude_error_rad"):
        for stat in ("max", "mean", "rmse"):
            assert f"{metrics[key][stat]:.4g}" in text, (key, stat)
    assert f"{metrics['fcu_step_us']['p50']:.4g}" in text
    assert f"{metrics['fcu_step_us']['p99']:.4g}" in text


def test_case1_report(case1_dir):
    """Given a short Case I run, when reported, then Fig. 3, 4 and 6 are valid PNGs (no
    disturbance figure) and report.md links them and carries the metrics beside the paper."""
    paths = make_report(case1_dir)
    names = [p.name for p in paths]
    assert names == [FIG3, FIG4, FIG6, REPORT]
    for path in paths[:-1]:
        assert path.parent == case1_dir / "figures"
        _assert_png(path)
    assert not (case1_dir / "figures" / FIG78).exists()
    text = (case1_dir / REPORT).read_text()
    for name in names[:-1]:
        assert f"(figures/{name})" in text
    metrics = json.loads((case1_dir / "metrics.json").read_text())
    _assert_metrics_in(text, metrics)
    for value in (*PAPER["case1_figure8"]["pid"][0], *PAPER["case1_figure8"]["pid"][1]):
        assert f"{value:.4f}" in text
    assert "case1_figure8" in text and "PID" in text and "completed" in text
    assert "in-process" in text and "lockstep: true" in text
    assert "cut short" in text  # 25 s of a 160 s scenario


def test_impulse_report_has_disturbance_figure(impulse_dir):
    """Given 8 s of Case II impulse, then Fig. 7/8 is drawn too and report.md names the
    pulse."""
    paths = make_report(impulse_dir)
    assert [p.name for p in paths] == [FIG3, FIG4, FIG6, FIG78, REPORT]
    for path in paths[:-1]:
        _assert_png(path)
    text = (impulse_dir / REPORT).read_text()
    assert f"(figures/{FIG78})" in text
    assert "pulse" in text and "[5.0, 7.0)" in text
    _assert_metrics_in(text, json.loads((impulse_dir / "metrics.json").read_text()))


def test_diverged_run_still_reports(diverged_dir):
    """Given Case II sine with PD (diverges at ~4.1 s), then every figure is drawn and
    report.md says the run diverged and when."""
    paths = make_report(diverged_dir)
    assert [p.name for p in paths] == [FIG3, FIG4, FIG6, FIG78, REPORT]
    for path in paths[:-1]:
        _assert_png(path)
    metrics = json.loads((diverged_dir / "metrics.json").read_text())
    text = (diverged_dir / REPORT).read_text()
    assert "**diverged**" in text
    assert f"diverged at t = {metrics['divergence_t_s']:.4g} s" in text
    _assert_metrics_in(text, metrics)


def test_non_finite_rows_are_dropped(diverged_dir, tmp_path):
    """Given a diverged run whose logs end in NaN rows (a process run's last samples), then
    the report leaves them out and says so."""
    out = tmp_path / "nan_tail"
    shutil.copytree(diverged_dir, out, ignore=shutil.ignore_patterns("figures", REPORT))
    for log, topic in (("truth.ulg", "dq_truth"), ("onboard.ulg", "dq_onboard")):
        columns, rows = read_topic(out / log, topic)
        tail = np.full((5, rows.shape[1]), np.nan)
        for i, name in enumerate(columns):  # the times stay times (dq_onboard has two)
            if i == 0 or name == "state_time_us":
                tail[:, i] = rows[-1, i] + 2000.0 * np.arange(1, 6)
        layout = Topic(topic, (("uint64_t", "timestamp"), *(("double", c) for c in columns[1:])))
        writer = ULogWriter(out / log, [layout])
        for row in np.vstack([rows, tail]):
            writer.add(topic, (int(row[0]), *row[1:]))
        writer.close()
    with pytest.raises(RunDirError):  # these are not the logs metrics.json was made from
        make_report(out)
    write_metrics(out, json.loads((out / "metrics.json").read_text()))
    paths = make_report(out)
    assert len(paths) == 5 and all(p.exists() for p in paths)
    text = (out / REPORT).read_text()
    assert "logged rows left out" in text and "(5 with non-finite values" in text


@pytest.mark.parametrize("name", ["case2_impulse", "case2_sine", "case2_irregular"])
def test_disturbance_profile_matches_the_plant(name):
    """Given a Case II scenario, then the profile drawn in Fig. 7/8 is the wrench the plant
    applies (sitl.disturbance) at every instant."""
    tables = tomllib.loads((SCENARIOS / f"{name}.toml").read_text())["disturbance"]
    scenario = load_scenario(SCENARIOS / f"{name}.toml")
    plant = Disturbance(scenario.force_terms, scenario.torque_terms)
    t = np.concatenate([np.linspace(0.0, 60.0, 601), [5.0, 7.0, 20.0, 22.0, 6.999, 21.999]])
    force = disturbance_profile(tables.get("force", []), t)
    torque = disturbance_profile(tables.get("torque", []), t)
    expected = np.array([np.concatenate(plant.wrench(x)) for x in t])
    np.testing.assert_allclose(np.hstack([force, torque]), expected, atol=1e-12)


def test_thinning_keeps_peaks():
    """Given 80k samples with a one-sample spike and dip, then the thinned indices are
    sorted, far fewer, and keep both extremes and the ends."""
    rng = np.random.default_rng(0)
    y = rng.normal(size=(80_000, 2))
    y[12_345, 0], y[54_321, 1] = 50.0, -50.0
    idx = thin_indices(y)
    assert np.all(np.diff(idx) > 0) and len(idx) < 12_000
    assert {0, 12_345, 54_321, 79_999} <= set(idx.tolist())
    assert np.array_equal(thin_indices(np.arange(100.0)), np.arange(100))


def _fake_metrics(scale: float, status: str = "completed") -> dict:
    def stats(x: float) -> dict:
        return {"max": 3 * x, "mean": x, "rmse": 1.2 * x}
    return {"status": status, "sim_time_s": 4.4 if status == "diverged" else 60.0,
            "position_error_m": stats(scale), "attitude_error_rad": stats(scale / 10)}


def test_table1_chart(tmp_path):
    """Given a synthetic Table I with a diverged row and a missing one, then a bar chart PNG
    is written."""
    results = {}
    for k, (_, scen) in enumerate(CASES):
        for ctrl in CONTROLLERS:
            if (scen, ctrl) == ("case2_irregular", "pd"):
                continue  # missing: drawn as n/a
            diverged = (scen, ctrl) == ("case2_sine", "pd")
            results[(scen, ctrl)] = _fake_metrics(10.0 ** (k - 3) * (2 if ctrl == "pd" else 1),
                                                  "diverged" if diverged else "completed")
    table = table_json(results)
    assert len(table["rows"]) == 7
    out = table1_chart(table, tmp_path / "sub" / "table1.png")
    assert out == tmp_path / "sub" / "table1.png"
    _assert_png(out)




def _gcs(*argv: str) -> tuple[int, str, str]:
    """`gcs ARGV...` in this process: (exit status, stdout, stderr)."""
    from gcs.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue(), err.getvalue()



def test_report_refuses_other_folders(tmp_path):
    """Given a folder that is neither a run folder nor a table1 folder, then exit 2."""
    (tmp_path / "notes.txt").write_text("hello\n")
    rc, stdout, stderr = _gcs("report", str(tmp_path))
    assert rc == 2 and stdout == ""
    assert "neither metrics.json" in stderr and "table1.json" in stderr
    rc, _, _ = _gcs("report", str(tmp_path / "absent"))
    assert rc == 2
