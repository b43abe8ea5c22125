"""`gcs`'s arguments: the parser of every subcommand, its flags and their checks. `USAGE`,
the summary of all commands, is the epilog of `gcs --help`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from common.process.cliargs import OneLineParser
from common.process.diagnostics import add_verbosity_options

USAGE = """Runs and reports:
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
Every command takes -v (debug diagnostics too) or -q (only warnings and errors), before or
after its name; diagnostics go to stderr, results to stdout.
"""
DEFAULT_SCENARIOS = Path(__file__).resolve().parents[2] / "config" / "scenarios"
DEFAULT_CONNECT = "udpin:127.0.0.1:14550"
HEARTBEAT_WAIT_S = 10.0  # --wait's default for the vehicle's heartbeat


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


class SubcommandParser(OneLineParser):
    """A subcommand's parser (and the options it shares): `-v`/`-q` taken after the
    subcommand too (`gcs run -q ...`), once, whether or not a parent parser gave them."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if self.get_default("log_level") is None:  # not copied from a parent
            add_verbosity_options(self, subcommand=True)


def build_parser() -> argparse.ArgumentParser:
    link = SubcommandParser(add_help=False)
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
                                     epilog=USAGE)
    add_verbosity_options(parser)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=SubcommandParser)

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
    ms = msub.add_parser("start", parents=[link],
                         help="MISSION_START to an armed vehicle (a disarmed one: refused)")
    ms.add_argument("--arm", action="store_true",
                    help="arm a disarmed vehicle first (without it, nothing is sent to one)")

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
