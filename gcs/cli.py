"""`gcs`: the ground-station command line.

Runs and reports:
    gcs run SCENARIO.toml [--in-process | --realtime] [--controller pid|pd]
            [--ideal-actuators] [--duration S] [--sensors PROFILE] [--seed N]
            [--link udp|tcp|zenoh] [--zenoh URL] [--fleet N [--spacing METRES]] --out DIR
    gcs router [--listen ENDPOINT]
    gcs keygen FILE
    gcs table1 [--in-process] [--ideal-actuators] [--duration S] [--sensors PROFILE]
            [--seed N] [--lag-comp both|on|off] --out DIR
    gcs campaign CAMPAIGN.toml --out DIR [--scheduler tcp://HOST:8786] [--workers N]
    gcs report RUN_DIR | TABLE1_DIR
Against a vehicle (any MAVLink 2 autopilot; --connect URL, default udpin:127.0.0.1:14550):
    gcs status [--json] | arm | disarm [--force] | mode NAME | takeoff [--alt M]
    gcs mission upload FILE | download [FILE] [--frame global|local] | clear | start
            (FILE: .plan QGC plan, .waypoints/.txt QGC WPL 110, .toml; or --format)
    gcs param list | get NAME | set NAME VALUE | save FILE | load FILE   (QGC .params)
    gcs goto X Y Z [--roll D --pitch D --yaw D] [--arm]     (local NED, m and deg)
    (PX4, ArduPilot and this FCU: the autopilot is told by its HEARTBEAT; mode names are its
    own or HOLD, LOITER, MISSION, TAKEOFF, LAND, RTL, POSCTL, OFFBOARD, mapped per autopilot)
    gcs watch
    gcs view [--port 8765] [--mcap FILE] | view RUN_DIR [--speed X]   (Foxglove WebSocket)
    gcs log record FILE [--duration S]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

from common.cliargs import OneLineParser
from common.config import ConfigError, load_scenario
from common.links import LinkError, parse_url
from common.sensors_config import resolve_sensor_profile

DEFAULT_SCENARIOS = Path(__file__).resolve().parent.parent / "config" / "scenarios"
DEFAULT_CONNECT = "udpin:127.0.0.1:14550"
HEARTBEAT_WAIT_S = 10.0  # --wait's default for the vehicle's heartbeat


class Progress:
    """One self-overwriting status line on a terminal; silent when piped."""

    def __init__(self, stream=sys.stderr) -> None:
        self.stream = stream
        self.active = stream.isatty()
        self.t0 = time.monotonic()

    def __call__(self, text: str) -> None:
        if self.active:
            self.stream.write(f"\r\033[K{text}")
            self.stream.flush()

    def done(self) -> None:
        if self.active:
            self.stream.write("\r\033[K")
            self.stream.flush()


class InputError(ValueError):
    """Bad input found before anything is opened: one line, exit status 2."""


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text}") from None
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text}") from None
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"expected 0..2^63-1, got {text}")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    link = OneLineParser(add_help=False)
    link.add_argument("--connect", default=DEFAULT_CONNECT, metavar="URL",
                      help=f"link URL: udpin/udpout/tcp/tcpin:HOST:PORT, serial:DEVICE:BAUD, "
                           f"zenoh:PREFIX[@ENDPOINT], or MAVSDK's udpin://, udp://, tcp://, "
                           f"serial:// forms (default {DEFAULT_CONNECT})")
    link.add_argument("--sysid", type=int, help="the vehicle's system id (default: first heard)")
    link.add_argument("--wait", type=_positive, default=None, metavar="S",
                      help=f"how long to wait for the vehicle's heartbeat (default "
                           f"{HEARTBEAT_WAIT_S:g}); mode and takeoff: also for the HEARTBEAT "
                           f"that shows the mode engaged (default 3)")
    link.add_argument("--signing-key", metavar="FILE",
                      help="sign with this MAVLink 2 key and refuse unsigned input")

    parser = OneLineParser(prog="gcs", description="dqflight ground station",
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n", 2)[2])
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="fly a scenario and write DIR/metrics.json")
    run.add_argument("scenario", type=Path)
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--in-process", action="store_true",
                      help="compose the FCU core and the plant in this process")
    mode.add_argument("--realtime", action="store_true",
                      help="sitl and fcu paced by the wall clock instead of lockstep")
    run.add_argument("--controller", choices=("pid", "pd"),
                     help="override the scenario's controller")
    run.add_argument("--ideal-actuators", action="store_true",
                     help="rotors and tilt servos follow their commands instantly")
    run.add_argument("--duration", type=_positive, metavar="S",
                     help="cut the scenario short after S simulated seconds")
    run.add_argument("--sensors", metavar="PROFILE",
                     help="sensor profile: truth (the exact state, no estimator), "
                          "mocap-indoor, degraded (config/sensors/) or a .toml file; "
                          "default: the scenario's, else truth")
    run.add_argument("--seed", type=_seed, metavar="N",
                     help="seed of the sensors' noise (default: the scenario's seed key)")
    run.add_argument("--link", choices=("udp", "tcp", "zenoh"), default="udp",
                     help="links between the processes: udp (default), tcp (simulator link "
                          "over TCP) or zenoh (every link over Zenoh)")
    run.add_argument("--zenoh", default="zenoh:mavlink", metavar="URL",
                     help="zenoh:PREFIX[@ENDPOINT,...] for --link zenoh (default: prefix "
                          "mavlink, router tcp/127.0.0.1:7447, started if none runs)")
    run.add_argument("--fleet", type=int, default=1, metavar="N",
                     help="fly N vehicles (system ids 1..N) on one fabric")
    run.add_argument("--spacing", type=_finite, default=0.0, metavar="METRES",
                     help="fleet: start vehicles this far apart along east")
    run.add_argument("--signing-key", metavar="FILE",
                     help="sign the GCS links of the run with this key (gcs keygen)")
    run.add_argument("--out", type=Path, required=True, metavar="DIR")
    run.add_argument("--force", action="store_true",
                     help="empty DIR first if it holds anything (a folder holds one run)")

    t1 = sub.add_parser("table1", help="Case I and Case II, PID and PD, beside the paper")
    t1.add_argument("--in-process", action="store_true",
                    help="run in this machine's processes without MAVLink")
    t1.add_argument("--ideal-actuators", action="store_true")
    t1.add_argument("--duration", type=_positive, metavar="S")
    t1.add_argument("--sensors", metavar="PROFILE",
                    help="sensor profile of every run (as gcs run --sensors)")
    t1.add_argument("--seed", type=_seed, metavar="N", help="seed of the sensors' noise")
    t1.add_argument("--lag-comp", choices=("both", "on", "off"), default="both",
                    help="allocations flown: the FCU's (CA_LAG_COMP 1), the paper's plain "
                         "one (0, in DIR/plain/), or both (default)")
    t1.add_argument("--scenarios", type=Path, default=DEFAULT_SCENARIOS, metavar="DIR",
                    help="folder holding the four scenario files")
    t1.add_argument("--jobs", type=int, default=None, help="parallel runs")
    t1.add_argument("--out", type=Path, required=True, metavar="DIR")

    cp = sub.add_parser("campaign", help="fly a campaign of runs (grid, Monte-Carlo) on Dask")
    cp.add_argument("campaign", type=Path, help="campaign file (config/campaigns/)")
    cp.add_argument("--out", type=Path, required=True,
                    help="campaign folder: results.csv, runs.jsonl, summary.md; resumed "
                         "if it holds runs already")
    cp.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                    help="a running Dask scheduler (default: a local cluster on 127.0.0.1)")
    cp.add_argument("--workers", type=int, default=None,
                    help="local cluster's worker processes (default: one per CPU)")
    cp.add_argument("--dashboard", default="127.0.0.1:8787", metavar="HOST:PORT|none",
                    help="local cluster's dashboard address (default 127.0.0.1:8787)")
    cp.add_argument("--transport", choices=("in-process", "udp", "tcp", "zenoh"),
                    default=None, help="override the campaign file's transport")
    cp.add_argument("--no-report", action="store_true", help="no summary.md and figures")
    rt = sub.add_parser("router", help="a Zenoh router for the machine (or for others)")
    rt.add_argument("--listen", action="append", metavar="ENDPOINT",
                    help="endpoint to listen on, repeatable (default tcp/127.0.0.1:7447)")

    kg = sub.add_parser("keygen", help="write a new MAVLink 2 signing key (mode 0600)")
    kg.add_argument("file", type=Path)

    rep = sub.add_parser("report", help="figures and report.md of a run folder, or of a "
                         "gcs table1 folder and all its runs")
    rep.add_argument("run_dir", type=Path)

    rpl = sub.add_parser(
        "replay", help="re-run the estimator on an onboard.ulg's sensor topics and compare "
        "with the logged estimate (exit 0 agree, 1 differ, 2 bad input)",
        description="Re-run the estimator on the log's sensor_combined and "
        "vehicle_visual_odometry (merged in the order the FCU received them) with the "
        "log's parameters, and compare its estimate with dq_onboard's at every control "
        "step. Exit status: 0 agree (to float rounding, normally bit-identical), 1 differ "
        "(expected with --param), 2 bad input.")
    rpl.add_argument("log", type=Path, help="an onboard.ulg of a run with the estimator")
    rpl.add_argument("--out", type=Path, metavar="FILE",
                     help="write the replayed estimate at each control step (time_us, px..wz "
                          "as in dq_onboard): CSV if FILE ends in .csv, else JSON "
                          "{\"columns\": [...], \"rows\": [...]}")
    rpl.add_argument("--param", action="append", metavar="NAME=VALUE",
                     help="override a logged parameter for the replay (repeatable), e.g. "
                          "EKF_EVP_NOISE=0.01")

    st = sub.add_parser("status", parents=[link],
                        help="identity, mode, position, attitude, health")
    st.add_argument("--json", action="store_true", help="print one JSON document")
    sub.add_parser("arm", parents=[link], help="arm the vehicle")
    dis = sub.add_parser("disarm", parents=[link], help="disarm the vehicle")
    dis.add_argument("--force", action="store_true", help="disarm even in the air")
    md = sub.add_parser("mode", parents=[link], help="change the flight mode")
    md.add_argument("name", help="the vehicle's own mode (ArduCopter: STABILIZE, ALT_HOLD, "
                                 "AUTO, GUIDED, LOITER, RTL, LAND, POSHOLD, BRAKE, ...; PX4: "
                                 "HOLD, MISSION, POSCTL, OFFBOARD, ALTCTL, MANUAL, ...) or a "
                                 "portable one: HOLD, LOITER, MISSION, TAKEOFF, LAND, RTL, "
                                 "POSCTL, OFFBOARD (mapped per autopilot; TAKEOFF: as gcs "
                                 "takeoff, without waiting for the height); case-insensitive. "
                                 "Exit 0 only once a HEARTBEAT shows the mode")
    tk = sub.add_parser("takeoff", parents=[link],
                        help="take off to --alt above home (armed, on the ground) and wait "
                             "until there",
                        description="ArduCopter: GUIDED, then MAV_CMD_NAV_TAKEOFF (metres "
                                    "above home); PX4 and this FCU: MAV_CMD_NAV_TAKEOFF (home's "
                                    "altitude AMSL + --alt). Waits until the vehicle is within "
                                    "--tolerance of the height (--no-wait: returns once "
                                    "accepted). Exit 1 when disarmed, in the air, refused or "
                                    "not there within --timeout.")
    tk.add_argument("--alt", type=_positive, default=10.0, metavar="M",
                    help="metres above home (default 10)")
    tk.add_argument("--tolerance", type=_positive, default=0.5, metavar="M",
                    help="reached within this much of --alt (default 0.5)")
    tk.add_argument("--timeout", type=_positive, default=60.0, metavar="S",
                    help="how long to wait for the height (default 60)")
    tk.add_argument("--no-wait", action="store_true",
                    help="return once the takeoff is accepted")

    mis = sub.add_parser("mission", help="upload, download, clear, start")
    msub = mis.add_subparsers(dest="action", required=True)
    up = msub.add_parser("upload", parents=[link],
                         help="upload a QGC .plan, QGC WPL 110 or TOML file")
    up.add_argument("file", type=Path)
    up.add_argument("--format", choices=("plan", "wpl", "toml"), default=None,
                    help="file format (default: by extension .plan, .waypoints, .toml; "
                         "else by content)")
    down = msub.add_parser("download", parents=[link], help="download (to FILE or stdout)")
    down.add_argument("file", type=Path, nargs="?")
    down.add_argument("--format", choices=("plan", "wpl", "toml"), default=None,
                      help="file format (default: by extension .plan, .toml, else QGC WPL)")
    down.add_argument("--frame", choices=("global", "local"), default=None,
                      help="write positions in MAV_FRAME_GLOBAL_RELATIVE_ALT (lat, lon deg, "
                           "alt above home: what MAVProxy's wp load and QGC take) or "
                           "MAV_FRAME_LOCAL_NED, through the vehicle's home (default: as "
                           "uploaded; global for .plan)")
    msub.add_parser("clear", parents=[link], help="clear the vehicle's mission")
    msub.add_parser("start", parents=[link], help="MISSION_START (arm first)")

    par = sub.add_parser("param", help="list, get, set parameters")
    psub = par.add_subparsers(dest="action", required=True)
    psub.add_parser("list", parents=[link])
    pg = psub.add_parser("get", parents=[link])
    pg.add_argument("name")
    ps = psub.add_parser("set", parents=[link])
    ps.add_argument("name")
    ps.add_argument("value", type=_finite)
    psave = psub.add_parser("save", parents=[link],
                            help="write every parameter to FILE (QGC .params)")
    psave.add_argument("file", type=Path)
    pload = psub.add_parser("load", parents=[link],
                            help="set every parameter of FILE (QGC .params)")
    pload.add_argument("file", type=Path)

    go = sub.add_parser("goto", parents=[link],
                        help="fly to a 6-DoF pose in OFFBOARD (PX4, this FCU), or to a "
                             "position and yaw in GUIDED (ArduPilot: --roll/--pitch 0)")
    for axis in ("x", "y", "z"):
        go.add_argument(axis, type=_finite, help=f"{axis} in local NED, m")
    go.add_argument("--roll", type=_finite, default=0.0, help="deg (Z-Y-X, NED/FRD)")
    go.add_argument("--pitch", type=_finite, default=0.0, help="deg")
    go.add_argument("--yaw", type=_finite, default=90.0,
                    help="deg (default 90: body x east, the level ENU identity)")
    go.add_argument("--arm", action="store_true",
                    help="arm before switching to OFFBOARD (GUIDED)")
    go.add_argument("--tolerance", type=_positive, default=0.05, help="position, m")
    go.add_argument("--tolerance-deg", type=_positive, default=1.0, help="attitude, deg")
    go.add_argument("--timeout", type=_positive, default=60.0, metavar="S")
    go.add_argument("--hold", type=float, default=0.0, metavar="S",
                    help="keep streaming the setpoint S s after reaching it")

    wa = sub.add_parser("watch", parents=[link], help="live view; q or Ctrl-C quits")
    wa.add_argument("--rate", type=_positive, default=5.0, help="refreshes per second")
    wa.add_argument("--duration", type=_positive, metavar="S", help="quit after S s")
    wa.add_argument("--all", action="store_true", help="every vehicle heard, not one")
    sub.add_parser("vehicles", parents=[link],
                   help="system ids of the vehicles on the link (Zenoh: from liveliness)")

    vw = sub.add_parser("view", parents=[link],
                        help="live 3D view over the Foxglove WebSocket protocol (127.0.0.1)")
    vw.add_argument("run_dir", type=Path, nargs="?", metavar="RUN_DIR",
                    help="replay this run folder's ULog logs instead of a live vehicle")
    vw.add_argument("--port", type=int, default=8765,
                    help="WebSocket port on 127.0.0.1 (0: any free port; default 8765)")
    vw.add_argument("--mcap", type=Path, metavar="FILE",
                    help="also record the channels to this new MCAP file")
    vw.add_argument("--speed", type=float, default=1.0, metavar="X",
                    help="replay at X times real time (0: as fast as possible, then exit)")
    vw.add_argument("--vehicle", type=Path, metavar="FILE",
                    help="vehicle TOML for the airframe (default: the run's, or hexa_tilted)")

    log = sub.add_parser("log", help="record telemetry")
    lsub = log.add_subparsers(dest="action", required=True)
    rec = lsub.add_parser("record", parents=[link], help="record a tlog until Ctrl-C")
    rec.add_argument("file", type=Path)
    rec.add_argument("--duration", type=_positive, metavar="S")
    return parser


# ------------------------------------------------------------------ runs


def _summary(m: dict) -> str:
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
    from gcs.inprocess import InProcessError, apply_overrides, run_scenario
    from gcs.process_run import RunError, run_processes
    from gcs.runio import RunDirError, prepare_run_dir, write_run

    scenario = apply_overrides(load_scenario(args.scenario), controller=args.controller,
                               ideal_actuators=True if args.ideal_actuators else None,
                               duration_s=args.duration, sensors=args.sensors,
                               seed=args.seed)
    if args.fleet < 1:
        print("gcs run: --fleet needs at least 1 vehicle", file=sys.stderr)
        return 2
    try:
        prepare_run_dir(args.out, args.force)
    except RunDirError as exc:
        print(f"gcs run: {exc}", file=sys.stderr)
        return 2
    progress = Progress()
    if args.in_process:
        progress(f"{scenario.name}: running {scenario.duration_s:.0f} s in-process ...")
        try:
            result = run_scenario(scenario)
        except InProcessError as exc:
            progress.done()
            print(f"gcs run: {exc}", file=sys.stderr)
            return 1
        write_run(args.out, scenario, result)
        metrics = result.metrics
    else:
        def report(p) -> None:
            elapsed = time.monotonic() - progress.t0
            progress(f"{scenario.name}: t = {p.sim_time_s:7.2f} / {scenario.duration_s:.0f} s"
                     f"   {p.sim_time_s / max(elapsed, 1e-3):5.1f}x real time")
        try:
            metrics = run_processes(scenario, args.out, realtime=args.realtime,
                                    transport=args.link, report=report, fleet=args.fleet,
                                    spacing_m=args.spacing, zenoh_url=args.zenoh,
                                    signing_key_file=args.signing_key)
        except RunError as exc:
            progress.done()
            print(f"gcs run: {exc}", file=sys.stderr)
            return 1
        if args.fleet > 1:
            progress.done()
            for m in metrics["vehicles"].values():
                _print_error(m)
                print(f"vehicle {m['system_id']}: " + _summary(m))
            print(f"  wrote {args.out / 'fleet.json'}")
            return 0 if metrics["all_completed"] else 1
    progress.done()
    _print_error(metrics)
    print(_summary(metrics))
    print(f"  wrote {args.out / 'metrics.json'}")
    return 0 if metrics["status"] == "completed" else 1


def _print_error(m: dict) -> None:
    if m.get("error"):
        print(f"gcs run: {m['error']}", file=sys.stderr)


def cmd_table1(args: argparse.Namespace) -> int:
    from gcs.table1_run import run_table1

    progress = Progress()
    progress(f"table1: {16 if args.lag_comp == 'both' else 8} runs ...")
    try:
        if args.sensors is not None:
            resolve_sensor_profile(args.sensors)  # a bad name: one line, before any run
    except ConfigError as exc:
        progress.done()
        print(f"gcs table1: {exc}", file=sys.stderr)
        return 2
    table = run_table1(args.scenarios, args.out, ideal=args.ideal_actuators,
                       duration_s=args.duration, workers=args.jobs,
                       in_process=args.in_process, progress=progress,
                       lag_comp=args.lag_comp, sensors=args.sensors, seed=args.seed)
    progress.done()
    print((args.out / "table1.md").read_text())
    print(f"wrote {args.out / 'table1.md'}, {args.out / 'table1.json'} and "
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
        print(f"gcs campaign: {exc}", file=sys.stderr)
        return 2
    done = len(read_journal(args.out)) if args.out.is_dir() else 0
    print(f"campaign {campaign.name}: {total} runs ({campaign.transport}); "
          f"{min(done, total)} recorded in {args.out} already", file=sys.stderr)
    dashboard = None if args.dashboard.lower() == "none" else args.dashboard
    try:
        outcome = run_campaign(campaign, args.out, scheduler=args.scheduler,
                               workers=args.workers, dashboard=dashboard,
                               report=not args.no_report)
    except OSError as exc:  # no scheduler at that address, a cluster that did not start
        print(f"gcs campaign: {exc}", file=sys.stderr)
        return 1
    flown = outcome.flown
    rate = outcome.sim_s / outcome.wall_s if outcome.wall_s > 0 and flown else 0.0
    print(f"campaign {campaign.name}: {len(outcome.rows)}/{outcome.total} runs recorded "
          f"({outcome.recorded_before} before, {flown} flown now in {outcome.wall_s:.1f} s "
          f"on {outcome.workers} workers after {outcome.startup_s:.1f} s of start-up: "
          f"{rate:.1f} simulated s per wall s)")
    for index, why in sorted(outcome.failed.items()):
        print(f"gcs campaign: run {index} not executed: {why}", file=sys.stderr)
    print(f"  wrote {args.out / 'results.csv'}"
          + ("" if args.no_report else f" and {args.out / 'summary.md'}"))
    return outcome.exit_code


def cmd_keygen(args: argparse.Namespace) -> int:
    import os
    import secrets

    if args.file.exists():
        print(f"gcs keygen: {args.file} exists; not overwriting a key", file=sys.stderr)
        return 2
    try:
        fd = os.open(args.file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        where = "its folder does not exist" if isinstance(exc, FileNotFoundError) \
            else exc.strerror
        print(f"gcs keygen: cannot write {args.file}: {where}", file=sys.stderr)
        return 2
    with os.fdopen(fd, "w") as fh:
        fh.write(secrets.token_hex(32) + "\n")
    print(f"wrote a 32-byte signing key to {args.file} (keep it out of version control)")
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    import signal
    import threading

    from common.links.url import DEFAULT_ROUTER
    from common.zenoh_link import run_router

    listen = args.listen or [DEFAULT_ROUTER]
    for endpoint in listen:
        problem = _endpoint_problem(endpoint)
        if problem:
            print(f"gcs router: {problem}", file=sys.stderr)
            return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    print(f"gcs router: listening on {', '.join(listen)} (multicast scouting off)", flush=True)
    try:
        run_router(listen, stop)
    except Exception as exc:  # zenoh reports a listener it cannot open as a plain error
        print(f"gcs router: cannot listen on {', '.join(listen)}: "
              f"{(str(exc).splitlines() or [type(exc).__name__])[0]}", file=sys.stderr)
        return 2
    return 0


def _endpoint_problem(endpoint: str) -> str:
    """Why a router cannot listen on a Zenoh endpoint ('' if it can, as far as a test
    bind tells): tcp/HOST:PORT and udp/HOST:PORT are checked, other protocols left to
    Zenoh."""
    import errno
    import socket

    proto, slash, addr = endpoint.partition("/")
    host, colon, port = addr.rpartition(":")
    if not slash or not colon or not port.isdigit() or not host:
        return f"endpoint '{endpoint}': expected PROTO/HOST:PORT, e.g. tcp/127.0.0.1:7447"
    if not 1 <= int(port) <= 65535:
        return f"endpoint '{endpoint}': port {port} out of range (1..65535)"
    kind = {"tcp": socket.SOCK_STREAM, "udp": socket.SOCK_DGRAM}.get(proto)
    if kind is None:
        return ""
    family = socket.AF_INET6 if host.startswith("[") else socket.AF_INET
    with socket.socket(family, kind) as s:
        if kind == socket.SOCK_STREAM:  # ignore connections in TIME_WAIT, as Zenoh does
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host.strip("[]"), int(port)))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return f"{host}:{port} is in use by another process"
            return f"cannot listen on {endpoint}: {exc.strerror or exc}"
    return ""


def cmd_replay(args: argparse.Namespace) -> int:
    """The estimator re-run on an onboard log (gcs.replay): 0 agree, 1 differ, 2 bad input."""
    from gcs.replay import main as replay_main

    return replay_main(args)


def cmd_report(args: argparse.Namespace) -> int:
    """A run folder (metrics.json) or a table1 folder (table1.json). Exit status: 0 when
    everything was reported, 1 when a table1 folder's run folder is missing or could not be
    read (the rest is reported), 2 for a path that is neither kind of folder."""
    from gcs.report.names import TABLE1_JSON
    from gcs.report.run_report import make_report
    from gcs.report.table1_report import is_table1_dir, make_table1_report
    from gcs.runio import RunDirError, check_run_dir

    if is_table1_dir(args.run_dir):
        def warn(problem: str) -> None:
            print(f"gcs report: {problem}", file=sys.stderr)

        result = make_table1_report(args.run_dir, warn=warn)
        for path in result.written:
            print(path)
        if result.problems:
            print(f"gcs report: {len(result.problems)} problem(s); everything else in "
                  f"{args.run_dir} was reported", file=sys.stderr)
        return 1 if result.problems else 0
    if not (args.run_dir / "metrics.json").exists():
        print(f"gcs report: {args.run_dir} has neither metrics.json (a run folder) nor "
              f"{TABLE1_JSON} (a table1 folder)", file=sys.stderr)
        return 2
    try:
        check_run_dir(args.run_dir)
    except RunDirError as exc:
        print(f"gcs report: {exc}", file=sys.stderr)
        return 2
    for path in make_report(args.run_dir):
        print(path)
    return 0


# ------------------------------------------------------------------ vehicle commands


def _session(args: argparse.Namespace, tlog: Path | None = None):
    from common.mavlink import read_signing_key
    from gcs.session import Session

    key = read_signing_key(args.signing_key) if args.signing_key else None
    session = Session(args.connect, tlog=tlog, vehicle=args.sysid or 0, signing_key=key)
    try:
        session.wait_vehicle(timeout=_heartbeat_wait(args), system_id=args.sysid)
        _request_streams(session, args)
    except BaseException:
        session.close()
        raise
    return session


def _heartbeat_wait(args: argparse.Namespace) -> float:
    return HEARTBEAT_WAIT_S if args.wait is None else args.wait


def _request_streams(session, args: argparse.Namespace) -> None:
    """Ask the vehicle for the telemetry the command needs (ArduPilot sends little until
    asked); the session gives back what it changed when it closes."""
    from gcs.autopilot.streams import needs

    if session.autopilot is not None:
        session.request_streams(needs(args.command, session.autopilot.kind))


def _result(what: str, result: int, session=None) -> int:
    """The vehicle's answer; a refusal with the reason it gave (its STATUSTEXT)."""
    from common.mavlink import MAV

    if result == MAV.MAV_RESULT_ACCEPTED:
        print(f"{what}: MAV_RESULT_ACCEPTED")
        return 0
    if session is not None:
        print(f"{what} refused: {session.describe(result)}")
    else:
        enum = MAV.enums["MAV_RESULT"]
        print(f"{what} refused: {enum[result].name if result in enum else result}")
    return 1


