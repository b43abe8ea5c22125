"""summary.md and envelope.png of the random-mission campaign (benchmarks/random_missions.py)."""

from __future__ import annotations

import argparse
import math
from collections import Counter
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

LEG_BINS_M = np.geomspace(0.2, 30.0, 9)  # 8 log-spaced bins over the generator's legs


def _fmt(x: float, unit: str = "", scale: float = 1.0, digits: int = 2) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    return f"{x * scale:.{digits}f}{unit}"


def envelope_rows(results: list[dict[str, Any]], vehicle: str) -> list[dict[str, float]]:
    """Per leg-length bin: the largest cruise speed of an accepted mission with a waypoint leg
    in the bin, of a mission that flew it within the property, and the largest planned speed
    (leg / planned travel time, after stretching) of such a leg."""
    rows = []
    for lo, hi in pairwise(LEG_BINS_M):
        acc = clean = eff = refused = -math.inf
        n = 0
        for r in results:
            if r["vehicle"] != vehicle:
                continue
            for _, length, speed in r["legs"]:
                if not lo <= length < hi or (hi == LEG_BINS_M[-1] and length > hi):
                    continue
                n += 1
                if r["verdict"] == "accepted":
                    acc = max(acc, r["cruise_m_s"])
                    eff = max(eff, speed)
                    if not r.get("why"):
                        clean = max(clean, r["cruise_m_s"])
                else:
                    refused = max(refused, r["cruise_m_s"])
        rows.append({"lo": lo, "hi": hi, "legs": n, "accepted": acc, "clean": clean,
                     "planned": eff, "refused": refused})
    return rows


def _plot(out: Path, results: list[dict[str, Any]], vehicles: list[str]) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        return False
    fig, axes = plt.subplots(1, len(vehicles), figsize=(6 * len(vehicles), 4.5), squeeze=False)
    for ax, v in zip(axes[0], vehicles, strict=True):
        for verdict, style in (("accepted", "o"), ("refused", "x")):
            pts = [(leg[1], r["cruise_m_s"]) for r in results
                   if r["vehicle"] == v and r["verdict"] == verdict for leg in r["legs"]]
            if pts:
                ax.scatter(*zip(*pts, strict=True), marker=style, s=12, alpha=0.5,
                           label=f"legs of {verdict} missions")
        bad = [(leg[1], r["cruise_m_s"]) for r in results
               if r["vehicle"] == v and r.get("why") for leg in r["legs"]]
        if bad:
            ax.scatter(*zip(*bad, strict=True), marker="s", s=20, facecolors="none",
                       edgecolors="red", label="legs of violating missions")
        rows = envelope_rows(results, v)
        mid = [math.sqrt(r["lo"] * r["hi"]) for r in rows]
        ax.step(mid, [r["accepted"] if math.isfinite(r["accepted"]) else np.nan for r in rows],
                where="mid", label="largest accepted cruise")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("waypoint leg length (m)")
        ax.set_ylabel("MIS_CRUISE_SPD (m/s)")
        ax.set_title(v)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "envelope.png", dpi=110)
    plt.close(fig)
    return True


