"""`gcs run`, `table1`, `campaign`, `report` and `replay`: flying scenarios and reporting
on what they wrote."""

from __future__ import annotations

import argparse
import dataclasses
import time

from common.config.reader import ConfigError
from common.process.diagnostics import get_logger, say
from gcs.cli.console import Progress
from gcs.report.run_metrics import RunMetrics

log = get_logger(__name__)


def _summary(m: RunMetrics) -> str:
    pos, att = m["position_error_m"], m["attitude_error_rad"]
    events = "".join(f"\n  t = {e['t_s']:8.3f} s  {e['text']}" for e in m.get("events", [])
                     if e.get("kind", "info") != "info" or e["severity"] <= 4)
    return (f"{m['scenario']} [{m['controller']}] {m['status']}"
            + (f" ({m['status_reason']})" if m.get("status_reason") else "") + events
            + f"\n  {m['sim_time_s']:.1f} s simulated in {m['wall_time_s']:.1f} s "
            f"({m['real_time_factor']:.1f}x real time)\n"
            f"  position error  max {pos['max']:.6f} m   mean {pos['mean']:.6f} m   "
            f"rmse {pos['rmse']:.6f} m\n"
            f"  attitude error  max {att['max']:.3e} rad   mean {att['mean']:.3e} rad   "
            f"rmse {att['rmse']:.3e} rad\n"
            f"  fcu step        p50 {m['fcu_step_us']['p50']:.1f} us   "
            f"p99 {m['fcu_step_us']['p99']:.1f} us   transport {m['transport']}, "
            f"lockstep {str(m['lockstep']).lower()}, mission completed "
            f"{str(m['mission_completed']).lower()}")


def cmd_run(args: argparse.Namespace) -> int:
    """Exit 0 when the run completed, 1 for any other status, 2 for bad input."""
    from common.config.scenario import load_scenario  # numba: only for the commands that fly
    from gcs.run.overrides import apply_overrides
    from gcs.run.process_run import Progress as RunProgress
    from gcs.run.process_run import RunError, fleet_of, one_vehicle, run_processes
    from gcs.run.runio import RunDirError, prepare_run_dir, write_run

    scenario = apply_overrides(load_scenario(args.scenario), controller=args.controller,
                               ideal_actuators=True if args.ideal_actuators else None,
                               duration_s=args.duration, sensors=args.sensors,
                               seed=args.seed)
    if args.fleet < 1:
        log.error("gcs run: --fleet needs at least 1 vehicle")
        return 2
    try:
        prepare_run_dir(args.out, args.force)
    except RunDirError as exc:
        log.error(f"gcs run: {exc}")
        return 2
    progress = Progress()
    if args.in_process:
        from gcs.run.inprocess import InProcessError, run_scenario  # loads the FCU and plant

        progress(f"{scenario.name}: running {scenario.duration_s:.0f} s in-process ...")
        try:
            result = run_scenario(scenario)
        except InProcessError as exc:
            if exc.result is None:
                progress.done()
                log.error(f"gcs run: {exc}")
                return 1
            result = exc.result  # refused by the vehicle: recorded as a process run records it
        write_run(args.out, scenario, result)
        metrics = result.metrics
    else:
        def report(p: RunProgress) -> None:
            elapsed = time.monotonic() - progress.t0
            progress(f"{scenario.name}: t = {p.sim_time_s:7.2f} / {scenario.duration_s:.0f} s"
                     f"   {p.sim_time_s / max(elapsed, 1e-3):5.1f}x real time")
        try:
            outcome = run_processes(scenario, args.out, realtime=args.realtime,
                                    transport=args.link, report=report, fleet=args.fleet,
                                    spacing_m=args.spacing, zenoh_url=args.zenoh,
                                    signing_key_file=args.signing_key)
        except RunError as exc:
            progress.done()
            log.error(f"gcs run: {exc}")
            return 1
        if args.fleet > 1:
            progress.done()
            fleet = fleet_of(outcome)
            for m in fleet["vehicles"].values():
                _print_error(m)
                say(f"vehicle {m['system_id']}: " + _summary(m))
            say(f"  wrote {args.out / 'fleet.json'}")
            return 0 if fleet["all_completed"] else 1
        metrics = one_vehicle(outcome)
    progress.done()
    _print_error(metrics)
    say(_summary(metrics))
    say(f"  wrote {args.out / 'metrics.json'}")
    return 0 if metrics["status"] == "completed" else 1


def _print_error(m: RunMetrics) -> None:
    if m.get("error"):
        log.error(f"gcs run: {m['error']}")


