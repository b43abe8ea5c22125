"""Random-mission campaign: `--count` random missions per vehicle (hexa_tilted, hexa_planar),
each checked by the FCU's upload check with the FCU's own limits and, if accepted, flown
in-process (truth sensors); a sub-sample flown again with mocap-indoor.

    .venv/bin/python benchmarks/random_missions.py --count 1000 --workers 2

Missions: benchmarks/random_mission_gen.py (distributions stated there). Mission k of a
campaign seed S is drawn from numpy's default_rng((S, k)) for both vehicles; a mission whose
planned timeline (the FCU's plan with its envelope stretching) exceeds `--max-s` (120 s) is
drawn again from the same generator (counted: `regenerated`). Each mission flies for its
planned end + 3 s, its MIS_CRUISE_SPD set as a scenario parameter.

Per accepted mission, over the rows from the planned end of the takeoff (item 0) to the run's
end, matched on time_us (truth rows and onboard rows), leaving out rows where the vehicle
rests on the ground or is disarmed and the touchdown set-point below the ground plane:
the largest |p_truth - p_ref| and the largest angle between the truth attitude and the
reference attitude. PROPERTY (truth sensors): status "completed", position error <= 5 cm,
attitude error <= 3 deg, and no monitor event ("rate-limited", "at its speed limit").
Mocap sub-sample (`--sample` K): each mission's position error <= its truth-sensor error + its
estimation error (max |p_estimate - p_truth| over the same rows) + 2 cm.

Results in --out: results.jsonl (a line per flight), summary.md (counts, refusal reasons,
envelope table, wall time), envelope.png, failed/ (each violating mission as a mission TOML
and a scenario TOML that re-flies it). Exit code 0 only if the property holds everywhere.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.random_mission_gen import (
    DEFAULT,
    NAV_WAYPOINT,
    MissionDistributions,
    item_kind,
    leg_lengths_m,
    random_cruise_speed,
    random_mission,
)
from common.config.scenario import Scenario, TrajectoryConfig, load_scenario, load_vehicle
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.wire.mission_items import PX4_SITL_HOME, MissionItem
from fcu.compose import published_home
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission
from gcs.mission_files import read_mission, write_mission
from gcs.run.inprocess import (
    fcu_pipeline,
    run_scenario,
    through_wire_item,
)
from gcs.run.overrides import apply_overrides

ROOT = Path(__file__).resolve().parents[1]
VEHICLES = ("hexa_tilted", "hexa_planar")
BASE_SCENARIO = ROOT / "config/scenarios/mission_tour.toml"
POS_LIMIT_M = 0.05
ATT_LIMIT_DEG = 3.0
MOCAP_MARGIN_M = 0.02
MONITOR_WORDS = ("rate-limited", "at its speed limit")
TAIL_S = 3.0  # the run goes on this long after the planned end
Q_ID = (1.0, 0.0, 0.0, 0.0)


def base_scenario(vehicle: str, sensors: str = "truth") -> Scenario:
    """The mission scenario with `vehicle` (config/vehicles/NAME.toml) and a sensor profile."""
    base = load_scenario(BASE_SCENARIO)
    path = ROOT / "config/vehicles" / f"{vehicle}.toml"
    base = dataclasses.replace(base, vehicle=load_vehicle(path),
                               files={**base.files, "vehicle": str(path)})
    return apply_overrides(base, sensors=sensors)


def with_mission(base: Scenario, mission_file: Path, cruise_m_s: float, duration_s: float,
                 name: str, seed: int) -> Scenario:
    """`base` flying `mission_file` at MIS_CRUISE_SPD `cruise_m_s` for `duration_s`."""
    traj = TrajectoryConfig(kind="mission", position_enu_m=base.initial_position_enu_m,
                            mission_file=str(mission_file))
    return dataclasses.replace(base, name=name, trajectory=traj, duration_s=duration_s,
                               seed=seed, params={**base.params, "MIS_CRUISE_SPD": cruise_m_s})


def fcu_limits(scenario: Scenario) -> MissionLimits:
    """The mission limits the FCU puts in force for this scenario (its parameters)."""
    return fcu_pipeline(scenario)[0].commander.limits


def schedule(items: list[MissionItem], limits: MissionLimits,
             start_enu_m: tuple[float, float, float]) -> tuple[tuple[int, float, float], ...]:
    """(seq, start, end) of each item as the FCU's executor plans it from the start pose."""
    ex = MissionExecutor(items, limits)
    ex.start(0.0, start_enu_m, Q_ID)
    return ex.schedule


