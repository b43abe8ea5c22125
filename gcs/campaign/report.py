"""A campaign's summary: DIR/summary.md and its figures, from results.csv's rows.

- Success rate and error distributions per value of every axis (a run succeeds when its
  status is "completed"; a "limited" run, flown to its end with an actuator at its limit,
  is counted on a line of its own and is not a success).
- The disturbance envelope (`envelope.png`), when the campaign sweeps a disturbance's
  magnitude (a key ending in `.magnitude`) and its direction (`.azimuth_deg`, with
  `.elevation_deg` if swept too): per direction, the largest magnitude survived with every
  smaller one survived too, one curve per controller (the paper's robustness claim, PID
  beside PD, as a picture).
- Actuator failures (`failures.png`), when the campaign sweeps `actuator_fault[i].index`:
  the success rate per failed actuator, per fault kind and controller.
- `errors.png`: the distribution of each run's maximum position error per axis value.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from common.vehicle_constants import N_ROTORS
from gcs.campaign.keys import key_path
from gcs.campaign.model import Campaign

OK = "completed"
LIMITED = "limited"


def _num(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    return float(v) if math.isfinite(v) else None


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def _key(v: Any) -> Any:
    return tuple(v) if isinstance(v, list) else v


def _quantile(xs: Sequence[float], q: float) -> float:
    s = sorted(xs)
    if not s:
        return math.nan
    pos = q * (len(s) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


def per_value(rows: list[dict[str, Any]], key: str) -> list[dict[str, Any]]:
    """For each value of `key`: runs, success rate, the maximum position and attitude
    errors' median, 90th percentile and worst over the runs."""
    groups: dict[Any, list[dict[str, Any]]] = defaultdict(list)
    order: list[Any] = []
    for r in rows:
        k = _key(r.get(key))
        if k not in groups:
            order.append(k)
        groups[k].append(r)
    out = []
    for k in order:
        g = groups[k]
        pos = [x for x in (_num(r.get("position_error_m.max")) for r in g) if x is not None]
        att = [x for x in (_num(r.get("attitude_error_rad.max")) for r in g) if x is not None]
        out.append({"value": g[0].get(key), "runs": len(g),
                    "success": sum(r.get("status") == OK for r in g) / len(g),
                    "pos_med": _quantile(pos, 0.5), "pos_p90": _quantile(pos, 0.9),
                    "pos_max": max(pos) if pos else math.nan,
                    "att_med": _quantile(att, 0.5), "att_max": max(att) if att else math.nan})
    return out


def _order(d: tuple[Any, ...]) -> tuple[tuple[int, float, str], ...]:
    """Directions in numeric order (numbers before anything else)."""
    return tuple((0, float(x), "") if _num(x) is not None else (1, 0.0, str(x)) for x in d)


def _find(columns: Sequence[str], suffix: str) -> str | None:
    hits = [c for c in columns if c.endswith(suffix)]
    return hits[0] if hits else None


def envelope(rows: list[dict[str, Any]], magnitude: str, direction: Sequence[str],
             group: str | None) -> dict[Any, dict[tuple[Any, ...], float]]:
    """envelope[group value][direction] = the largest magnitude survived at that direction
    with every smaller magnitude survived too (0 when the smallest fails)."""
    runs: dict[Any, dict[tuple[Any, ...], list[tuple[float, bool]]]] = defaultdict(
        lambda: defaultdict(list))
    for r in rows:
        m = _num(r.get(magnitude))
        if m is None:
            continue
        d = tuple(_key(r.get(k)) for k in direction)
        runs[r.get(group) if group else ""][d].append((m, r.get("status") == OK))
    out: dict[Any, dict[tuple[Any, ...], float]] = {}
    for g, by_dir in runs.items():
        out[g] = {}
        for d, ms in by_dir.items():
            best = 0.0
            for m, ok in sorted(ms):
                if not ok:
                    break
                best = m
            out[g][d] = best
    return out