def cmd_vehicle(args: argparse.Namespace) -> int:
    from gcs import vehicle_link as vl

    _read_files(args)  # a bad file is refused before any network wait
    session = _session(args)
    try:
        if args.command == "status":
            if args.json:
                import json

                print(json.dumps(vl.status(session), allow_nan=False))
            else:
                print("\n".join(vl.format_status(vl.status(session))))
            return 0
        if args.command == "arm":
            return _result("arm", vl.arm(session, True), session)
        if args.command == "disarm":
            return _result("disarm", vl.arm(session, False, force=args.force), session)
        if args.command == "mode":
            return _mode(args, session)
        if args.command == "takeoff":
            return _takeoff(args, session)
        if args.command == "mission":
            return _mission(args, session)
        if args.command == "param":
            return _param(args, session)
        if args.command == "goto":
            return _goto(args, session)
        if args.command == "watch":
            from gcs.watch import watch

            return watch(session, refresh_hz=args.rate, duration=args.duration,
                         all_vehicles=args.all)
        if args.command == "vehicles":
            for sysid in vl.vehicles(session, _heartbeat_wait(args)):
                print(sysid)
            return 0
        raise AssertionError(args.command)
    finally:
        session.close()


def cmd_view(args: argparse.Namespace) -> int:
    """Exit 0 on Ctrl-C, SIGTERM or the end of a replay, 1 without a vehicle, 2 for bad
    input (run folder, port, MCAP path)."""
    from common.mavlink import read_signing_key
    from gcs.view import ViewError, view_live, view_replay

    try:
        if not 0 <= args.port <= 65535:
            raise ViewError(f"--port must be 0..65535, got {args.port}")
        if args.run_dir is not None:
            if args.connect != DEFAULT_CONNECT:
                raise ViewError("give RUN_DIR or --connect, not both")
            return view_replay(args.run_dir, port=args.port, mcap=args.mcap, speed=args.speed,
                               vehicle_file=args.vehicle)
        key = read_signing_key(args.signing_key) if args.signing_key else None
        return view_live(args.connect, port=args.port, mcap=args.mcap,
                         vehicle_file=args.vehicle, system_id=args.sysid,
                         wait_s=_heartbeat_wait(args), signing_key=key)
    except ViewError as exc:
        print(f"gcs view: {exc}", file=sys.stderr)
        return 2