def write_report(out: Path, results: list[dict[str, Any]], mocap: list[dict[str, Any]],
                 wall_s: float, args: argparse.Namespace) -> tuple[str, bool]:
    """Write summary.md (and envelope.png); returns (the text, whether the property held)."""
    vehicles = list(dict.fromkeys(r["vehicle"] for r in results))
    lines = ["# Random-mission campaign", "",
             f"`benchmarks/random_missions.py --count {args.count} --seed {args.seed} "
             f"--sensors {args.sensors} --sample {args.sample} --workers {args.workers}`; "
             f"wall time {wall_s:.0f} s.", "",
             "| vehicle | missions | regenerated (> max s) | refused | accepted | stretched "
             "| flown | violations | mocap flown | mocap violations |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    ok = True
    for v in vehicles:
        line, held = _vehicle_row(v, results, mocap)
        lines.append(line)
        ok = ok and held
    lines += ["", "Property (truth sensors): status completed, max |p - p_ref| <= 5 cm, max "
              "attitude error <= 3 deg from the planned end of the takeoff, no monitor event. "
              "Mocap: position error <= truth-run error + estimation error + 2 cm.", ""]
    lines += [*_refusals_md(results, vehicles), *_violations_md(results, mocap, vehicles),
              *_errors_md(results, mocap, vehicles)]
    lines += ["", "## Envelope: largest cruise speed by waypoint leg length", "",
              "Largest MIS_CRUISE_SPD among accepted missions with a waypoint leg in the bin, "
              "among those that also held the property, the largest planned leg speed (leg / "
              "planned travel, after stretching) and the largest refused cruise speed.", "",
              "| vehicle | leg (m) | legs | accepted (m/s) | held the property (m/s) "
              "| planned leg speed (m/s) | refused (m/s) |", "|---|---|---|---|---|---|---|"]
    for v in vehicles:
        for row in envelope_rows(results, v):
            lines.append(f"| {v} | {row['lo']:.2f}-{row['hi']:.2f} | {row['legs']} | "
                         f"{_fmt(row['accepted'])} | {_fmt(row['clean'])} | "
                         f"{_fmt(row['planned'])} | {_fmt(row['refused'])} |")
    if _plot(out, results, vehicles):
        lines += ["", "![envelope](envelope.png)"]
    failed = sorted(p.name for p in (out / "failed").glob("*.toml")
                    if not p.name.endswith(".mission.toml")) if (out / "failed").is_dir() else []
    if failed:
        lines += ["", f"Violating missions, re-flyable: failed/ ({len(failed)} scenario files, "
                  "e.g. `gcs run --in-process failed/" + failed[0] + "`)."]
    lines += ["", f"Property {'HOLDS' if ok else 'FAILS'}."]
    text = "\n".join(lines) + "\n"
    (out / "summary.md").write_text(text)
    return text, ok


def _vehicle_row(v: str, results: list[dict[str, Any]],
                 mocap: list[dict[str, Any]]) -> tuple[str, bool]:
    """A vehicle's row of the summary table, and whether it held the property (no
    violation in the main runs nor in the mocap sample)."""
    rs = [r for r in results if r["vehicle"] == v]
    acc = [r for r in rs if r["verdict"] == "accepted"]
    bad = [r for r in acc if r.get("why")]
    ms = [r for r in mocap if r["vehicle"] == v]
    mbad = [r for r in ms if r.get("why")]
    row = (f"| {v} | {len(rs)} | {sum(r['regenerated'] for r in rs)} | "
           f"{len(rs) - len(acc)} | {len(acc)} | {sum(r['stretched'] for r in acc)} | "
           f"{sum('status' in r for r in acc)} | {len(bad)} | {len(ms)} | "
           f"{len(mbad)} |")
    return row, not bad and not mbad


def _refusals_md(results: list[dict[str, Any]], vehicles: list[str]) -> list[str]:
    """The refusals by reason (with an example) and by refused item, per vehicle."""
    lines = ["## Refusal reasons", "", "| vehicle | kind | count | example |",
             "|---|---|---|---|"]
    for v in vehicles:
        kinds = Counter(r["reason_kind"] for r in results
                        if r["vehicle"] == v and r["verdict"] == "refused")
        for kind, n in kinds.most_common():
            ex = next(r["reason"] for r in results if r["vehicle"] == v
                      and r["reason_kind"] == kind)
            lines.append(f"| {v} | {kind} | {n} | {ex} |")
    lines += ["", "| vehicle | refused item | count |", "|---|---|---|"]
    for v in vehicles:
        items = Counter(r.get("refused_item", "") for r in results
                        if r["vehicle"] == v and r["verdict"] == "refused")
        for kind, n in items.most_common():
            lines.append(f"| {v} | {kind or '-'} | {n} |")
    return lines


def _violations_md(results: list[dict[str, Any]], mocap: list[dict[str, Any]],
                   vehicles: list[str]) -> list[str]:
    """The property's violations by kind, per vehicle (main runs and mocap sample)."""
    lines = ["", "## Violations", "", "| vehicle | kind | count |", "|---|---|---|"]
    for v in vehicles:
        kinds = Counter(w.split(" ")[0] + (" " + w.split(" ")[1] if w.startswith(
            ("position", "attitude", "mocap")) else "")
            for r in [*results, *mocap] if r["vehicle"] == v for w in r.get("why", []))
        for kind, n in kinds.most_common():
            lines.append(f"| {v} | {kind} | {n} |")
    return lines


def _errors_md(results: list[dict[str, Any]], mocap: list[dict[str, Any]],
               vehicles: list[str]) -> list[str]:
    """The tracking and estimation errors of the flown missions, per vehicle and sensors."""
    lines = ["", "## Tracking errors of the flown missions", "",
             "| vehicle | sensors | flown | median pos (cm) | max pos (cm) | median att (deg) "
             "| max att (deg) | max estimation (cm) |", "|---|---|---|---|---|---|---|---|"]
    for v in vehicles:
        for label, rs in (("main", results), ("mocap sample", mocap)):
            fl = [r for r in rs if r["vehicle"] == v and "pos_err_m" in r]
            if not fl:
                continue
            pos = np.array([r["pos_err_m"] for r in fl])
            att = np.array([r["att_err_deg"] for r in fl])
            est = np.array([r["est_pos_err_m"] for r in fl])
            lines.append(f"| {v} | {fl[0]['sensors']} ({label}) | {len(fl)} | "
                         f"{_fmt(float(np.nanmedian(pos)), '', 100)} | "
                         f"{_fmt(float(np.nanmax(pos)), '', 100)} | "
                         f"{_fmt(float(np.nanmedian(att)))} | {_fmt(float(np.nanmax(att)))} | "
                         f"{_fmt(float(np.nanmax(est)), '', 100)} |")
    return lines
