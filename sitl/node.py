"""`sitl`: the plant as a process, serving a simulator link (the command line).

Protocols: dqflight, this project's own link to its FCU (`sitl.server`: lockstep or real
time, the exact state or a sensor profile's samples, `sitl.world`'s physics), and the
interfaces through which external physics engines serve real firmware
(`sitl.firmware.ardupilot_json`, `sitl.firmware.px4_hil`), where the firmware drives simulated time.

The ground-truth log (one row per state sent) is the run's reference for every metric.

The options are parsed and checked before the scenario's and the plant's code and their
libraries load (numpy, numba, pymavlink): `sitl --help` and a bad command line are answered
at once.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from common.config.reader import ConfigError
from common.links import LinkError, parse_url
from common.process import startup
from common.process.cliargs import OneLineParser, check_output_path
from common.process.diagnostics import add_verbosity_options, get_logger, say, setup_logging
from common.process.parent import stop_with_parent
from common.process.program import STARTUP_ERRORS, serve, start_failed
from common.process.realtime import DEFAULT_PRIORITY

if TYPE_CHECKING:
    from common.config.scenario import Scenario

log = get_logger(__name__)

# The simulator protocols `sitl` serves: its own link to this project's FCU, and the
# interfaces through which external physics engines serve real firmware. Each has its own
# default --link; with a firmware protocol the firmware drives simulated time.
DQFLIGHT = "dqflight"
DEFAULT_LINKS = {DQFLIGHT: "udpin:127.0.0.1:4560",  # this project's FCU (PX4's port)
                 "ardupilot-json": "udpin:127.0.0.1:9002",  # ArduPilot's SIM_JSON
                 "px4-hil": "tcpin:127.0.0.1:4560"}  # PX4's simulator MAVLink API
FIRMWARE_MODULES = {"ardupilot-json": "sitl.firmware.ardupilot_json",
                    "px4-hil": "sitl.firmware.px4_hil"}
# Options that only the dqflight protocol takes (the firmware protocols refuse them): the
# firmware sets the rates and drives the clock.
DQFLIGHT_ONLY = ("realtime", "rt_priority", "control_rate", "hil_sensor_hz", "resend_ms")
SITL_PRIORITY = DEFAULT_PRIORITY - 1  # the world's clock, just below the controller's loop


class FirmwareServer(Protocol):
    """What a firmware protocol's module provides as `Server(scenario, link_url, *,
    truth_log, end_time_s)`: the plant behind the firmware's own simulator interface,
    stepped by the firmware's packets, until `running` is cleared (SIGTERM, Ctrl-C) or
    `end_time_s` of simulated time after the first packet."""

    running: bool

    def run(self) -> None: ...

    def close(self) -> None: ...

    def stats(self) -> dict[str, Any]: ...

    def summary(self) -> str:
        """The `sitl: stopped ...` line's text after "sitl: "."""
        ...


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="sitl", description="tilt-rotor plant on a simulator link",
        epilog="protocols: dqflight (this project's FCU; every option applies), "
               "ardupilot-json (ArduPilot's JSON SITL interface: ArduPilot sends servo "
               "packets and drives simulated time) and px4-hil (PX4's simulator MAVLink API: "
               "HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION out, HIL_ACTUATOR_CONTROLS in, "
               "lockstep on PX4's answers). With ardupilot-json and px4-hil the options "
               "--link, --truth-log, --end-time (after the first packet; default: serve until "
               "SIGTERM), --ideal-actuators, --sensors, --seed, --sysid, --stats and "
               "--position apply; --realtime, --control-rate, --hil-sensor-hz and "
               "--resend-ms are dqflight's only. ardupilot-json takes only the truth sensor "
               "profile (ArduPilot makes its sensors from the exact state), so --seed does "
               "nothing there.")
    add_verbosity_options(p)
    p.add_argument("scenario", type=Path, help="scenario TOML (vehicle, start, disturbances)")
    p.add_argument("--protocol", choices=tuple(DEFAULT_LINKS), default=DQFLIGHT,
                   help="simulator protocol (default dqflight)")
    p.add_argument("--link", default=None,
                   help="simulator link URL (default per protocol: dqflight "
                        "udpin:127.0.0.1:4560, ardupilot-json udpin:127.0.0.1:9002, px4-hil "
                        "tcpin:127.0.0.1:4560)")
    p.add_argument("--realtime", action="store_true", help="pace by the wall clock")
    p.add_argument("--rt-priority", type=int, default=None, metavar="P",
                   help="with --realtime: the physics loop's SCHED_FIFO priority, 1..99, 0 "
                        f"for normal scheduling (default {SITL_PRIORITY}, below fcu's; where "
                        "it is not granted the loop runs at normal priority and says so)")
    p.add_argument("--truth-log", type=Path,
                   help="write the ground-truth log (ULog) here, e.g. truth.ulg")
    p.add_argument("--end-time", type=float, metavar="S",
                   help="stop advancing this long after the flight starts (default: the "
                        "scenario's duration in lockstep, never in real time; with a firmware "
                        "protocol, after the first packet, default never)")
    p.add_argument("--control-rate", type=int, default=None,
                   help="control periods per second (default: the scenario's)")
    p.add_argument("--ideal-actuators", action="store_true")
    p.add_argument("--hil-sensor-hz", type=float, default=None,
                   help="with the truth profile: HIL_SENSOR rate in simulated time (0: off; "
                        "default 100)")
    p.add_argument("--sensors", metavar="PROFILE",
                   help="sensor profile: a name in config/sensors/ (truth, mocap-indoor, "
                        "degraded, px4-default) or a .toml file (default: the scenario's, "
                        "else truth; with px4-hil, px4-default)")
    p.add_argument("--seed", type=int, metavar="N",
                   help="seed of the sensors' noise (default: the scenario's seed)")
    p.add_argument("--resend-ms", type=float, default=None,
                   help="re-send an unanswered state after this wall time (default 5)")
    p.add_argument("--sysid", type=int, default=1)
    p.add_argument("--stats", type=Path,
                   help="write run statistics (JSON: counts, per-step stage times) here at exit")
    p.add_argument("--position", metavar="X,Y,Z",
                   help="start position in ENU metres (default: the scenario's)")
    p.add_argument("--speed-factor", type=float, metavar="X",
                   help="pace the lockstep (dqflight, px4-hil) at X times the wall clock "
                        "(1: real time, as PX4's Gazebo runs by default; default: as fast as "
                        "the FCU or PX4 answers). A ground station's timers run on the wall "
                        "clock: with a person or a script at `gcs`, use 1 to a few")
    return p


def _check_protocol_options(args: argparse.Namespace) -> None:
    """Refuse what the chosen protocol does not take (exit 2), fill in the defaults."""
    if args.protocol != DQFLIGHT:
        given = [name for name in DQFLIGHT_ONLY if getattr(args, name) not in (None, False)]
        if given:
            flag = "--" + given[0].replace("_", "-")
            raise ConfigError(f"{flag} does not apply to --protocol {args.protocol}: the "
                              "firmware sets the rates and drives simulated time")
    if args.speed_factor is not None:
        if args.protocol == "ardupilot-json" or args.realtime:
            raise ConfigError("--speed-factor paces a lockstep (dqflight, px4-hil): not with "
                              + ("--realtime" if args.realtime else
                                 "--protocol ardupilot-json (ArduPilot paces itself: its "
                                 "--speedup)"))
        if not (math.isfinite(args.speed_factor) and args.speed_factor > 0.0):
            raise ConfigError(f"--speed-factor {args.speed_factor:g}: a positive number")
    if args.link is None:
        args.link = DEFAULT_LINKS[args.protocol]
    if args.hil_sensor_hz is None:
        args.hil_sensor_hz = 100.0
    if args.resend_ms is None:
        args.resend_ms = 5.0
    if args.rt_priority is None:
        args.rt_priority = SITL_PRIORITY
    if not 0 <= args.rt_priority <= 99:
        raise ConfigError(f"--rt-priority: expected 0..99, got {args.rt_priority}")


def _position(text: str) -> tuple[float, float, float]:
    """`--position X,Y,Z`: three finite ENU metres (ConfigError otherwise)."""
    try:
        xyz = tuple(float(v) for v in text.split(","))
    except ValueError:
        xyz = ()
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise ConfigError(f"--position: expected X,Y,Z in metres, got {text}")
    return xyz[0], xyz[1], xyz[2]


def _scenario(args: argparse.Namespace) -> Scenario:
    """The scenario file with the command line's overrides (actuators, start position,
    sensor profile, seed), checked."""
    # The scenario's code and its libraries (numpy, numba) load here, after the command
    # line's own checks
    from common.config.scenario import check_sensor_faults, load_scenario
    from common.config.sensors import resolve_sensor_profile

    scenario = load_scenario(args.scenario, firmware=args.protocol != DQFLIGHT)
    if args.ideal_actuators:
        scenario = dataclasses.replace(scenario, ideal_actuators=True)
    if args.position is not None:
        scenario = dataclasses.replace(scenario, initial_position_enu_m=_position(args.position))
    if args.sensors is not None:
        scenario = dataclasses.replace(scenario, sensors=resolve_sensor_profile(args.sensors))
    check_sensor_faults(scenario.sensor_faults, scenario.sensors, "--sensors")
    if args.seed is not None:
        if not 0 <= args.seed < 2**63:
            raise ConfigError(f"--seed: expected 0..2^63-1, got {args.seed}")
        scenario = dataclasses.replace(scenario, seed=args.seed)
    return scenario


def _end_time(args: argparse.Namespace, scenario: Scenario) -> float | None:
    """Simulated seconds to serve: --end-time, else the scenario's duration for a dqflight
    lockstep run, else no end (ConfigError for a bad value)."""
    end: float | None = args.end_time
    if end is None and not args.realtime and args.protocol == DQFLIGHT:
        end = scenario.duration_s
    if end is not None and not (math.isfinite(end) and end > 0):
        raise ConfigError(f"--end-time: expected a positive number of seconds, got {end}")
    return end


def main(argv: list[str] | None = None) -> int:
    stop_with_parent()
    args = build_parser().parse_args(argv)
    setup_logging("sitl", args)

    startup.guard()  # a stop while starting (loading the kernels, say) is looked at below
    try:
        _check_protocol_options(args)
        parse_url(args.link)  # before anything is opened
        check_output_path("--truth-log", args.truth_log)
        check_output_path("--stats", args.stats)
        scenario = _scenario(args)
        rate = args.control_rate or scenario.control_rate_hz
        if not 1 <= rate <= 1000:
            raise ConfigError(f"--control-rate: expected 1..1000 Hz, got {rate}")
        end = _end_time(args, scenario)
        if args.protocol != DQFLIGHT:
            return _serve_firmware(args, scenario, end)
        log.debug("sitl: scenario %s from %s, control at %s Hz, end at %s s of simulated "
                  "time", scenario.name, args.scenario, rate, end)
        from sitl.server import SimulatorServer

        server = SimulatorServer(scenario, args.link, truth_log=args.truth_log,
                                 end_time_s=end, realtime=args.realtime,
                                 control_rate_hz=rate, hil_sensor_hz=args.hil_sensor_hz,
                                 resend_ms=args.resend_ms, system_id=args.sysid,
                                 sensors=scenario.sensors, seed=scenario.seed,
                                 speed_factor=args.speed_factor)
    except (KeyboardInterrupt, LinkError, *STARTUP_ERRORS, OSError) as exc:
        return start_failed("sitl", exc)
    said = (f"sitl: serving {scenario.name} on {args.link} "
            f"({'real time' if args.realtime else 'lockstep'})")
    if not serve("sitl", server, said, rt_priority=args.rt_priority if args.realtime else None,
                 stats=args.stats, stats_of=server.stats):
        return 0
    say(f"sitl: stopped at t = {server.state.time_us * 1e-6:.3f} s after {server.steps} "
        f"control periods; {server.resends} re-sends, {server.ignored_answers} answers "
        f"ignored, {server.rejected_bytes} bytes rejected, {server.skipped_s:.3f} s of wall "
        "time skipped")
    return 0


def _serve_firmware(args: argparse.Namespace, scenario: Scenario, end_s: float | None) -> int:
    """Serve the plant to real firmware over its own simulator protocol until SIGTERM or
    Ctrl-C (or `end_s` of simulated time after the firmware's first packet)."""
    module = importlib.import_module(FIRMWARE_MODULES[args.protocol])
    try:
        pace = {} if args.speed_factor is None else {"speed_factor": args.speed_factor}
        server: FirmwareServer = module.Server(scenario, args.link, truth_log=args.truth_log,
                                               end_time_s=end_s, system_id=args.sysid, **pace)
    except (LinkError, *STARTUP_ERRORS) as exc:
        return start_failed("sitl", exc)
    said = (f"sitl: serving {scenario.name} on {args.link} ({args.protocol}, lockstep driven "
            "by the firmware)")
    if not serve("sitl", server, said, stats=args.stats, stats_of=server.stats):
        return 0
    say(f"sitl: {server.summary()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
