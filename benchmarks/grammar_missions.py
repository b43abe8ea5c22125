"""Grammar-mission campaign: `--count` missions per vehicle (hexa_tilted, hexa_planar) drawn
phase by phase (benchmarks/grammar_mission_gen.py: take-offs to 0.2-3 m, landings at
MIS_LAND_SPD 0.05-5 m/s, touch-and-goes, starts up to 5 m from home, DO_CHANGE_SPEED,
waypoints, loiters, keyframes, figures), each written as a mission file in its drawn format
(TOML, QGC WPL local or global, .plan) and flown as a user flies it: the scenario's
mission_file, its parameters and start position, `gcs.run.inprocess.run_scenario`.

    .venv/bin/python benchmarks/grammar_missions.py --count 1000 --workers 2

Each mission is either refused (at upload or at MISSION_START: InProcessError, whose text
and metrics carry the refusal) or flown for its planned end (the FCU's own plan from the
start) + `TAIL_S`. Properties:

1. an accepted mission flies: status `completed`; metrics.json's position error max <= 5 cm
   and attitude error max <= 3 deg (the rows of `error_rows`); every touchdown (the truth
   log's `landed` going to 1) slower than 1 m/s; no tilt servo at its rate limit for
   `SERVO_EPISODE_S` (50 ms) or longer (truth log tilt columns: a control period whose mean
   rate is >= `SERVO_AT_LIMIT` of tilt_rate_max_rad_s is at the limit) from the flight's
   start through touchdown to disarm and the end; shorter episodes (the envelope's allowed
   tilt step at a figure's ends) are counted and reported, not failed;
2. a refusal names a MAV_MISSION_RESULT by name (MAV_MISSION_...), "item N" and a reason.

Per phase (the item current in the onboard log's mission_result topic; the touchdown after
the last NAV_LAND counts as landing), the worst position and attitude error (truth against
the onboard reference, the rows of error_rows' rule) and the largest tilt-servo rate.
Results in --out: results.jsonl (a line per mission), summary.md (printed), failed/ (each
mission over a property as its mission file and a scenario TOML that re-flies it). Exit 0
only if both properties hold everywhere. `--summarize` prints the summary of an existing
results.jsonl (a campaign cut short included) without flying.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.grammar_mission_gen import (
    EXTENSION,
    PhaseMission,
    draw_mission,
    file_items,
    item_phase,
)
from common.config.scenario import Scenario, TrajectoryConfig, load_scenario, load_vehicle
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.logs.ulog import read_topic
from common.wire.mission_items import PX4_SITL_HOME
from fcu.compose import published_home
from fcu.mission.executor import MissionExecutor
from gcs.mission_files import read_mission, write_mission
from gcs.report.run_metrics import RunMetrics
from gcs.run.inprocess import InProcessError, fcu_pipeline, run_scenario, through_wire_item

ROOT = Path(__file__).resolve().parents[1]
VEHICLES = ("hexa_tilted", "hexa_planar")
BASE_SCENARIO = ROOT / "config/scenarios/mission_tour.toml"
POS_LIMIT_M = 0.05
ATT_LIMIT_DEG = 3.0
TOUCHDOWN_LIMIT_M_S = 1.0
SERVO_AT_LIMIT = 0.95  # a period's mean tilt rate at this share of the limit: rate-limited
# A servo at its rate this long is over the property: the envelope allows a tilt step of what
# the servo turns in 50 ms where an item starts or ends with an acceleration (a figure's ends;
# docs/autopilot.md), so shorter episodes are counted (`servo_limited_rows`), not failed.
SERVO_EPISODE_S = 0.05
TAIL_S = 4.0  # flown this long after the planned end (touchdown and disarm)
UNPLANNED_S = 10.0  # the run's length for a mission the FCU cannot plan (refused)
MAX_PLANNED_S = 90.0  # a mission planned longer is drawn again (counted)
PHASES = ("takeoff", "cruise", "keyframe_figure", "speed", "touch_and_go", "land",
          "after_end")
# A result by name (MAV_MISSION_DENIED, ...; "MAV_MISSION_RESULT 3" is a number), the item,
# and a reason after it.
REFUSAL = re.compile(r"\b(MAV_MISSION_(?!RESULT\b)[A-Z0-9_]+)\b.*?\bitem (\d+)\b:?\s*([^\s:].*)",
                     re.S)
Q_ID = (1.0, 0.0, 0.0, 0.0)
HOME = published_home(PX4_SITL_HOME)


def base_scenario(vehicle: str) -> Scenario:
    base = load_scenario(BASE_SCENARIO)
    path = ROOT / "config/vehicles" / f"{vehicle}.toml"
    return dataclasses.replace(base, vehicle=load_vehicle(path),
                               files={**base.files, "vehicle": str(path)})


def scenario_for(base: Scenario, mission: PhaseMission, path: Path, name: str,
                 duration_s: float) -> Scenario:
    traj = TrajectoryConfig(kind="mission", position_enu_m=mission.start_enu_m,
                            mission_file=str(path))
    return dataclasses.replace(base, name=name, trajectory=traj, duration_s=duration_s,
                               initial_position_enu_m=mission.start_enu_m,
                               params={**base.params, **mission.params})


def planned_end_s(scenario: Scenario, path: Path, start_enu_m: tuple[float, float, float]
                  ) -> float:
    """The mission's planned end as the FCU plans it from the start (its limits, the file
    read back as MISSION_ITEM_INT carries it, global items through home)."""
    from common.wire.mission_items import to_local

    limits = fcu_pipeline(scenario)[0].commander.limits
    items = [to_local(through_wire_item(it), HOME) for it in read_mission(path)]
    try:
        ex = MissionExecutor(items, limits)
    except ValueError:  # not executable: the FCU refuses it at upload
        return UNPLANNED_S
    ex.start(0.0, start_enu_m, Q_ID)
    return float(ex.schedule[-1][2]) if ex.schedule else 0.0


def refusal_ok(text: str) -> tuple[bool, str, str]:
    """(names a MAV_MISSION_RESULT, item N and a reason; the result's name; the reason)."""
    m = REFUSAL.search(text)
    if not m or not m.group(3).strip():
        return False, m.group(1) if m else "", text
    return True, m.group(1), m.group(3).strip()


def reason_kind(reason: str) -> str:
    r = reason.lower()
    for key, name in (("tilt servo", "tilt servo"), ("rotor", "rotor"),
                      ("geofence", "geofence"), ("attitude", "attitude"),
                      ("not supported", "unsupported"), ("p1", "param"), ("p2", "param")):
        if key in r:
            return name
    return "other: " + " ".join(r.split()[:4])


def _angle_deg(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    dot = np.abs(np.sum(q * qd, axis=1)) / (np.linalg.norm(q, axis=1)
                                           * np.linalg.norm(qd, axis=1))
    out: np.ndarray = np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))
    return out


