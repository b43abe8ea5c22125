"""The commands against a vehicle: `gcs status`, `arm`, `disarm`, `mode`, `takeoff`,
`goto`, `watch`, `vehicles`, and the dispatch to `mission` and `param`."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from common.process.diagnostics import say
from gcs.cli.connection import heartbeat_wait, open_session, print_result
from gcs.cli.console import InputError, Progress
from gcs.cli.inputs import read_files
from gcs.cli.missions import mission_command
from gcs.cli.params import param_command

if TYPE_CHECKING:
    from gcs.vehicle_link.session import Session


def cmd_vehicle(args: argparse.Namespace) -> int:
    """A command against a vehicle: its files read, the link opened, the command run, the
    link closed."""
    read_files(args)  # a bad file is refused before any network wait
    session = open_session(args)
    try:
        return _vehicle_command(args, session)
    finally:
        session.close()


def _vehicle_command(args: argparse.Namespace, session: Session) -> int:
    """`args.command` against the vehicle of `session`: its exit status."""
    from gcs.vehicle_link.actions import arm

    if args.command == "status":
        return _status(args, session)
    if args.command == "arm":
        return print_result("arm", arm(session, True), session)
    if args.command == "disarm":
        return print_result("disarm", arm(session, False, force=args.force), session)
    if args.command == "mode":
        return _mode(args, session)
    if args.command == "takeoff":
        return _takeoff(args, session)
    if args.command == "mission":
        return mission_command(args, session)
    if args.command == "param":
        return param_command(args, session)
    if args.command == "goto":
        return _goto(args, session)
    if args.command == "watch":
        from gcs.cli.watch import watch

        return watch(session, refresh_hz=args.rate, duration=args.duration,
                     all_vehicles=args.all)
    if args.command == "vehicles":
        return _vehicles(args, session)
    raise AssertionError(args.command)


def _status(args: argparse.Namespace, session: Session) -> int:
    """`gcs status`: the vehicle's status, as lines or one JSON document (--json)."""
    from gcs.vehicle_link.status import format_status, status

    if args.json:
        import json

        say(json.dumps(status(session), allow_nan=False))
    else:
        say("\n".join(format_status(status(session))))
    return 0


def _vehicles(args: argparse.Namespace, session: Session) -> int:
    """`gcs vehicles`: the system id of every vehicle heard, one a line."""
    from gcs.vehicle_link.status import vehicles

    for sysid in vehicles(session, heartbeat_wait(args)):
        say(str(sysid))
    return 0


def _mode(args: argparse.Namespace, session: Session) -> int:
    """Exit 0 once a HEARTBEAT shows the mode; 1 refused or not confirmed; 2 a name the
    autopilot does not have (with its names)."""
    from gcs.autopilot import UnknownMode
    from gcs.autopilot.commands import CONFIRM_S
    from gcs.vehicle_link.actions import set_mode

    confirm = CONFIRM_S if args.wait is None else args.wait
    _refuse_bare_offboard(session, args.name)
    try:
        result = set_mode(session, args.name, confirm_s=confirm)
    except UnknownMode as exc:
        raise InputError(str(exc)) from None
    return print_result(f"mode {args.name.upper()}", result, session)


def _refuse_bare_offboard(session: Session, name: str) -> None:
    """InputError for OFFBOARD asked of PX4 by `gcs mode`, which streams no set-points:
    PX4 refuses it in the air, and on the ground it accepts it and then outputs nothing
    (with PX4 SITL in lockstep its simulated clock stops). `gcs goto` streams first."""
    from gcs.autopilot import PX4, UnknownMode
    from gcs.vehicle_link.goto import flies_pose

    ap = session.autopilot
    if ap is None or ap.kind != PX4:
        return
    try:
        target = ap.resolve_mode(name)
    except UnknownMode:
        return  # said by set_mode, with the names
    if target.name == "OFFBOARD" and not flies_pose(session):
        raise InputError("OFFBOARD on PX4 needs a set-point stream before and during it, "
                         "which gcs mode does not send: use gcs goto X Y Z")


def _takeoff(args: argparse.Namespace, session: Session) -> int:
    from gcs.autopilot.commands import CONFIRM_S
    from gcs.vehicle_link.actions import takeoff

    progress = Progress()
    confirm = CONFIRM_S if args.wait is None else args.wait
    result, height = takeoff(session, args.alt, reach_s=None if args.no_wait else
                                args.timeout, tolerance_m=args.tolerance, confirm_s=confirm,
                                report=lambda h: progress(f"takeoff: {h:.2f} m above home"),
                                notice=say)
    progress.done()
    code = print_result(f"takeoff to {args.alt:g} m", result, session)
    if code == 0 and height is not None:
        say(f"reached: {height:.2f} m above home")
    return code


def _goto(args: argparse.Namespace, session: Session) -> int:
    """Exit 0 once the pose is reached and held; 1 refused, not reached, unsafe (the
    vehicle fell: hold commanded), a disarmed vehicle without --arm, an ArduPilot vehicle
    on the ground; 2 a roll or a pitch for a vehicle that cannot fly one apart from its
    position."""
    from gcs.vehicle_link.goto import flies_pose, goto
    from gcs.vehicle_link.pose import PoseTarget

    full = flies_pose(session)
    if not full and (args.roll or args.pitch):
        ap = session.autopilot
        label = ap.label if ap is not None else "the vehicle"
        raise InputError(f"--roll and --pitch must be 0 on {label}: it flies a position and a "
                         "yaw (an attitude target there replaces the position target); only "
                         "a vehicle that flies position and attitude together (this project's "
                         "FCU, by its AUTOPILOT_VERSION) takes them")

    target = PoseTarget.from_euler_deg((args.x, args.y, args.z), args.roll, args.pitch,
                                       args.yaw)
    progress = Progress()
    # "attitude error" on every vehicle (an interface): the yaw's where only the yaw is flown

    def report(errs: tuple[float, float]) -> None:
        progress(f"goto: position error {errs[0]:.3f} m, attitude error "
                 f"{math.degrees(errs[1]):.2f} deg")

    dp, da = goto(session, target, arm_first=args.arm, tolerance_m=args.tolerance,
                  tolerance_rad=math.radians(args.tolerance_deg), timeout=args.timeout,
                  hold_s=args.hold, report=report, full_pose=full)
    progress.done()
    say(f"reached: position error {dp:.4f} m, attitude error {math.degrees(da):.3f} deg")
    return 0