def _read_files(args: argparse.Namespace) -> None:
    """Read the file a mission or param command takes, before any network wait: a bad one
    raises MissionFileError or InputError (one line, exit status 2); the contents go to
    args.items / args.params. Files to be written must have a folder to go to."""
    from gcs.mission_files import file_format, read_mission_doc
    from gcs.param_files import ParamFileError, read_params

    if args.command == "mission" and args.action == "upload":
        args.mission = read_mission_doc(args.file, args.format)
        args.items = args.mission.items
    elif args.command == "mission" and args.action == "download" and args.file is not None:
        file_format(args.file, args.format)
        _writable_file(args.file, "mission file")
    elif args.command == "param" and args.action == "save":
        _writable_file(args.file, "parameter file")
    elif args.command == "param" and args.action == "load":
        try:
            args.params = read_params(args.file)
        except ParamFileError as exc:
            raise InputError(str(exc)) from None


def _mission(args: argparse.Namespace, session) -> int:
    from common.mavlink import MAV
    from gcs.autopilot import autopilot_of
    from gcs.mission_client import clear, download, home_position, result_name, upload_detailed
    from gcs.mission_files import file_format, format_mission, to_frame
    from gcs.mission_home import HomeError, WireMission, for_ardupilot, split_home

    t, c, send = session.target_system, session.target_component, session.send
    progress = Progress()
    pilot = autopilot_of(session.heartbeat_msg)
    at_seq0 = pilot.mission_home_at_seq0  # ArduPilot: home is seq 0, the plan from seq 1

    def report(done: int, total: int) -> None:
        progress(f"mission: {done}/{total} items")

    if args.action == "upload":
        items = args.items
        wire = WireMission(list(items))
        if at_seq0:
            need_home = args.mission.home is None or any(
                it.frame == MAV.MAV_FRAME_LOCAL_NED for it in items)
            vehicle_home = home_position(session.conn, t, c, send=send) if need_home \
                else None
            try:
                wire = for_ardupilot(items, args.mission.fmt, args.mission.home, vehicle_home)
            except HomeError as exc:
                print(f"gcs mission: {exc}", file=sys.stderr)
                return 1
            h = wire.home
            assert h is not None
            print(f"home (seq 0): lat {h.lat_deg:.7f}, lon {h.lon_deg:.7f} deg, alt "
                  f"{h.alt_m:.2f} m AMSL, from {wire.home_source}")
        n = len(wire.items) - (1 if at_seq0 else 0)  # the plan's items, home not counted
        answer = upload_detailed(session.conn, t, c, wire.items, progress=report, send=send)
        progress.done()
        if not answer.accepted:
            where = ""
            if answer.about_item and not answer.notes:  # the vehicle said not which
                where = ": the home item (seq 0)" if at_seq0 and answer.asked == 0 else \
                    f": item {answer.asked + (0 if at_seq0 else 1)} of {n}"
            print(f"upload of {n} items refused: {answer.describe()}{where}")
            return 1
        print(f"upload of {n} items: {result_name(answer.result)}")
        return 0
    if args.action == "download":
        items = download(session.conn, t, c, progress=report, send=send)
        progress.done()
        fmt = file_format(args.file, args.format)
        frame = args.frame or ("global" if fmt == "plan" else None)  # QGC plans globally
        home = None
        if at_seq0:  # seq 0 is the vehicle's home: it goes where the format keeps home
            home, items = split_home(items)
        if home is None and (frame is not None or at_seq0):
            home = home_position(session.conn, t, c, send=send)
        if frame is not None and home is None:
            if args.frame is not None or any(it.frame == MAV.MAV_FRAME_LOCAL_NED
                                             for it in items):
                print(f"gcs mission: --frame {frame}: the vehicle sent no HOME_POSITION",
                      file=sys.stderr)
                return 1
            frame = None  # a plan of global items needs no conversion
        hb = session.heartbeat_msg
        text = format_mission(to_frame(items, frame, home), fmt, home,
                              home_at_seq0=at_seq0, firmware_type=pilot.firmware_type,
                              vehicle_type=hb.type)
        if args.file is None:
            print(text, end="")
        else:
            args.file.write_text(text)
            print(f"downloaded {len(items)} items to {args.file}"
                  + (" (and home, seq 0)" if at_seq0 and home is not None else ""))
        return 0
    if args.action == "clear":
        result = clear(session.conn, t, c, send=send)
        print(f"clear: {result_name(result)}")
        return 0 if result == MAV.MAV_MISSION_ACCEPTED else 1
    return _result("mission start", session.command(MAV.MAV_CMD_MISSION_START), session)


