"""`gcs`: the ground-station command line (`gcs --help`; every command and flag:
`gcs.cli.parser`).

`main` parses the arguments, checks what can be checked before a link is opened
(`gcs.cli.inputs`), runs the command and turns its errors into one line and an exit status.
The commands, by what they drive: runs and reports (`runs`), the links' router and keys
(`links`), a vehicle (`vehicle`, with `missions` and `params`, over `connection`), its
telemetry (`telemetry`: log record, view).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from common.config.reader import ConfigError
from common.links import LinkError
from common.process.diagnostics import get_logger, setup_logging
from gcs.cli.console import InputError
from gcs.cli.inputs import check_input
from gcs.cli.links import cmd_keygen, cmd_router
from gcs.cli.parser import build_parser
from gcs.cli.runs import cmd_campaign, cmd_replay, cmd_report, cmd_run, cmd_table1
from gcs.cli.telemetry import cmd_log, cmd_view
from gcs.cli.vehicle import cmd_vehicle

log = get_logger(__name__)

# the commands that do not talk to a vehicle, by name; every other one is `cmd_vehicle`'s
COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "run": cmd_run, "table1": cmd_table1, "campaign": cmd_campaign, "report": cmd_report,
    "replay": cmd_replay, "router": cmd_router, "keygen": cmd_keygen, "log": cmd_log,
    "view": cmd_view}


# The commands whose work loads numba (flights, reports, the live view, goto's poses): a
# ground station that only talks to a vehicle does without it.
NUMERIC = frozenset({"run", "table1", "campaign", "report", "replay", "view", "goto"})


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 1 the vehicle refused or did not answer (or a link failed at
    run time), 2 bad input (arguments, URLs, files, busy ports), 130 interrupted."""
    from common.process.startup import sigint_deferred

    args = build_parser().parse_args(argv)
    setup_logging("gcs", args)
    # The libraries load here, a Ctrl-C meanwhile raised after them, not inside (an import
    # a KeyboardInterrupt broke off leaves numpy half made, and numba drops one that lands
    # in its ctypes callbacks): pymavlink and numpy for every command, numba for those that
    # need it, as `fcu` and `sitl` load theirs.
    with sigint_deferred():
        caught: tuple[type[BaseException], ...] = (LinkError, KeyboardInterrupt, OSError,
                                                  *_bad_input(), *_refused())
        if args.command in NUMERIC:
            import common.config.scenario  # noqa: F401  (numba and the scenario's loaders)
    try:
        check_input(args)
        return COMMANDS.get(args.command, cmd_vehicle)(args)
    except caught as exc:
        return _failed(args.command, exc)


def _bad_input() -> tuple[type[Exception], ...]:
    """The errors of bad input (exit status 2), imported when a command runs."""
    from common.wire.mavlink import SigningKeyError
    from gcs.mission_files.items import MissionFileError

    return ConfigError, InputError, MissionFileError, SigningKeyError


def _refused() -> tuple[type[Exception], ...]:
    """The errors of a vehicle that refused or did not answer (exit status 1)."""
    from gcs.vehicle_link.mission_client import MissionError
    from gcs.vehicle_link.session import GcsError

    return GcsError, MissionError


def _failed(command: str, exc: BaseException) -> int:
    """The one line (an error diagnostic) and the exit status of a command that failed:
    a link's own status, 2 bad input, 1 the vehicle or the machine said no, 130
    interrupted, 0 for a reader gone (`gcs ... | head`: nothing is lost)."""
    if isinstance(exc, LinkError):
        log.error("gcs %s: %s", command, exc)
        return exc.exit_code
    if isinstance(exc, KeyboardInterrupt):
        log.error("gcs: interrupted")
        return 130
    if isinstance(exc, BrokenPipeError):
        sys.stdout = None
        return 0
    if isinstance(exc, OSError):  # the file system (or the machine) said no: one line
        if exc.filename is not None:
            log.error("gcs %s: %s: %s", command, exc.filename, exc.strerror)
            return 2
        log.error("gcs %s: %s", command, exc.strerror or exc)
        return 1
    log.error("gcs %s: %s", command, exc)
    return 2 if isinstance(exc, _bad_input()) else 1
