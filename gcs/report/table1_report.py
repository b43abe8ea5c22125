"""A table1 folder's report (`gcs table1 --out DIR`): every run folder's report, Table I
(table1.png), Figs. 5, 7 and 8 and report.md, with the run folders missing or unreadable
named and the rest reported all the same."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.outcome import INFO, LIMIT
from gcs.report.chart import table1_chart
from gcs.report.disturbance_figures import fig7_8_case2
from gcs.report.names import (
    CAPTIONS,
    CASE1,
    CASE2_ROWS,
    FIG5,
    FIG78_BY_CONTROLLER,
    FIG_DIR,
    REPORT,
    SEVERITY,
    TABLE1_JSON,
    TABLE1_PNG,
)
from gcs.report.run_metrics import EventRecord, RunMetrics
from gcs.report.run_report import fmt, write_run_report
from gcs.report.rundata import RunData, cut_short, load_run
from gcs.report.table1 import CASES, CONTROLLERS, STATS, table_json, table_markdown
from gcs.report.tracking_figures import fig5_errors

REPORTS = (INFO, LIMIT)  # event kinds that are news, not reactions (LIMIT: a WARNING)


def is_table1_dir(path: Path) -> bool:
    """A folder written by `gcs table1 --out DIR` (it holds table1.json)."""
    return (Path(path) / TABLE1_JSON).is_file()


def table1_run_name(scenario: str, controller: str) -> str:
    """The run folder of a case and controller in a table1 folder
    (`gcs.run.table1_run.run_table1`)."""
    return f"{scenario}_{controller}"


@dataclass
class Table1Report:
    """What `make_table1_report` wrote, and what it could not report (one line each, naming
    the run folder)."""

    written: list[Path]
    problems: list[str]


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _events_summary(events: list[EventRecord], limit: int = 4) -> str:
    """One line: how many events, by severity, and the notable ones in time order: every
    reaction (failsafe, crash, divergence), then warnings up to `limit` in all (the rest
    counted), else the first few."""
    if not events:
        return "none"
    counts: dict[str, int] = {}
    for e in events:
        level = e.get("severity")
        sev = SEVERITY.get(level, str(level)) if isinstance(level, int) else str(level)
        counts[sev] = counts.get(sev, 0) + 1
    reactions = [e for e in events if e.get("kind", "info") not in REPORTS]
    warnings = [e for e in events if e.get("kind", "info") in REPORTS
                and isinstance(e.get("severity"), int) and e["severity"] <= 4]
    notable = reactions + warnings  # failsafes, crashes, divergence always; then warnings
    shown = (notable or events)[:max(limit, len(reactions))]
    shown.sort(key=lambda e: e.get("t_s") or 0.0)
    parts = [f"{e.get('text', '?')} ({fmt(e.get('t_s'))} s)" for e in shown]
    rest = len(notable or events) - len(shown)
    return (f"{len(events)} ({', '.join(f'{n} {s}' for s, n in counts.items())}): "
            + "; ".join(parts) + (f"; … {rest} more" if rest > 0 else ""))


def _status_text(m: RunMetrics) -> str:
    text = f"**{m.get('status', 'unknown')}**"
    if m.get("status") == "diverged" and m.get("divergence_t_s") is not None:
        text += f" at {fmt(m['divergence_t_s'])} s"
    return text


def _table1_md(table_dir: Path, table: dict[str, Any], runs: dict[tuple[str, str], RunData],
               run_figures: dict[tuple[str, str], list[Path]], figures: list[Path],
               problems: dict[tuple[str, str], str], other_problems: list[str],
               notes: list[str], from_json: list[tuple[str, str]]) -> str:
    """report.md of a table1 folder: what was reported, the table, the runs, the figures."""
    lines = [*_head_md(table_dir, runs, problems, other_problems, notes),
             *_table_md(table_dir, table, from_json), *_runs_md(runs, problems),
             *_figures_md(figures, run_figures)]
    return "\n".join(lines).rstrip() + "\n"


def _head_md(table_dir: Path, runs: dict[tuple[str, str], RunData],
             problems: dict[tuple[str, str], str], other_problems: list[str],
             notes: list[str]) -> list[str]:
    """The title, how many runs were reported, runs cut short, what is missing, notes."""
    n_runs = len(CASES) * len(CONTROLLERS)
    lines = [f"# Table I report: {table_dir.name}", "",
             f"{len(runs)} of {n_runs} runs reported"
             + (f"; {len(problems)} missing or unreadable: "
                + ", ".join(f"`{table1_run_name(*k)}`" for k in problems) if problems else "")
             + "."]
    cut = sorted({fmt(d.metrics.get("overrides", {}).get("duration_s"))
                  for d in runs.values() if cut_short(d)})
    if cut:
        lines += ["", f"Runs cut short (to {', '.join(cut)} s of the scenarios' durations): "
                  "the paper's figures are for the full scenarios."]
    lines += [""]
    if problems or other_problems:
        lines += ["## Missing or unreadable", ""]
        lines += [f"- {_md_cell(p)}" for p in [*problems.values(), *other_problems]]
        lines.append("")
    lines += [f"_{n}_" for n in notes]
    if notes:
        lines.append("")
    return lines


def _table_md(table_dir: Path, table: dict[str, Any],
              from_json: list[tuple[str, str]]) -> list[str]:
    """Table I, the rows taken from table1.json named, and its chart."""
    table_md = table_markdown(table).replace("# Table I", "## Table I", 1)
    lines = [table_md.rstrip(), ""]
    if from_json:
        lines += ["Rows of run folders that are missing or unreadable are those of "
                  f"{TABLE1_JSON}: " + ", ".join(f"`{table1_run_name(*k)}`" for k in from_json)
                  + ".", ""]
    if (table_dir / TABLE1_PNG).exists():
        lines += [f"![{CAPTIONS[TABLE1_PNG]}]({TABLE1_PNG})", ""]
    return lines


def _runs_md(runs: dict[tuple[str, str], RunData],
             problems: dict[tuple[str, str], str]) -> list[str]:
    """One row per run: its status, why, and what the vehicle said (or why not reported)."""
    lines = ["## Runs", "", "Status, why, and what the vehicle said (events on the flight "
             "clock, from each run's metrics.json).", "",
             "| case | controller | run folder | status | why | events |",
             "|---|---|---|---|---|---|"]
    for label, scen in CASES:
        for ctrl in CONTROLLERS:
            key = (scen, ctrl)
            name = table1_run_name(scen, ctrl)
            if key in runs:
                m = runs[key].metrics
                why = str(m.get("status_reason") or "")
                if m.get("failsafe"):
                    why += f"; failsafe: {m['failsafe']}"
                lines.append(f"| {label} | {ctrl.upper()} | [{name}]({name}/{REPORT}) | "
                             f"{_status_text(m)} | {_md_cell(why) or '—'} | "
                             f"{_md_cell(_events_summary(list(m.get('events', []))))} |")
            else:
                lines.append(f"| {label} | {ctrl.upper()} | `{name}` | **not reported** | "
                             f"{_md_cell(problems.get(key, 'missing'))} | — |")
    lines.append("")
    return lines


def _figures_md(figures: list[Path], run_figures: dict[tuple[str, str], list[Path]]
                ) -> list[str]:
    """The table's figures (and those not drawn, why), then each run's figures."""
    lines = ["## Figures", ""]
    for fig in figures:
        lines.append(f"- [{CAPTIONS.get(fig.name, fig.stem)}]({fig.name})")
    drawn = {f.name for f in figures}
    for name, source in ((FIG5, f"`{table1_run_name(CASE1, 'pd')}`"),
                         *((f, f"any `case2_*_{c}`") for c, (_, f) in
                           FIG78_BY_CONTROLLER.items())):
        if name not in drawn:
            lines.append(f"- {CAPTIONS[name].split(':')[0]}: not drawn (no run: {source} "
                         "is missing or unreadable)")
    lines += ["", "Each run's own figures and report:", ""]
    for label, scen in CASES:
        for ctrl in CONTROLLERS:
            key = (scen, ctrl)
            if key not in run_figures:
                continue
            name = table1_run_name(scen, ctrl)
            links = [f"[{CAPTIONS.get(p.name, p.stem).split(':')[0]}]"
                     f"({name}/{FIG_DIR}/{p.name})" for p in run_figures[key]]
            lines.append(f"- `{name}` (Case {label}, {ctrl.upper()}): " + ", ".join(links)
                         + f", [report]({name}/{REPORT})")
    return lines


def _valid_row(row: Any) -> bool:
    try:
        return all(isinstance(row[side][metric][stat], int | float)
                   for side in ("ours", "paper")
                   for metric in ("position_error_m", "attitude_error_rad") for stat in STATS) \
            and isinstance(row["status"], str) and isinstance(row["case"], str)
    except (KeyError, TypeError):
        return False


def _saved_rows(table_dir: Path, other: list[str],
                note: Callable[[str], None]) -> dict[tuple[str, str], Any]:
    """table1.json's valid rows by (scenario, controller); none, and the problem noted in
    `other` and passed to `note`, when it cannot be read."""
    try:
        saved = json.loads((table_dir / TABLE1_JSON).read_text())
        return {(r["scenario"], r["controller"]): r for r in saved["rows"] if _valid_row(r)}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        other.append(f"{table_dir / TABLE1_JSON}: not readable ({exc}); the table is made "
                     "from the run folders")
        note(other[-1])
        return {}


def _merged_table(runs: dict[tuple[str, str], RunData],
                  saved_rows: dict[tuple[str, str], Any],
                  from_json: list[tuple[str, str]]) -> dict[str, Any]:
    """The table: the run folders' metrics, and table1.json's rows for the runs not read
    (`from_json`), in the table's order; the plain allocation's figures from table1.json."""
    table = table_json({k: d.metrics for k, d in runs.items()})
    order = {(scen, ctrl): i for i, (scen, ctrl) in
             enumerate((s, c) for _, s in CASES for c in CONTROLLERS)}
    table["rows"] = sorted([*table["rows"], *(saved_rows[k] for k in from_json)],
                           key=lambda r: order[(r["scenario"], r["controller"])])
    for r in table["rows"]:  # the plain allocation's figures (CA_LAG_COMP 0), as table1 ran them
        plain = saved_rows.get((r["scenario"], r["controller"]), {}).get("plain")
        if plain is not None:
            r.setdefault("plain", plain)
    return table


def _table_figures(table: dict[str, Any], runs: dict[tuple[str, str], RunData],
                   table_dir: Path) -> list[Path]:
    """table1.png, and Figs. 5, 7 and 8 where their runs were read."""
    figures = [table1_chart(table, table_dir / TABLE1_PNG)]
    pd1 = runs.get((CASE1, "pd"))
    if pd1 is not None:
        figures.append(fig5_errors(pd1, table_dir / FIG5, reference=runs.get((CASE1, "pid"))))
    for ctrl, (_, name) in FIG78_BY_CONTROLLER.items():
        row_runs = [runs.get((scen, ctrl)) for scen, _ in CASE2_ROWS]
        if any(r is not None for r in row_runs):
            figures.append(fig7_8_case2(row_runs, ctrl, table_dir / name))
    return figures


def make_table1_report(table_dir: Path, *,
                       warn: Callable[[str], None] | None = None) -> Table1Report:
    """Report a table1 folder: each run folder's figures and report.md (as `make_report`),
    and in `table_dir` table1.png, Figs. 5, 7 and 8 and report.md. A run folder that is
    missing or cannot be read is named in `problems` (and passed to `warn` as it is found)
    and the rest is reported all the same."""
    table_dir = Path(table_dir)
    written: list[Path] = []
    problems: dict[tuple[str, str], str] = {}
    other: list[str] = []
    notes: list[str] = []

    def note(problem: str) -> None:
        if warn is not None:
            warn(problem)

    saved_rows = _saved_rows(table_dir, other, note)

    runs: dict[tuple[str, str], RunData] = {}
    run_figures: dict[tuple[str, str], list[Path]] = {}
    for _, scen in CASES:
        for ctrl in CONTROLLERS:
            run_dir = table_dir / table1_run_name(scen, ctrl)
            if not run_dir.is_dir():
                problems[(scen, ctrl)] = f"{run_dir}: run folder missing"
                note(problems[(scen, ctrl)])
                continue
            try:
                data = load_run(run_dir)
                row = table_json({(scen, ctrl): data.metrics})["rows"]
            except Exception as exc:  # any reading failure: name it, report the rest
                problems[(scen, ctrl)] = f"{run_dir}: could not be read " \
                                         f"({type(exc).__name__}: {exc})"
                note(problems[(scen, ctrl)])
                continue
            runs[(scen, ctrl)] = data
            paths = write_run_report(data)
            run_figures[(scen, ctrl)] = paths[:-1]
            written += paths
            old = saved_rows.get((scen, ctrl))
            if old is not None and row and (old.get("status") != row[0]["status"] or old.get(
                    "ours") != row[0]["ours"]):
                notes.append(f"{run_dir.name}: its metrics.json differs from the row of "
                             f"{TABLE1_JSON} (status {old.get('status')} there, "
                             f"{row[0]['status']} here); the table shows the run folder's.")

    from_json = [k for k in problems if k in saved_rows]
    table = _merged_table(runs, saved_rows, from_json)
    figures = _table_figures(table, runs, table_dir)
    report = table_dir / REPORT
    report.write_text(_table1_md(table_dir, table, runs, run_figures, figures, problems,
                                 other, notes, from_json))
    written += [*figures, report]
    return Table1Report(written, [*problems.values(), *other])