def _param(args: argparse.Namespace, session) -> int:
    from gcs import vehicle_link as vl
    from gcs.param_wire import ParamValueError, intended

    if args.action == "list":
        for name, p in vl.param_values(session).items():
            print(f"{name:<16} {p.text()}")
        return 0
    if args.action == "get":
        print(f"{args.name} = {vl.param_read(session, args.name).text()}")
        return 0
    if args.action == "save":
        return _param_save(args, session)
    if args.action == "load":
        return _param_load(args, session)
    current = vl.param_read(session, args.name)
    try:
        value, texts = vl.param_set(session, args.name, args.value,
                                    param_type=current.param_type)
    except ParamValueError as exc:
        print(f"gcs param: {exc}", file=sys.stderr)
        return 2
    for text in texts:
        print(f"vehicle: {text}")
    now = vl.ParamValue(value, current.param_type).text()
    print(f"{args.name} = {now}")
    if value == intended(args.name, args.value, current.param_type):
        return 0
    print(f"not taken: the vehicle keeps {now}")  # clamped, or refused with its reason
    return 1


def _param_save(args: argparse.Namespace, session) -> int:
    from common.mavlink import MAV
    from gcs import vehicle_link as vl
    from gcs.param_files import ParamEntry, format_params

    values = vl.param_values(session)
    t, c = session.target_system, session.target_component
    beat = session.conn.messages.get("HEARTBEAT")
    stack = vehicle = version = git = ""
    if beat is not None and beat.get_srcSystem() == t:
        stack = {MAV.MAV_AUTOPILOT_PX4: "PX4 Pro", MAV.MAV_AUTOPILOT_ARDUPILOTMEGA: "ArduPilot"
                 }.get(beat.autopilot, "MAVLink Generic")
        vehicle = "Multi-Rotor" if beat.type in (
            MAV.MAV_TYPE_QUADROTOR, MAV.MAV_TYPE_HEXAROTOR, MAV.MAV_TYPE_OCTOROTOR,
            MAV.MAV_TYPE_TRICOPTER, MAV.MAV_TYPE_COAXIAL) else \
            MAV.enums["MAV_TYPE"][beat.type].name.removeprefix("MAV_TYPE_").title() \
            if beat.type in MAV.enums["MAV_TYPE"] else ""
    ver = vl.autopilot_version(session)  # the header's version line; best effort
    if ver is not None:
        sw = ver.flight_sw_version
        kind = {0: "dev", 64: "alpha", 128: "beta", 192: "rc", 255: ""}.get(sw & 0xFF, "")
        version = f"{sw >> 24 & 0xFF}.{sw >> 16 & 0xFF}.{sw >> 8 & 0xFF} {kind}".rstrip()
        git = bytes(ver.flight_custom_version).hex()
    entries = [ParamEntry(t, c, name, p.value, p.param_type)
               for name, p in sorted(values.items())]
    args.file.write_text(format_params(entries, system_id=t, stack=stack, vehicle=vehicle,
                                       version=version, git_revision=git))
    print(f"saved {len(entries)} parameters to {args.file}")
    return 0


