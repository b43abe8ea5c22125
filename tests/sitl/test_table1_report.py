"""A table1 folder (`gcs table1`'s runs in worker processes, then `gcs report`): every run's
report, Table I, Figs. 5, 7 and 8, and a partial folder."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from gcs.report.disturbance_figures import fig7_8_figure
from gcs.report.names import FIG3, FIG4, FIG5, FIG6, FIG7, FIG8, FIG78, FIG_DIR, REPORT, TABLE1_PNG
from gcs.report.rundata import load_run
from gcs.report.table1 import CASES, CONTROLLERS, PAPER
from gcs.report.tracking_figures import fig5_figure

from ..closed_loop.conftest import SCENARIOS
from ..unit.test_report import _assert_png, _gcs

TABLE1_S = 8.0  # includes the impulse case's torque pulse (5-7 s); PD diverges in two cases,
# PID in one (the sine: its attitude error above 2 rad for 1 s)
RUN_NAMES = [f"{scen}_{ctrl}" for _, scen in CASES for ctrl in CONTROLLERS]


@pytest.fixture(scope="session")  # its tests share one xdist group (one worker): built once
def table1_dir(tmp_path_factory) -> Path:  # (module scope was torn down between them)
    """`gcs table1 --in-process --duration 8` (through run_table1), then `gcs report` on it."""
    from gcs.run.table1_run import run_table1

    out = tmp_path_factory.mktemp("table1") / "t1"
    run_table1(SCENARIOS, out, in_process=True, duration_s=TABLE1_S, workers=2)
    for name in RUN_NAMES:  # no report yet: the fixture's report is the one tested
        assert not (out / name / REPORT).exists()
    rc, stdout, stderr = _gcs("report", str(out))
    assert rc == 0, stderr
    assert stderr == ""
    assert str(out / REPORT) in stdout.splitlines()
    return out


def _links(md: str) -> list[str]:
    return re.findall(r"\]\(([^)\s]+)\)", md)


def _row(text: str, name: str) -> str:
    rows = [line for line in text.splitlines() if f"[{name}]({name}/{REPORT})" in line
            and line.startswith("|")]
    assert len(rows) == 1, name
    return rows[0]


@pytest.mark.slow  # a table1 folder of 8 runs (about 25 s): make test, not test-fast
@pytest.mark.xdist_group("table1_report")
def test_table1_folder_report(table1_dir):
    """Given a table1 folder of 8 short runs, when `gcs report DIR` runs, then every run
    folder has Fig. 3, 4 and 6 (Fig. 5 for Case I PD only, Fig. 7/8 for disturbed runs) and
    its report.md, the folder has table1.png and Figs. 5, 7 and 8, and its report.md lists
    the 8 runs with their status, why, and events, the table beside the paper, and links to
    every figure."""
    for name in RUN_NAMES:
        figs = table1_dir / name / FIG_DIR
        for fig in (FIG3, FIG4, FIG6):
            _assert_png(figs / fig)
        assert (figs / FIG5).exists() == (name == "case1_figure8_pd"), name
        assert (figs / FIG78).exists() == name.startswith("case2_"), name
        assert f"({FIG_DIR}/{FIG3})" in (table1_dir / name / REPORT).read_text()
    _assert_png(table1_dir / "case1_figure8_pd" / FIG_DIR / FIG5)
    for fig in (TABLE1_PNG, FIG5, FIG7, FIG8):
        _assert_png(table1_dir / fig)

    text = (table1_dir / REPORT).read_text()
    statuses = {}
    for name in RUN_NAMES:
        m = json.loads((table1_dir / name / "metrics.json").read_text())
        statuses[name] = m["status"]
        row = _row(text, name)
        assert f"**{m['status']}**" in row, row
        assert m["status_reason"] in row, row
        assert f"{len(m['events'])} (" in row, row  # the events' count, then the summary
        reactions = [e for e in m["events"] if e["kind"] not in ("info", "limit")]
        warnings = [e for e in m["events"] if e["kind"] in ("info", "limit")
                    and e["severity"] <= 4]
        for event in reactions:  # failsafes, crashes, divergence are always named
            assert event["text"] in row, (row, event)
        named = [e for e in warnings if e["text"] in row]
        assert len(named) >= min(len(warnings), max(0, 4 - len(reactions))), row
        rest = len(reactions) + len(warnings) - max(4, len(reactions))
        assert (f"… {rest} more" in row) == (rest > 0), row
        assert f"{m['position_error_m']['rmse']:.4g}" in text
    # The short runs still exercise both outcomes: PD loses the vehicle under the sine.
    assert statuses["case2_sine_pd"] == "diverged" and statuses["case1_figure8_pid"] == \
        "completed"
    for (scen, ctrl), (pos, att) in ((k, PAPER[k[0]][k[1]]) for k in
                                     ((s, c) for _, s in CASES for c in CONTROLLERS)):
        assert f"{pos[2]:.4f}" in text and f"{att[2]:.4f}" in text, (scen, ctrl)
    assert "8 of 8 runs reported" in text and "Missing" not in text
    # Both allocations were flown (run_table1's default): the plain runs in plain/, and
    # the table's columns beside ours with the plain runs' own figures.
    md = (table1_dir / "table1.md").read_text()
    assert "position (plain)" in md and "CA_LAG_COMP 0" in md
    for name in RUN_NAMES:
        plain = json.loads((table1_dir / "plain" / name / "metrics.json").read_text())
        assert plain["fcu_params"]["CA_LAG_COMP"] == 0.0
        assert f"{plain['position_error_m']['rmse']:.4g}" in md, name
    links = _links(text)
    for fig in (TABLE1_PNG, FIG5, FIG7, FIG8):
        assert fig in links
    for name in RUN_NAMES:
        for fig in (FIG3, FIG4, FIG6):
            assert f"{name}/{FIG_DIR}/{fig}" in links
    assert f"case1_figure8_pd/{FIG_DIR}/{FIG5}" in links
    for link in links:
        assert (table1_dir / link).is_file(), link


@pytest.mark.slow  # a table1 folder of 8 runs (about 25 s): make test, not test-fast
@pytest.mark.xdist_group("table1_report")
def test_partial_table1_folder(table1_dir, tmp_path):
    """Given a table1 folder with one run folder removed and one whose log is not the one
    metrics.json was made from, then `gcs report` reports the six others (and the figures
    that can be drawn), names both problems in report.md and on stderr, and exits 1."""
    out = tmp_path / "partial"
    shutil.copytree(table1_dir, out, ignore=shutil.ignore_patterns(
        FIG_DIR, REPORT, "*.png"))
    shutil.rmtree(out / "case2_sine_pid")
    log = next(p for p in (out / "case1_figure8_pid").iterdir() if p.name.startswith("truth"))
    with log.open("ab") as fh:
        fh.write(b"\0")
    rc, stdout, stderr = _gcs("report", str(out))
    assert rc == 1
    assert "case2_sine_pid: run folder missing" in stderr
    assert "case1_figure8_pid: could not be read" in stderr
    text = (out / REPORT).read_text()
    assert "6 of 8 runs reported" in text
    assert "`case2_sine_pid`" in text and "run folder missing" in text
    assert "`case1_figure8_pid`" in text and "could not be read" in text
    for name in RUN_NAMES:
        done = name not in ("case2_sine_pid", "case1_figure8_pid")
        assert (out / name / FIG_DIR / FIG3).exists() == done, name
        if done:
            assert str(out / name / REPORT) in stdout
            _row(text, name)
    # Fig. 5 without its PID reference, Fig. 7 with an empty sine row, Fig. 8 whole.
    for fig in (TABLE1_PNG, FIG5, FIG7, FIG8):
        _assert_png(out / fig)
    # The missing runs' rows of Table I still come from table1.json.
    saved = {(r["scenario"], r["controller"]): r for r in
             json.loads((out / "table1.json").read_text())["rows"]}
    assert f"{saved[('case2_sine', 'pid')]['ours']['position_error_m']['rmse']:.4g}" in text


def _data_lines(ax) -> list:
    return [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]


@pytest.mark.slow  # a table1 folder of 8 runs (about 25 s): make test, not test-fast
@pytest.mark.xdist_group("table1_report")
def test_fig7_8_rows_and_divergence(table1_dir):
    """Given the three Case II runs, then Figs. 7 and 8 have the rows impulse, sinusoidal,
    irregular (lettered down the columns, as the paper's "(a) and (d)"), the drawn errors are
    the metrics' own, and a diverged run is drawn up to its divergence_t_s and no further,
    with a red line there."""
    for ctrl, number in (("pid", 7), ("pd", 8)):
        runs = [load_run(table1_dir / f"{scen}_{ctrl}") for scen in
                ("case2_impulse", "case2_sine", "case2_irregular")]
        fig = fig7_8_figure(runs, ctrl)
        assert fig._suptitle is not None and f"Fig. {number}" in fig._suptitle.get_text()
        axes = np.array(fig.axes).reshape(3, 3)
        for r, word in enumerate(("impulse", "sinusoidal", "irregular")):
            for c, part in enumerate(("attitude error", "position error", "disturbance")):
                title = axes[r, c].get_title()
                assert title.startswith(f"({'abcdefghi'[3 * c + r]}) {word}"), title
                assert part in title, title
        for r, data in enumerate(runs):
            m = data.metrics
            (att_line,) = _data_lines(axes[r, 0])
            assert np.max(att_line.get_ydata()) == pytest.approx(
                m["attitude_error_rad"]["max"], rel=1e-9)
            norm_line = next(ln for ln in _data_lines(axes[r, 1])
                             if ln.get_label() == "|p − p_d|")
            assert np.max(norm_line.get_ydata()) == pytest.approx(
                m["position_error_m"]["max"], rel=1e-9)
            end = m["divergence_t_s"] if m["status"] == "diverged" else TABLE1_S
            for ax in axes[r]:
                xmax = max(float(np.max(ln.get_xdata())) for ln in _data_lines(ax))
                assert end - 0.0021 <= xmax <= end + 1e-9, (ctrl, r, xmax, end)
                red = [ln for ln in ax.get_lines() if ln.get_color() == "red"
                       and ln.get_linestyle() == ":"]
                if m["status"] == "diverged":
                    assert len(red) == 1 and red[0].get_xdata()[0] == pytest.approx(end)
                    assert "DIVERGED" in ax.get_title()
                else:
                    assert not red and "DIVERGED" not in ax.get_title()
        assert [d.diverged for d in runs] == [ctrl == "pd", True, False]
    # The impulse row shades the torque pulse (5-7 s) on each of its panels, no other row.
    for r in range(3):
        for ax in axes[r]:
            spans = [(p.get_x(), p.get_x() + p.get_width()) for p in ax.patches]
            assert spans == ([(5.0, 7.0)] if r == 0 else []), (r, spans)
    with pytest.raises(ValueError):  # rows in another order are refused, not mislabelled
        fig7_8_figure(runs[::-1], "pd")
    fig = fig7_8_figure([runs[0], None, runs[2]], "pd")
    titles = [ax.get_title() for ax in fig.axes[:9]]  # row-major
    assert all("case2_sine_pd is missing" in t for t in titles[3:6])
    assert not any("missing" in t for t in titles[:3] + titles[6:])


@pytest.mark.slow  # a table1 folder of 8 runs (about 25 s): make test, not test-fast
@pytest.mark.xdist_group("table1_report")
def test_fig5_is_the_pd_errors(table1_dir):
    """Given the Case I runs, then Fig. 5 shows the PD run's attitude error and position
    error (the maxima of metrics.json), with the PID run's drawn for comparison."""
    pd = load_run(table1_dir / "case1_figure8_pd")
    pid = load_run(table1_dir / "case1_figure8_pid")
    fig = fig5_figure(pd, reference=pid)
    ax_att, ax_pos = fig.axes
    assert ax_att.get_title().startswith("(a) attitude error")
    assert ax_pos.get_title().startswith("(b) position error")
    assert ax_att.get_yscale() == "log"
    lines = {ln.get_label(): ln for ln in ax_att.get_lines()}
    assert np.max(lines["∠(q_d* q), PD"].get_ydata()) == pytest.approx(
        pd.metrics["attitude_error_rad"]["max"], rel=1e-9)
    assert any("PID" in label for label in lines)
    norm = next(ln for ln in ax_pos.get_lines() if ln.get_label() == "|p − p_d|")
    assert np.max(norm.get_ydata()) == pytest.approx(pd.metrics["position_error_m"]["max"],
                                                     rel=1e-9)
    assert fig._suptitle is not None and "Fig. 5" in fig._suptitle.get_text()
