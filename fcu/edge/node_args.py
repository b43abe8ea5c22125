"""`fcu`'s command line: its options, their defaults and what they take."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from common.process.cliargs import OneLineParser
from common.process.diagnostics import add_verbosity_options
from common.process.realtime import DEFAULT_PRIORITY
from common.wire.mission_items import PX4_SITL_HOME, HomePosition
from fcu.work import KINDS

DEFAULT_GCS = ("udpout:127.0.0.1:14550", "udpout:127.0.0.1:14540")


def _home(text: str) -> HomePosition:
    try:
        lat, lon, alt = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT, got {text}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and math.isfinite(alt)):
        raise argparse.ArgumentTypeError(f"home out of range: {text}")
    return HomePosition(lat, lon, alt)


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="fcu", description="dual-quaternion flight controller")
    add_verbosity_options(p)
    p.add_argument("--vehicle", type=Path, required=True, help="vehicle TOML")
    p.add_argument("--gains", type=Path, required=True, help="gains TOML (PID or PD)")
    p.add_argument("--sim", default="udpout:127.0.0.1:4560", help="simulator link URL")
    p.add_argument("--gcs", action="append", metavar="URL",
                   help=f"GCS link URL, repeatable (default: {' and '.join(DEFAULT_GCS)})")
    p.add_argument("--rate", type=int, default=500, help="control rate in Hz (1..1000)")
    p.add_argument("--realtime", action="store_true", help="run on the monotonic clock")
    p.add_argument("--rt-priority", type=int, default=DEFAULT_PRIORITY, metavar="P",
                   help="with --realtime: the loop's SCHED_FIFO priority, 1..99, 0 for "
                        f"normal scheduling (default {DEFAULT_PRIORITY}; where it is not "
                        "granted the loop runs at normal priority and says so)")
    p.add_argument("--work", choices=KINDS,
                   help="mission checks and plans: 'beside' the loop in a worker process "
                        "(real-time default) or 'inline' (lockstep default)")
    p.add_argument("--sysid", type=int, default=1, help="MAVLink system id (1..254)")
    p.add_argument("--home", type=_home, default=PX4_SITL_HOME, help="LAT,LON,ALT of the origin")
    p.add_argument("--onboard-log", type=Path,
                   help="write the onboard log (ULog) here, e.g. onboard.ulg")
    p.add_argument("--stats", type=Path,
                   help="write run statistics and events (JSON) here at exit")
    p.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing on the GCS links: sign telemetry, refuse unsigned "
                        "or wrongly signed input (key from `gcs keygen`)")
    p.add_argument("--rtt-probes", type=int, default=0, metavar="N",
                   help="lockstep: time N TIMESYNC round trips with the simulator when it is "
                        "first heard (the link's round trip, in --stats; default 0: none)")
    return p