def _param_load(args: argparse.Namespace, session) -> int:
    from gcs import vehicle_link as vl
    from gcs.param_wire import ParamValueError, intended
    from gcs.session import GcsError

    t, c = session.target_system, session.target_component
    refused = 0
    entries = [e for e in args.params if e.component_id in (c, 0)]
    others = len(args.params) - len(entries)
    if others:
        print(f"skipped {others} parameters of other components than {c}")
    if any(e.system_id != t for e in entries):
        print(f"note: the file holds parameters of another vehicle; loading into system {t}")
    for e in entries:
        try:  # the vehicle's own type, whatever the file says (older files say 9 for all)
            ptype = vl.param_read(session, e.name).param_type
            value, texts = vl.param_set(session, e.name, e.value, param_type=ptype)
        except GcsError:
            print(f"{e.name}: not answered (unknown to the vehicle?)")
            refused += 1
            continue
        except ParamValueError as exc:
            print(f"{e.name} = {e.value:g}: {exc}")
            refused += 1
            continue
        if value != intended(e.name, e.value, ptype):
            said = "; ".join(" ".join(str(x).split()) for x in texts)
            print(f"{e.name} = {e.value:g}: " +
                  (f"vehicle: {said}" if said else
                   f"not taken (the vehicle keeps {vl.ParamValue(value, ptype).text()})"))
            refused += 1
    print(f"loaded {len(entries) - refused} of {len(entries)} parameters from {args.file}")
    return 0 if refused == 0 else 1