def judge_flight(run: Any, items: list[Any], tilt_rate_max: float) -> dict[str, Any]:
    """Touchdowns, servo rates and per-phase worst errors of a flown mission."""
    tc, oc = TRUTH_COLUMNS.index, ONBOARD_COLUMNS.index
    start = run.metrics.get("flight_start_us")
    truth = run.truth
    t = truth[:, tc("time_us")]
    t0 = float(start) if start is not None else float(t[0])
    fl = truth[t >= t0]
    tf = fl[:, tc("time_us")]
    # Touchdowns: landed 0 -> 1; speed at the row before contact.
    landed = fl[:, tc("landed")] > 0.5
    v = np.linalg.norm(fl[:, [tc("vx"), tc("vy"), tc("vz")]], axis=1)
    idx = np.nonzero(landed[1:] & ~landed[:-1])[0]
    touchdowns = [float(max(v[i], v[i + 1])) for i in idx]
    # Tilt servo rate over each control period.
    tilts = fl[:, [tc(f"tilt{i}") for i in range(6)]]
    dt = np.diff(tf) * 1e-6
    rate = np.abs(np.diff(tilts, axis=0)) / np.maximum(dt, 1e-9)[:, None]
    rate_max_row = np.concatenate([[0.0], rate.max(axis=1)]) if len(rate) else np.zeros(len(fl))
    # The current item at each row: mission_result (onboard.ulg).
    with tempfile.NamedTemporaryFile(suffix=".ulg") as fh:
        fh.write(run.onboard_ulog)
        fh.flush()
        cols, rows = read_topic(fh.name, "mission_result")
    mt = rows[:, 0]
    cur = rows[:, list(cols).index("seq_current")].astype(int)
    fin = rows[:, list(cols).index("finished")] > 0.5
    k = np.clip(np.searchsorted(mt, tf, side="right") - 1, 0, max(len(mt) - 1, 0))
    last_land = items[-1].command == 21
    phase_of_item = [item_phase(items, s) for s in range(len(items))]
    phase = np.array([("land" if last_land else "after_end") if fin[j]
                      else phase_of_item[min(cur[j], len(items) - 1)] for j in k])
    # Errors on matched rows, error_rows' rule (on the ground with the reference below it).
    on = run.onboard
    _, it_, io = np.intersect1d(tf, on[:, oc("time_us")], return_indices=True)
    tr, ob = fl[it_], on[io]
    keep = ~((tr[:, tc("landed")] > 0.5) & (ob[:, oc("pdz")] < 0.0))
    perr = np.linalg.norm(tr[:, [tc("px"), tc("py"), tc("pz")]]
                          - ob[:, [oc("pdx"), oc("pdy"), oc("pdz")]], axis=1)
    aerr = _angle_deg(tr[:, [tc("qw"), tc("qx"), tc("qy"), tc("qz")]],
                      ob[:, [oc("qdw"), oc("qdx"), oc("qdy"), oc("qdz")]])
    by_phase: dict[str, dict[str, float]] = {}
    for ph in sorted(set(phase.tolist())):
        rows_ph = phase == ph
        sel = rows_ph[it_] & keep
        by_phase[ph] = {
            "pos_m": float(perr[sel].max()) if sel.any() else 0.0,
            "att_deg": float(aerr[sel].max()) if sel.any() else 0.0,
            "servo_rad_s": float(rate_max_row[rows_ph].max()) if rows_ph.any() else 0.0}
    limited = [i for i in range(len(rate_max_row))
               if rate_max_row[i] >= SERVO_AT_LIMIT * tilt_rate_max]
    # The longest episode of one servo at its rate, consecutive periods.
    at = np.vstack([np.zeros((1, 6), bool), rate >= SERVO_AT_LIMIT * tilt_rate_max]) \
        if len(rate) else np.zeros((len(fl), 6), bool)
    longest, longest_at = 0, 0
    for j in range(at.shape[1]):
        run_len = 0
        for i, flag in enumerate(at[:, j]):
            run_len = run_len + 1 if flag else 0
            if run_len > longest:
                longest, longest_at = run_len, i - run_len + 1
    period_s = float(np.median(dt)) if len(dt) else 0.0
    return {"touchdowns_m_s": touchdowns,
            "servo_max_rad_s": float(rate_max_row.max()) if len(rate_max_row) else 0.0,
            "servo_limited_rows": len(limited),
            "servo_limited_first_s": (tf[limited[0]] - t0) * 1e-6 if limited else None,
            "servo_limited_phase": str(phase[limited[0]]) if limited else "",
            "servo_episode_s": longest * period_s,
            "servo_episode_at_s": (tf[longest_at] - t0) * 1e-6 if longest else None,
            "servo_episode_phase": str(phase[longest_at]) if longest else "",
            "by_phase": by_phase}


