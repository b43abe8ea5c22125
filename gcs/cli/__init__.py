"""`gcs`: the ground-station command line (`gcs --help`; every command and flag:
`gcs.cli.parser`).

`main` parses the arguments, checks what can be checked before a link is opened
(`gcs.cli.inputs`), runs the command and turns its errors into one line and an exit status.
The commands, by what they drive: runs and reports (`runs`), the links' router and keys
(`links`), a vehicle (`vehicle`, with `missions` and `params`, over `connection`), its
telemetry (`telemetry`: log record, view).
"""

from __future__ import annotations

import sys

from common.config.scenario import ConfigError
from common.links import LinkError
from gcs.cli.console import InputError
from gcs.cli.inputs import check_input
from gcs.cli.links import cmd_keygen, cmd_router
from gcs.cli.parser import build_parser
from gcs.cli.runs import cmd_campaign, cmd_replay, cmd_report, cmd_run, cmd_table1
from gcs.cli.telemetry import cmd_log, cmd_view
from gcs.cli.vehicle import cmd_vehicle


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 1 the vehicle refused or did not answer (or a link failed at
    run time), 2 bad input (arguments, URLs, files, busy ports), 130 interrupted."""
    from common.wire.mavlink import SigningKeyError
    from gcs.mission_files.items import MissionFileError
    from gcs.vehicle_link.mission_client import MissionError
    from gcs.vehicle_link.session import GcsError

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
        sys.stdout = None
        return 0
    except OSError as exc:  # the file system (or the machine) said no: one line
        if exc.filename is not None:
            print(f"gcs {args.command}: {exc.filename}: {exc.strerror}", file=sys.stderr)
            return 2
        print(f"gcs {args.command}: {exc.strerror or exc}", file=sys.stderr)
        return 1