def _mode(args: argparse.Namespace, session) -> int:
    """Exit 0 once a HEARTBEAT shows the mode; 1 refused or not confirmed; 2 a name the
    autopilot does not have (with its names)."""
    from gcs import vehicle_link as vl
    from gcs.autopilot import UnknownMode

    confirm = 3.0 if args.wait is None else args.wait
    try:
        result = vl.set_mode(session, args.name, confirm_s=confirm)
    except UnknownMode as exc:
        raise InputError(str(exc)) from None
    return _result(f"mode {args.name.upper()}", result, session)


def _takeoff(args: argparse.Namespace, session) -> int:
    from gcs import vehicle_link as vl

    progress = Progress()
    confirm = 3.0 if args.wait is None else args.wait
    result, height = vl.takeoff(session, args.alt, reach_s=None if args.no_wait else
                                args.timeout, tolerance_m=args.tolerance, confirm_s=confirm,
                                report=lambda h: progress(f"takeoff: {h:.2f} m above home"))
    progress.done()
    code = _result(f"takeoff to {args.alt:g} m", result, session)
    if code == 0 and height is not None:
        print(f"reached: {height:.2f} m above home")
    return code


def _goto(args: argparse.Namespace, session) -> int:
    import math

    from gcs import vehicle_link as vl
    from gcs.autopilot import ARDUPILOT

    if session.autopilot is not None and session.autopilot.kind == ARDUPILOT and \
            (args.roll or args.pitch):
        raise InputError("--roll and --pitch must be 0 on ArduPilot: it flies a position and "
                         "a yaw in GUIDED (an attitude target there replaces the position "
                         "target)")

    target = vl.PoseTarget.from_euler_deg((args.x, args.y, args.z), args.roll, args.pitch,
                                          args.yaw)
    progress = Progress()

    def report(errs) -> None:
        progress(f"goto: position error {errs[0]:.3f} m, attitude error "
                 f"{math.degrees(errs[1]):.2f} deg")

    dp, da = vl.goto(session, target, arm_first=args.arm, tolerance_m=args.tolerance,
                     tolerance_rad=math.radians(args.tolerance_deg), timeout=args.timeout,
                     hold_s=args.hold, report=report)
    progress.done()
    print(f"reached: position error {dp:.4f} m, attitude error {math.degrees(da):.3f} deg")
    return 0