def write_report(out: Path, campaign: Campaign, rows: list[dict[str, Any]]) -> Path:
    """summary.md (and the figures it shows) in DIR; returns its path."""
    import matplotlib

    matplotlib.use("Agg")

    columns = list(campaign.columns)
    axis_keys = [k for a in campaign.axes for k in a.keys]
    lines = _overview(campaign, rows) + _by_axis(rows, axis_keys)
    figures = []
    magnitude = _find(columns, ".magnitude")
    azimuth = _find(columns, ".azimuth_deg")
    if magnitude and azimuth:
        lines += _envelope_section(out, rows, columns, magnitude, azimuth)
        figures.append("envelope.png")
    index_key = next((c for c in columns if c.startswith("actuator_fault")
                      and c.endswith(".index")), None)
    if index_key:
        lines += _failures_section(out, campaign, rows, index_key)
        figures.append("failures.png")
    if rows and axis_keys:
        _errors_figure(out, rows, axis_keys)
        figures.append("errors.png")
    if figures:
        lines += ["## Figures", ""] + [f"![{f}]({f})" for f in figures] + [""]
    path = out / "summary.md"
    path.write_text("\n".join(lines))
    return path


def _overview(campaign: Campaign, rows: list[dict[str, Any]]) -> list[str]:
    """The heading, the base scenario, the success rate and the simulated time."""
    n = len(rows)
    statuses: dict[str, int] = defaultdict(int)
    for r in rows:
        statuses[str(r.get("status"))] += 1
    ok = statuses.get(OK, 0)
    lines = [f"# Campaign {campaign.name}", "",
             f"Base scenario `{campaign.base.name}`, transport {campaign.transport}; "
             f"{n} runs recorded.", "",
             f"Success (status completed): {ok}/{n} = {100.0 * ok / max(n, 1):.1f} %  ("
             + ", ".join(f"{k} {v}" for k, v in sorted(statuses.items())) + ")", ""]
    if statuses.get(LIMITED):
        lines += [f"Limited (flown to the end with an actuator at its limit, not a success): "
                  f"{statuses[LIMITED]}/{n}", ""]
    sim = sum(_num(r.get("sim_time_s")) or 0.0 for r in rows)
    lines += [f"Simulated {sim:.0f} s in all.", ""]
    return lines


def _by_axis(rows: list[dict[str, Any]], axis_keys: list[str]) -> list[str]:
    """Per axis key, a table of success and errors per value."""
    lines: list[str] = []
    for key in axis_keys:
        lines += [f"## By `{key}`", "",
                  "| value | runs | success | pos. max: median | p90 | worst (m) | "
                  "att. max: median | worst (rad) |",
                  "|---|---|---|---|---|---|---|---|"]
        for g in per_value(rows, key):
            lines.append(f"| {_fmt(g['value'])} | {g['runs']} | {100 * g['success']:.0f} % | "
                         f"{g['pos_med']:.4g} | {g['pos_p90']:.4g} | {g['pos_max']:.4g} | "
                         f"{g['att_med']:.4g} | {g['att_max']:.4g} |")
        lines.append("")
    return lines


def _envelope_section(out: Path, rows: list[dict[str, Any]], columns: list[str],
                      magnitude: str, azimuth: str) -> list[str]:
    """envelope.png (a polar curve per controller and elevation) and its table."""
    import matplotlib.pyplot as plt

    elevation = _find(columns, ".elevation_deg")
    group = "controller" if "controller" in columns else None
    direction = [azimuth] + ([elevation] if elevation else [])
    env = envelope(rows, magnitude, direction, group)
    elevations = sorted({d[1] for e in env.values() for d in e} if elevation else {0.0})
    fig, axes = plt.subplots(1, len(elevations), subplot_kw={"projection": "polar"},
                             figsize=(4.5 * len(elevations), 4.5), squeeze=False)
    for ax, el in zip(axes[0], elevations, strict=True):
        for g, by_dir in sorted(env.items(), key=lambda kv: str(kv[0])):
            pts = sorted((d[0], m) for d, m in by_dir.items()
                         if not elevation or d[1] == el)
            if not pts:
                continue
            th = [math.radians(a) for a, _ in pts] + [math.radians(pts[0][0])]
            rr = [m for _, m in pts] + [pts[0][1]]
            ax.plot(th, rr, marker="o", label=str(g).upper() if g else "survived")
        ax.set_title(f"elevation {el:g} deg" if elevation else "")
    axes[0][0].legend(loc="lower left", bbox_to_anchor=(-0.15, -0.15))
    fig.suptitle(f"Largest magnitude survived by body-frame direction\n"
                 f"({magnitude})", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "envelope.png", dpi=110)
    plt.close(fig)
    lines = [f"## Envelope: the largest `{magnitude}` survived per direction", "",
              "A direction's figure is the largest magnitude survived with every smaller "
              "one survived too.", "",
              "| direction | " + " | ".join(str(g) for g in sorted(env, key=str)) + " |",
              "|---|" + "---|" * len(env)]
    dirs = sorted({d for e in env.values() for d in e}, key=_order)
    for d in dirs:
        lines.append(f"| {', '.join(_fmt(x) for x in d)} | " + " | ".join(
            _fmt(env[g].get(d, math.nan)) for g in sorted(env, key=str)) + " |")
    lines.append("")
    return lines