def flight_violations(rec: dict[str, Any], tilt_rate_max: float) -> list[str]:
    why = []
    if rec["status"] != "completed":
        why.append(f"status {rec['status']}: {rec['status_reason']}")
    if not rec["pos_err_m"] <= POS_LIMIT_M:
        why.append(f"position error {rec['pos_err_m'] * 100:.2f} cm > 5 cm")
    if not rec["att_err_deg"] <= ATT_LIMIT_DEG:
        why.append(f"attitude error {rec['att_err_deg']:.2f} deg > 3 deg")
    fast = [v for v in rec["touchdowns_m_s"] if v >= TOUCHDOWN_LIMIT_M_S]
    if fast:
        why.append(f"touchdown at {max(fast):.2f} m/s")
    if rec["servo_episode_s"] >= SERVO_EPISODE_S - 1e-9:
        why.append(f"a tilt servo at its rate ({tilt_rate_max:.1f} rad/s) for "
                   f"{rec['servo_episode_s']:.3f} s from {rec['servo_episode_at_s']:.3f} s "
                   f"({rec['servo_episode_phase']})")
    return why


def run_one(job: tuple[str, int, int, str]) -> dict[str, Any]:
    """Worker: mission k of `seed` on `vehicle`, written, flown or refused, judged."""
    vehicle, k, seed, out = job
    base = base_scenario(vehicle)
    rng = np.random.default_rng((seed, k))
    regenerated = 0
    with tempfile.TemporaryDirectory() as tmp:
        while True:
            mission = draw_mission(rng)
            path = Path(tmp) / f"{vehicle}_{k}{EXTENSION[mission.fmt]}"
            write_mission(path, file_items(mission, HOME),
                          fmt="toml" if mission.fmt == "toml"
                          else "plan" if mission.fmt == "plan" else "wpl", home=HOME)
            probe = scenario_for(base, mission, path, f"grammar_{vehicle}_{k}", 1.0)
            end_s = planned_end_s(probe, path, mission.start_enu_m)
            if end_s <= MAX_PLANNED_S:
                break
            regenerated += 1
        scenario = dataclasses.replace(probe, duration_s=end_s + TAIL_S)
        rec: dict[str, Any] = {
            "vehicle": vehicle, "k": k, "seed": [seed, k], "regenerated": regenerated,
            "fmt": mission.fmt, "phases": list(mission.phases),
            "start_enu_m": list(mission.start_enu_m),
            "away": math.hypot(*mission.start_enu_m[:2]) > 1e-9, "params": mission.params,
            "n_items": len(mission.items), "planned_s": end_s}
        t0 = time.perf_counter()
        tilt_max = base.vehicle.tilt_rate_max_rad_s
        try:
            run = run_scenario(scenario, logs=True)
        except InProcessError as exc:
            text = str(exc)
            ok, result, reason = refusal_ok(text)
            stage = ("upload" if text.startswith("mission refused:")
                     else "start" if text.startswith("mission start refused") else "other")
            m: RunMetrics | dict[str, Any] = exc.result.metrics if exc.result is not None else {}
            rec.update(verdict="refused", stage=stage, text=text, result=result,
                       reason=reason, reason_kind=reason_kind(reason), refusal_ok=ok,
                       metrics_status=m.get("status"), metrics_error=m.get("error"))
            item = re.search(r"item (\d+)", text)
            if item and int(item.group(1)) < len(mission.items):
                rec["refused_phase"] = item_phase(mission.items, int(item.group(1)))
            rec["why"] = [] if ok and m.get("error") == text else \
                [f"refusal without result, item and reason: {text!r} "
                 f"(metrics error {m.get('error')!r}, status {m.get('status')!r})"]
        else:
            met = run.metrics
            rec.update(verdict="flown", status=met["status"],
                       status_reason=met.get("status_reason", ""),
                       pos_err_m=float(met["position_error_m"]["max"]),
                       att_err_deg=math.degrees(float(met["attitude_error_rad"]["max"])),
                       limit_events=[e.text for e in run.events if e.kind == "limit"])
            rec.update(judge_flight(run, [through_wire_item(i) for i in mission.items],
                                    tilt_max))
            rec["why"] = flight_violations(rec, tilt_max)
        rec["wall_s"] = time.perf_counter() - t0
        if rec["why"]:
            save_failed(Path(out), rec, mission, path, scenario)
    return rec