def cmd_log(args: argparse.Namespace) -> int:
    from gcs.vehicle_link import Snapshot, collect

    session = _session(args, tlog=args.file)
    progress = Progress()
    snap = Snapshot()
    try:
        end = time.monotonic() + (args.duration or float("inf"))
        while time.monotonic() < end:
            collect(session, snap, min(0.5, max(0.0, end - time.monotonic())))
            progress(f"recording {args.file}: {sum(snap.counts.values())} messages")
    except KeyboardInterrupt:
        pass
    finally:
        session.close()
        progress.done()
    print(f"recorded {sum(snap.counts.values())} messages to {args.file}")
    return 0


def _writable_file(path: Path, what: str) -> None:
    """A file about to be written: its folder must exist and it must not be a folder."""
    if path.is_dir():
        raise InputError(f"{what} {path} is a folder, not a file")
    parent = path.parent
    if not parent.is_dir():
        raise InputError(f"{what} {path}: folder {parent} does not exist"
                         if not parent.exists() else f"{what} {path}: {parent} is not a folder")


def check_input(args: argparse.Namespace) -> None:
    """Everything that can be checked before a link is opened or a vehicle waited for;
    InputError, LinkError or SigningKeyError (all exit status 2). Mission and parameter
    files are read by `_read_files`, before any network wait too."""
    if getattr(args, "connect", None) is not None:
        parse_url(args.connect)
    if getattr(args, "signing_key", None):
        from common.mavlink import read_signing_key

        read_signing_key(args.signing_key)
    if args.command == "mode":
        from gcs.autopilot import all_mode_names

        known = all_mode_names()
        if args.name.strip().upper() not in known:
            raise InputError(f"unknown mode {args.name} (one of {', '.join(known)})")
    elif args.command == "log":
        _writable_file(args.file, "log file")


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 1 the vehicle refused or did not answer (or a link failed at
    run time), 2 bad input (arguments, URLs, files, busy ports), 130 interrupted."""
    from common.mavlink import SigningKeyError
    from gcs.mission_client import MissionError
    from gcs.mission_files import MissionFileError
    from gcs.session import GcsError

    args = build_parser().parse_args(argv)
    try:
        check_input(args)
        if args.command == "run":
            return cmd_run(args)
        if args.command == "table1":
            return cmd_table1(args)
        if args.command == "campaign":
            return cmd_campaign(args)
        if args.command == "report":
            return cmd_report(args)
        if args.command == "replay":
            return cmd_replay(args)
        if args.command == "router":
            return cmd_router(args)
        if args.command == "keygen":
            return cmd_keygen(args)
        if args.command == "log":
            return cmd_log(args)
        if args.command == "view":
            return cmd_view(args)
        return cmd_vehicle(args)
    except LinkError as exc:
        print(f"gcs {args.command}: {exc}", file=sys.stderr)
        return exc.exit_code
    except (ConfigError, InputError, MissionFileError, SigningKeyError) as exc:
        print(f"gcs {args.command}: {exc}", file=sys.stderr)
        return 2
    except (GcsError, MissionError) as exc:
        print(f"gcs {args.command}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("gcs: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `gcs ... | head`: the reader has gone, nothing is lost
        sys.stdout = None  # type: ignore[assignment]
        return 0
    except OSError as exc:  # the file system (or the machine) said no: one line
        if exc.filename is not None:
            print(f"gcs {args.command}: {exc.filename}: {exc.strerror}", file=sys.stderr)
            return 2
        print(f"gcs {args.command}: {exc.strerror or exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