def _failures_section(out: Path, campaign: Campaign, rows: list[dict[str, Any]],
                      index_key: str) -> list[str]:
    """failures.png (runs survived per failed actuator) and its table."""
    import matplotlib.pyplot as plt

    kind_key = index_key[:-len(".index")] + ".kind"
    groups: dict[tuple[str, str], dict[int, list[bool]]] = defaultdict(
        lambda: defaultdict(list))
    for r in rows:
        idx = r.get(index_key)
        kind = r.get(kind_key) or _base_kind(campaign, kind_key)
        if not isinstance(idx, int):
            continue
        groups[(str(kind), str(r.get("controller", campaign.base_data.get(
            "controller", "pid"))))][idx].append(r.get("status") == OK)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    labels = sorted(groups)
    width = 0.8 / max(len(labels), 1)
    lines = ["## Actuator failures: runs survived per failed actuator", "",
              "| fault | controller | " + " | ".join(f"#{i}" for i in range(N_ROTORS))
              + " |",
              "|---|---|" + "---|" * N_ROTORS]
    for j, lab in enumerate(labels):
        by_idx = groups[lab]
        xs = sorted(by_idx)
        rates = [sum(by_idx[i]) / len(by_idx[i]) for i in xs]
        ax.bar([x + j * width for x in xs], [100 * r for r in rates], width,
               label=f"{lab[0]} ({lab[1]})")
        lines.append(f"| {lab[0]} | {lab[1]} | " + " | ".join(
            f"{sum(by_idx[i])}/{len(by_idx[i])}" if i in by_idx else "–"
            for i in range(N_ROTORS)) + " |")
    ax.set_xlabel("failed actuator (rotor / servo index)")
    ax.set_ylabel("runs survived (%)")
    ax.set_ylim(0, 105)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "failures.png", dpi=110)
    plt.close(fig)
    lines.append("")
    return lines


def _errors_figure(out: Path, rows: list[dict[str, Any]], axis_keys: list[str]) -> None:
    """errors.png: the maximum position error's distribution per value of each axis."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(axis_keys), figsize=(4.2 * len(axis_keys), 3.5),
                             squeeze=False)
    for ax, key in zip(axes[0], axis_keys, strict=True):
        groups2: dict[Any, list[float]] = defaultdict(list)
        for r in rows:
            x = _num(r.get("position_error_m.max"))
            if x is not None and x > 0.0:
                groups2[_key(r.get(key))].append(x)
        labels2 = list(groups2)
        if labels2:
            ax.boxplot([groups2[k] for k in labels2])
            ax.set_xticks(range(1, len(labels2) + 1), [_fmt(k) for k in labels2],
                          rotation=45 if len(labels2) > 6 else 0, fontsize=7)
            ax.set_yscale("log")
        ax.set_title(key, fontsize=8)
        ax.set_ylabel("max position error (m)")
    fig.tight_layout()
    fig.savefig(out / "errors.png", dpi=110)
    plt.close(fig)


def _base_kind(campaign: Campaign, kind_key: str) -> str:
    """The fault kind the base scenario (with [set]) gives, when no axis sweeps it."""
    if kind_key in campaign.fixed:
        return str(campaign.fixed[kind_key])
    node: Any = campaign.base_data
    for p in key_path(kind_key):
        try:
            node = node[p]
        except (KeyError, IndexError, TypeError):
            return "?"
    return str(node)