def reason_kind(reason: str) -> str:
    """A refusal reason's kind (for the histogram)."""
    r = reason.lower()
    if "geofence" in r:
        return "geofence"
    if "tilt servo" in r:
        return "tilt servo rate" if "rad/s^2" not in r else "tilt servo acceleration"
    if "attitude too demanding" in r:
        return "attitude (any speed)"
    if "rotor" in r and ("must slow" in r or "rad/s^2" in r or "rate" in r):
        return "rotor rate"
    if "rotor" in r and "lag" in r:
        return "rotor speed (lag)"
    if "rotor" in r:
        return "rotor speed"
    return "other: " + " ".join(r.split()[:4]) if r else "other (no reason)"


@dataclasses.dataclass
class Prepared:
    items: list[MissionItem]
    cruise_m_s: float
    regenerated: int
    check: Any  # fcu.mission.MissionCheck
    planned: tuple[tuple[int, float, float], ...]
    nominal: tuple[tuple[int, float, float], ...]
    scenario: Scenario


def prepare(base: Scenario, k: int, seed: int, workdir: Path, max_s: float,
            dist: MissionDistributions = DEFAULT, vehicle: str = "") -> Prepared:
    """Mission k: drawn (again while planned longer than max_s), written as a mission file
    and read back as the FCU gets it (file, then MISSION_ITEM_INT), checked with the FCU's
    limits, planned with and without the vehicle's envelope."""
    rng = np.random.default_rng((seed, k))
    path = workdir / f"{vehicle or base.vehicle.name}_{k}.mission.toml"
    regenerated = 0
    while True:
        cruise = random_cruise_speed(rng, dist)
        drawn = random_mission(rng, dist)
        scenario = with_mission(base, path, cruise, 1.0, f"random_{vehicle}_{k}", k)
        lim = fcu_limits(scenario)
        write_mission(path, drawn)
        items = [through_wire_item(it) for it in read_mission(path)]
        start = base.initial_position_enu_m
        planned = schedule(items, lim, start)
        if planned[-1][2] <= max_s:
            break
        regenerated += 1
    check = check_mission(items, lim, published_home(PX4_SITL_HOME))
    nominal = schedule(items, dataclasses.replace(lim, vehicle=None), start)
    scenario = dataclasses.replace(scenario, duration_s=planned[-1][2] + TAIL_S)
    return Prepared(items, cruise, regenerated, check, planned, nominal, scenario)


def _angle_deg(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    dot = np.abs(np.sum(q * qd, axis=1)) / (np.linalg.norm(q, axis=1)
                                           * np.linalg.norm(qd, axis=1))
    angle: np.ndarray = np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))
    return angle


def tracking_errors(truth: np.ndarray, onboard: np.ndarray, t_from_us: float
                    ) -> dict[str, float]:
    """Largest position and attitude errors (truth vs reference) and estimation errors
    (estimate vs truth) over the matched rows from t_from_us on (module docstring)."""
    tc, oc = TRUTH_COLUMNS.index, ONBOARD_COLUMNS.index
    t_truth, t_on = truth[:, tc("time_us")], onboard[:, oc("time_us")]
    _, it, io = np.intersect1d(t_truth, t_on, assume_unique=False, return_indices=True)
    tr, on = truth[it], onboard[io]
    keep = ((on[:, oc("time_us")] >= t_from_us) & (tr[:, tc("landed")] < 0.5)
            & (on[:, oc("armed")] > 0.5) & (on[:, oc("pdz")] > -1e-6))
    tr, on = tr[keep], on[keep]
    if not len(tr):
        return {"pos_err_m": math.nan, "att_err_deg": math.nan, "est_pos_err_m": math.nan,
                "est_att_err_deg": math.nan, "rows": 0}
    p = tr[:, [tc("px"), tc("py"), tc("pz")]]
    q = tr[:, [tc("qw"), tc("qx"), tc("qy"), tc("qz")]]
    pd = on[:, [oc("pdx"), oc("pdy"), oc("pdz")]]
    qd = on[:, [oc("qdw"), oc("qdx"), oc("qdy"), oc("qdz")]]
    pe = on[:, [oc("px"), oc("py"), oc("pz")]]
    qe = on[:, [oc("qw"), oc("qx"), oc("qy"), oc("qz")]]
    return {"pos_err_m": float(np.max(np.linalg.norm(p - pd, axis=1))),
            "att_err_deg": float(np.max(_angle_deg(q, qd))),
            "est_pos_err_m": float(np.max(np.linalg.norm(pe - p, axis=1))),
            "est_att_err_deg": float(np.max(_angle_deg(qe, q))), "rows": len(tr)}