def save_failed(out: Path, rec: dict[str, Any], mission: PhaseMission, path: Path,
                scenario: Scenario) -> None:
    """The mission file and a scenario that re-flies it (`gcs run --in-process FILE`)."""
    folder = out / "failed"
    folder.mkdir(parents=True, exist_ok=True)
    stem = f"{rec['vehicle']}_{rec['k']}"
    mfile = folder / f"{stem}{path.suffix}"
    mfile.write_bytes(path.read_bytes())
    vehicle = os.path.relpath(scenario.files["vehicle"], folder)
    gains = os.path.relpath(ROOT / "config/gains", folder)
    params = "\n".join(f"{k} = {v!r}" for k, v in mission.params.items())
    s = mission.start_enu_m
    (folder / f"{stem}.toml").write_text(
        f'# Grammar mission {rec["seed"]} ({rec["vehicle"]}): {"; ".join(rec["why"])}\n'
        f'name = "grammar_{stem}"\nduration_s = {scenario.duration_s!r}\n'
        f'controller = "pid"\nvehicle = "{vehicle}"\nseed = 0\n\n'
        f'[gains]\npid = "{gains}/pid_eq30.toml"\npd = "{gains}/pd_eq33.toml"\n\n'
        f'[rates]\ncontrol_hz = {scenario.control_rate_hz}\n'
        f'physics_hz = {scenario.physics_rate_hz}\n\n'
        f'[initial]\nstart = "ground"\nposition_enu_m = [{s[0]!r}, {s[1]!r}, 0.0]\n\n'
        f'[trajectory]\nkind = "mission"\nmission = "{mfile.name}"\n\n[params]\n{params}\n')


