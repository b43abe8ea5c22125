"""`fcu`: the flight controller process's command line (the loop itself:
`fcu.edge.flight_controller`).

The options are parsed and checked (URLs, output files, ranges) before the flight code and
its libraries load (numpy, numba and the kernels, pymavlink): `fcu --help` and a bad command
line are answered at once, and a stop asked for while they load is recorded
(`common.process.startup`).
"""

from __future__ import annotations

import sys

from common.config.reader import ConfigError
from common.links import LinkError, parse_url
from common.process import startup
from common.process.cliargs import check_output_path
from common.process.diagnostics import get_logger, say, setup_logging
from common.process.parent import stop_with_parent
from common.process.program import STARTUP_ERRORS, serve, start_failed
from fcu.edge.node_args import DEFAULT_GCS, build_parser

log = get_logger(__name__)


def main(argv: list[str] | None = None) -> int:
    stop_with_parent()
    args = build_parser().parse_args(argv)
    setup_logging("fcu", args)

    startup.guard()  # a stop while starting (loading the kernels, say) is looked at below
    try:
        for url in (args.sim, *(args.gcs or ())):  # every URL, before anything is opened
            parse_url(url)
        for option, path in (("--onboard-log", args.onboard_log), ("--stats", args.stats)):
            check_output_path(option, path)
        if not 1 <= args.rate <= 1000:
            raise ConfigError(f"--rate: expected 1..1000 Hz, got {args.rate}")
        if not 0 <= args.rtt_probes <= 100_000:
            raise ConfigError(f"--rtt-probes: expected 0..100000, got {args.rtt_probes}")
        if not 1 <= args.sysid <= 254:
            raise ConfigError(f"--sysid: expected 1..254, got {args.sysid}")
        if not 0 <= args.rt_priority <= 99:
            raise ConfigError(f"--rt-priority: expected 0..99, got {args.rt_priority}")
        # The flight code and its libraries load here, after the command line is checked
        from common.config.scenario import load_gains, load_vehicle
        from common.wire.mavlink import read_signing_key
        from fcu.compose import fcu_pipeline
        from fcu.edge.flight_controller import FlightController
        from fcu.edge.work_process import make_work

        pipeline, params = fcu_pipeline(load_vehicle(args.vehicle), load_gains(args.gains),
                                        args.rate)
        log.debug("fcu: vehicle %s, gains %s, control at %s Hz", args.vehicle, args.gains,
                  args.rate)
        key = read_signing_key(args.signing_key) if args.signing_key else None
        fc = FlightController(pipeline, args.sim, args.gcs or list(DEFAULT_GCS),
                              system_id=args.sysid, lockstep=not args.realtime,
                              home=args.home, onboard_log=args.onboard_log,
                              stats_path=args.stats, signing_key=key,
                              rtt_probes=args.rtt_probes, params=params,
                              work=make_work(args.work, lockstep=not args.realtime)
                              if args.work else None)
    except (KeyboardInterrupt, LinkError, *STARTUP_ERRORS, OSError) as exc:
        return start_failed("fcu", exc)

    def rotate() -> None:  # SIGHUP: the onboard log rotated at the next housekeeping
        fc.rotate_log = True

    sim_port = getattr(fc.sim.link, "local_port", None)
    said = (f"fcu: system {args.sysid}, simulator {args.sim}, GCS "
            f"{', '.join(args.gcs or DEFAULT_GCS)} "
            f"({'real time' if args.realtime else 'lockstep'}, {args.rate} Hz)"
            + (f"\nfcu: sim port {sim_port}" if sim_port is not None else ""))
    if not serve("fcu", fc, said, rt_priority=args.rt_priority if args.realtime else None,
                 on_hup=rotate):
        return 0
    say(f"fcu: stopped after {fc.steps} control steps; {fc.deadlines.misses} deadline misses, "
        f"{fc.sim.resent_answers} answers re-sent, {fc.sim.rejected_bytes} bytes rejected")
    return 0


if __name__ == "__main__":
    sys.exit(main())