def monitor_events(events: list[Any]) -> list[str]:
    return [e.text for e in events if any(w in e.text for w in MONITOR_WORDS)]


def fly(prep: Prepared, scenario: Scenario | None = None) -> dict[str, Any]:
    """Fly an accepted mission; the errors, events and status."""
    scenario = scenario or prep.scenario
    t0 = time.perf_counter()
    try:
        run = run_scenario(scenario, logs=False)
    except Exception as exc:
        return {"status": "error", "status_reason": f"{type(exc).__name__}: {exc}",
                "monitor_events": [], "wall_s": time.perf_counter() - t0}
    start = [e.t_us for e in run.events if e.text == "mission started"]
    start_us = start[0] if start else 0
    takeoff_end_s = prep.planned[0][2]
    errors = tracking_errors(run.truth, run.onboard, start_us + takeoff_end_s * 1e6)
    return {**errors, "status": run.metrics["status"],
            "status_reason": run.metrics["status_reason"],
            "monitor_events": monitor_events(run.events), "wall_s": time.perf_counter() - t0}


def violations(flight: dict[str, Any]) -> list[str]:
    """Why a truth-sensor flight breaks the property ([] if it holds)."""
    why = []
    if flight["status"] != "completed":
        why.append(f"status {flight['status']}: {flight['status_reason']}")
    pos, att = flight.get("pos_err_m", math.nan), flight.get("att_err_deg", math.nan)
    if not pos <= POS_LIMIT_M:
        why.append(f"position error {pos * 100:.1f} cm > {POS_LIMIT_M * 100:.0f} cm")
    if not att <= ATT_LIMIT_DEG:
        why.append(f"attitude error {att:.2f} deg > {ATT_LIMIT_DEG:.0f} deg")
    if flight["monitor_events"]:
        why.append(f"monitor: {flight['monitor_events'][0]}")
    return why


def record(vehicle: str, k: int, seed: int, prep: Prepared) -> dict[str, Any]:
    """The mission's line in results.jsonl before any flight."""
    kinds: dict[str, int] = {}
    for it in prep.items:
        kinds[item_kind(it)] = kinds.get(item_kind(it), 0) + 1
    stretched = [p[0] for p, n in zip(prep.planned, prep.nominal, strict=True)
                 if p[2] - p[1] > n[2] - n[1] + 1e-6]
    by_seq = {s: t1 - t0 for s, t0, t1 in prep.planned}
    legs = []
    for seq, length in leg_lengths_m(prep.items):  # waypoint legs: those at cruise speed
        if prep.items[seq].command == NAV_WAYPOINT and length >= 1e-3:
            travel = by_seq[seq] - prep.items[seq].param1
            legs.append([seq, length, length / travel if travel > 0 else 0.0])
    accepted = prep.check.result == 0
    return {"seed": [seed, k], "vehicle": vehicle, "k": k, "n_items": len(prep.items),
            "kinds": kinds, "cruise_m_s": prep.cruise_m_s, "regenerated": prep.regenerated,
            "verdict": "accepted" if accepted else "refused",
            "result": prep.check.result, "reason": prep.check.reason,
            "reason_kind": "" if accepted else reason_kind(prep.check.reason),
            "refused_item": "" if accepted or prep.check.seq is None
            else item_kind(prep.items[prep.check.seq]),
            "planned_s": prep.planned[-1][2], "nominal_s": prep.nominal[-1][2],
            "stretched": bool(stretched), "stretched_items": stretched, "legs": legs}