def summary(results: list[dict[str, Any]], wall_s: float, args: argparse.Namespace) -> str:
    lines = [f"# Grammar-mission campaign: {args.count} missions per vehicle, seed {args.seed}",
             "", f"wall time {wall_s:.0f} s on {args.workers} workers", ""]
    lines += ["| vehicle | missions | refused at upload | refused at start | flown | "
              "flown over the property | refusals without a reason | regenerated |",
              "|---|---|---|---|---|---|---|---|"]
    for v in args.vehicles:
        rs = [r for r in results if r["vehicle"] == v]
        fl = [r for r in rs if r["verdict"] == "flown"]
        lines.append(
            f"| {v} | {len(rs)} | {sum(r.get('stage') == 'upload' for r in rs)} | "
            f"{sum(r.get('stage') == 'start' for r in rs)} | {len(fl)} | "
            f"{sum(bool(r['why']) for r in fl)} | "
            f"{sum(bool(r['why']) for r in rs if r['verdict'] == 'refused')} | "
            f"{sum(r['regenerated'] for r in rs)} |")
    lines += ["", "Per phase (missions holding it: drawn / flown; worst over flown missions "
              "of the rows in that phase):", "",
              "| vehicle | phase | missions drawn | flown | worst position error (mm) | "
              "worst attitude error (deg) | largest tilt rate (rad/s) |",
              "|---|---|---|---|---|---|---|"]
    drawn_key = {"takeoff": "takeoff", "cruise": ("leg", "loiter"),
                 "keyframe_figure": ("keyframe", "figure"), "speed": "speed",
                 "touch_and_go": "touch_and_go", "land": "land", "after_end": "end_in_air"}
    for v in args.vehicles:
        rs = [r for r in results if r["vehicle"] == v]
        for ph in PHASES:
            key = drawn_key[ph]
            keys = key if isinstance(key, tuple) else (key,)
            has = [r for r in rs if any(p in keys for p in r["phases"])]
            fl = [r for r in has if r["verdict"] == "flown"]
            vals = [r["by_phase"][ph] for r in fl if ph in r["by_phase"]]
            lines.append(
                f"| {v} | {ph} | {len(has)} | {len(fl)} | "
                f"{max((x['pos_m'] for x in vals), default=0) * 1e3:.2f} | "
                f"{max((x['att_deg'] for x in vals), default=0):.3f} | "
                f"{max((x['servo_rad_s'] for x in vals), default=0):.2f} |")
        away = [r for r in rs if r["away"]]
        fa = [r for r in away if r["verdict"] == "flown"]
        lines.append(
            f"| {v} | start away from home (whole flight) | {len(away)} | {len(fa)} | "
            f"{max((r['pos_err_m'] for r in fa), default=0) * 1e3:.2f} | "
            f"{max((r['att_err_deg'] for r in fa), default=0):.3f} | "
            f"{max((r['servo_max_rad_s'] for r in fa), default=0):.2f} |")
    lines += ["", "| vehicle | format | missions | flown |", "|---|---|---|---|"]
    for v in args.vehicles:
        for f in ("toml", "wpl_local", "wpl_global", "plan"):
            rs = [r for r in results if r["vehicle"] == v and r["fmt"] == f]
            lines.append(f"| {v} | {f} | {len(rs)} | "
                         f"{sum(r['verdict'] == 'flown' for r in rs)} |")
    flown = [r for r in results if r["verdict"] == "flown"]
    tds = [x for r in flown for x in r["touchdowns_m_s"]]
    lines += ["", f"touchdowns: {len(tds)}, fastest {max(tds, default=0):.3f} m/s; flown "
              f"missions with MIS_LAND_SPD > 1 m/s and a landing: "
              f"{sum(r['params']['MIS_LAND_SPD'] > 1 and 'land' in r['phases'] for r in flown)}"]
    hist: dict[tuple[str, str, str, str], int] = {}
    for r in results:
        if r["verdict"] == "refused":
            key = (r["vehicle"], r["stage"], r["result"] or "(none)", r["reason_kind"])
            hist[key] = hist.get(key, 0) + 1
    lines += ["", "Refusals:", "", "| vehicle | stage | result | reason | count |",
              "|---|---|---|---|---|"]
    for key, n in sorted(hist.items()):
        lines.append(f"| {' | '.join(key)} | {n} |")
    strict = [r for r in flown if r["servo_limited_rows"]]
    ep: dict[str, int] = {}
    for r in strict:
        ep[r["servo_limited_phase"]] = ep.get(r["servo_limited_phase"], 0) + 1
    lines += ["", f"flown missions with a tilt servo at its rate in any control period: "
              f"{len(strict)} (first such period by phase: "
              f"{', '.join(f'{k} {n}' for k, n in sorted(ep.items()))}); longest episode "
              f"{max((r['servo_episode_s'] for r in flown), default=0):.3f} s"]
    bad = [r for r in results if r["why"]]
    lines += ["", f"Over a property: {len(bad)}"]
    for r in bad[:40]:
        lines.append(f"- {r['vehicle']} {r['k']} ({r['fmt']}, {'/'.join(r['phases'])}): "
                     f"{'; '.join(r['why'])}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=1000, help="missions per vehicle")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=ROOT / "runs/grammar_missions")
    ap.add_argument("--vehicles", nargs="+", default=list(VEHICLES), choices=VEHICLES)
    ap.add_argument("--summarize", action="store_true",
                    help="fly nothing: summarize --out's results.jsonl (refusals judged "
                         "again)")
    args = ap.parse_args(argv)
    out: Path = args.out
    if args.summarize:
        with (out / "results.jsonl").open() as fh:
            results: list[dict[str, Any]] = [json.loads(line) for line in fh]
        for r in results:
            if r["verdict"] == "refused":
                ok, r["result"], r["reason"] = refusal_ok(r["text"])
                r["reason_kind"] = reason_kind(r["reason"])
                r["why"] = [] if ok and r["metrics_error"] == r["text"] else \
                    [f"refusal without result, item and reason: {r['text']!r}"]
        per = {v: sum(r["vehicle"] == v for r in results) for v in args.vehicles}
        args.count = min(per.values())
        text = summary(results, 0.0, args)
        print(text)
        return 1 if any(r["why"] for r in results) else 0
    out.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    jobs = [(v, k, args.seed, str(out)) for k in range(args.count) for v in args.vehicles]
    results = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool, \
            (out / "results.jsonl").open("w") as journal:
        for rec in pool.map(run_one, jobs, chunksize=1):
            results.append(rec)
            journal.write(json.dumps(rec) + "\n")
            journal.flush()
    text = summary(results, time.perf_counter() - wall0, args)
    (out / "summary.md").write_text(text)
    print(text)
    return 1 if any(r["why"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