def cmd_table1(args: argparse.Namespace) -> int:
    from common.config.sensors import resolve_sensor_profile
    from gcs.run.table1_run import run_table1

    progress = Progress()
    progress(f"table1: {16 if args.lag_comp == 'both' else 8} runs ...")
    try:
        if args.sensors is not None:
            resolve_sensor_profile(args.sensors)  # a bad name: one line, before any run
    except ConfigError as exc:
        progress.done()
        log.error(f"gcs table1: {exc}")
        return 2
    table = run_table1(args.scenarios, args.out, ideal=args.ideal_actuators,
                       duration_s=args.duration, workers=args.jobs,
                       in_process=args.in_process, progress=progress,
                       lag_comp=args.lag_comp, sensors=args.sensors, seed=args.seed)
    progress.done()
    say((args.out / "table1.md").read_text())
    say(f"wrote {args.out / 'table1.md'}, {args.out / 'table1.json'} and "
        f"{args.out / 'table1.png'}")
    return 0 if table["rows"] else 1


def cmd_campaign(args: argparse.Namespace) -> int:
    """Exit 0 when every run is recorded (whatever its status), 1 when runs could not be
    executed, 2 for bad input."""
    from gcs.campaign.journal import read_journal
    from gcs.campaign.load import load_campaign
    from gcs.campaign.model import CampaignError
    from gcs.campaign.run import run_campaign
    from gcs.campaign.runs import expand

    try:
        campaign = load_campaign(args.campaign)
        if args.transport is not None:
            campaign = dataclasses.replace(campaign, transport=args.transport)
        if args.workers is not None and args.workers < 1:
            raise CampaignError("--workers needs at least 1")
        if args.scheduler is not None and args.workers is not None:
            raise CampaignError("--workers sizes a local cluster: not with --scheduler")
        if args.out.exists() and not args.out.is_dir():
            raise CampaignError(f"{args.out}: not a folder")
        total = len(expand(campaign, args.out))
    except CampaignError as exc:
        log.error(f"gcs campaign: {exc}")
        return 2
    done = len(read_journal(args.out)) if args.out.is_dir() else 0
    log.info(f"campaign {campaign.name}: {total} runs ({campaign.transport}); "
              f"{min(done, total)} recorded in {args.out} already")
    dashboard = None if args.dashboard.lower() == "none" else args.dashboard
    try:
        outcome = run_campaign(campaign, args.out, scheduler=args.scheduler,
                               workers=args.workers, dashboard=dashboard,
                               report=not args.no_report)
    except OSError as exc:  # no scheduler at that address, a cluster that did not start
        log.error(f"gcs campaign: {exc}")
        return 1
    flown = outcome.flown
    rate = outcome.sim_s / outcome.wall_s if outcome.wall_s > 0 and flown else 0.0
    say(f"campaign {campaign.name}: {len(outcome.rows)}/{outcome.total} runs recorded "
        f"({outcome.recorded_before} before, {flown} flown now in {outcome.wall_s:.1f} s "
        f"on {outcome.workers} workers after {outcome.startup_s:.1f} s of start-up: "
        f"{rate:.1f} simulated s per wall s)")
    for index, why in sorted(outcome.failed.items()):
        log.warning(f"gcs campaign: run {index} not executed: {why}")
    say(f"  wrote {args.out / 'results.csv'}"
        + ("" if args.no_report else f" and {args.out / 'summary.md'}"))
    return outcome.exit_code


def cmd_replay(args: argparse.Namespace) -> int:
    """The estimator re-run on an onboard log (gcs.run.replay): 0 agree, 1 differ, 2 bad input."""
    from gcs.run.replay import main as replay_main

    return replay_main(args)


def cmd_report(args: argparse.Namespace) -> int:
    """A run folder (metrics.json) or a table1 folder (table1.json). Exit status: 0 when
    everything was reported, 1 when a table1 folder's run folder is missing or could not be
    read (the rest is reported), 2 for a path that is neither kind of folder."""
    from gcs.report.names import TABLE1_JSON
    from gcs.report.run_report import make_report
    from gcs.report.table1_report import is_table1_dir, make_table1_report
    from gcs.run.runio import RunDirError, check_run_dir

    if is_table1_dir(args.run_dir):
        def warn(problem: str) -> None:
            log.warning(f"gcs report: {problem}")

        result = make_table1_report(args.run_dir, warn=warn)
        for path in result.written:
            say(str(path))
        if result.problems:
            log.error(f"gcs report: {len(result.problems)} problem(s); everything else in "
                      f"{args.run_dir} was reported")
        return 1 if result.problems else 0
    if not (args.run_dir / "metrics.json").exists():
        log.error(f"gcs report: {args.run_dir} has neither metrics.json (a run folder) nor "
                  f"{TABLE1_JSON} (a table1 folder)")
        return 2
    try:
        check_run_dir(args.run_dir)
    except RunDirError as exc:
        log.error(f"gcs report: {exc}")
        return 2
    for path in make_report(args.run_dir):
        say(str(path))
    return 0