def save_failed(out: Path, rec: dict[str, Any], prep: Prepared) -> None:
    """The mission file and a scenario file that re-flies it (relative paths)."""
    folder = out / "failed"
    folder.mkdir(parents=True, exist_ok=True)
    suffix = "" if rec["sensors"] == "truth" else f"_{rec['sensors']}"
    stem = f"{rec['vehicle']}_{rec['k']}{suffix}"
    write_mission(folder / f"{stem}.mission.toml", prep.items)
    vehicle = os.path.relpath(prep.scenario.files["vehicle"], folder)
    gains = os.path.relpath(ROOT / "config/gains", folder)
    (folder / f"{stem}.toml").write_text(
        f'# Random mission {rec["seed"]} ({rec["vehicle"]}): {"; ".join(rec["why"])}\n'
        f'name = "random_{stem}"\nduration_s = {prep.scenario.duration_s!r}\n'
        f'controller = "pid"\nvehicle = "{vehicle}"\nseed = {rec["k"]}\n'
        f'sensors = "{rec["sensors"]}"\n\n'
        f'[gains]\npid = "{gains}/pid_eq30.toml"\npd = "{gains}/pd_eq33.toml"\n\n'
        f'[rates]\ncontrol_hz = {prep.scenario.control_rate_hz}\n'
        f'physics_hz = {prep.scenario.physics_rate_hz}\n\n'
        f'[initial]\nstart = "ground"\n\n[trajectory]\nkind = "mission"\n'
        f'mission = "{stem}.mission.toml"\n\n[params]\nMIS_CRUISE_SPD = {prep.cruise_m_s!r}\n')


def mocap_violations(flight: dict[str, Any], truth_pos_err_m: float) -> list[str]:
    """Why a mocap-indoor flight breaks its bound: truth-sensor error + estimation + 2 cm."""
    bound = truth_pos_err_m + flight.get("est_pos_err_m", math.nan) + MOCAP_MARGIN_M
    flight["mocap_bound_m"] = bound
    pos = flight.get("pos_err_m", math.nan)
    if pos <= bound:
        return []
    return [f"mocap position error {pos * 100:.1f} cm > {bound * 100:.1f} cm (truth + "
            f"estimation + 2 cm; status {flight['status']}: {flight['status_reason']})"]


def run_one(job: tuple[str, int, int, float, str, str, float | None]) -> dict[str, Any]:
    """Worker: one mission on one vehicle (mission k of `seed`) with `sensors`, flown if
    accepted and checked: against the property, or, given the mission's truth-sensor error
    (the mocap sample), against `mocap_violations`; failures saved in `out`/failed."""
    vehicle, k, seed, max_s, sensors, out, truth_pos_err_m = job
    with tempfile.TemporaryDirectory() as tmp:
        prep = prepare(base_scenario(vehicle, sensors), k, seed, Path(tmp), max_s,
                       vehicle=vehicle)
        rec = record(vehicle, k, seed, prep)
        rec["sensors"] = sensors
        if rec["verdict"] == "accepted":
            rec.update(fly(prep))
            rec["why"] = violations(rec) if truth_pos_err_m is None \
                else mocap_violations(rec, truth_pos_err_m)
            if rec["why"]:
                save_failed(Path(out), rec, prep)
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=1000, help="missions per vehicle")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=ROOT / "runs/random_missions")
    ap.add_argument("--sensors", choices=("truth", "mocap-indoor"), default="truth",
                    help="the profile of the main flights (the property applies to them; "
                         "the mocap sub-sample follows truth flights only)")
    ap.add_argument("--sample", type=int, default=200,
                    help="accepted missions flown again with mocap-indoor (0: none)")
    ap.add_argument("--max-s", type=float, default=120.0, help="longest planned mission")
    ap.add_argument("--vehicles", nargs="+", default=list(VEHICLES), choices=VEHICLES)
    args = ap.parse_args(argv)
    from benchmarks.random_missions_report import write_report

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    jobs = [(v, k, args.seed, args.max_s, args.sensors, str(out), None)
            for v in args.vehicles for k in range(args.count)]
    results: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool, \
            (out / "results.jsonl").open("w") as journal:
        for rec in pool.map(run_one, jobs, chunksize=1):
            results.append(rec)
            journal.write(json.dumps(rec) + "\n")
            journal.flush()
        accepted = [r for r in results if r["verdict"] == "accepted"
                    and r.get("status") != "error" and args.sensors == "truth"]  # vs truth
        rng = np.random.default_rng((args.seed, 1))
        picked = [accepted[i] for i in sorted(rng.permutation(len(accepted))[:args.sample])]
        sample = [(r["vehicle"], r["k"], args.seed, args.max_s, "mocap-indoor", str(out),
                   r.get("pos_err_m", math.nan)) for r in picked]
        mocap: list[dict[str, Any]] = []
        for rec in pool.map(run_one, sample, chunksize=1):
            mocap.append(rec)
            journal.write(json.dumps(rec) + "\n")
            journal.flush()
    wall = time.perf_counter() - wall0
    text, ok = write_report(out, results, mocap, wall, args)
    print(text)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
