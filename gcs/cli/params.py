"""`gcs param list`, `get`, `set`, `save` and `load` against a vehicle (a file to load was
read before the link was opened: `gcs.cli.inputs`)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from common.process.diagnostics import get_logger, say

log = get_logger(__name__)

if TYPE_CHECKING:
    from gcs.vehicle_link.session import Session



def param_command(args: argparse.Namespace, session: Session) -> int:
    from gcs.vehicle_link import params as vl
    from gcs.vehicle_link.param_wire import ParamValueError, intended

    if args.action == "list":
        for name, p in vl.param_values(session).items():
            say(f"{name:<16} {p.text()}")
        return 0
    if args.action == "get":
        say(f"{args.name} = {vl.param_read(session, args.name).text()}")
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
        log.error(f"gcs param: {exc}")
        return 2
    for text in texts:
        say(f"vehicle: {text}")
    now = vl.ParamValue(value, current.param_type).text()
    say(f"{args.name} = {now}")
    if value == intended(args.name, args.value, current.param_type):
        return 0
    say(f"not taken: the vehicle keeps {now}")  # clamped, or refused with its reason
    return 1


def _param_save(args: argparse.Namespace, session: Session) -> int:
    from common.wire.mavlink import MAV
    from gcs.mission_files.param_files import ParamEntry, format_params
    from gcs.vehicle_link import params as vl

    values = vl.param_values(session)
    t, c = session.target_system, session.target_component
    beat = session.heartbeat_msg  # the autopilot's (the link's latest may be a companion's)
    stack = vehicle = version = git = ""
    if beat is not None:
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
    say(f"saved {len(entries)} parameters to {args.file}")
    return 0


def _param_load(args: argparse.Namespace, session: Session) -> int:
    from gcs.vehicle_link import params as vl
    from gcs.vehicle_link.param_wire import ParamValueError, intended
    from gcs.vehicle_link.session import GcsError

    t, c = session.target_system, session.target_component
    refused = 0
    entries = [e for e in args.params if e.component_id in (c, 0)]
    others = len(args.params) - len(entries)
    if others:
        log.info(f"skipped {others} parameters of other components than {c}")
    if any(e.system_id != t for e in entries):
        log.info(f"note: the file holds parameters of another vehicle; loading into system {t}")
    for e in entries:
        try:  # the vehicle's own type, whatever the file says (older files say 9 for all)
            ptype = vl.param_read(session, e.name).param_type
            value, texts = vl.param_set(session, e.name, e.value, param_type=ptype,
                                        linger=False)
        except vl.ParamRefused as exc:
            say(f"{e.name}: {exc.reason}")
            refused += 1
            continue
        except GcsError:
            say(f"{e.name}: not answered (unknown to the vehicle?)")
            refused += 1
            continue
        except ParamValueError as exc:
            say(f"{e.name} = {e.value:g}: {exc}")
            refused += 1
            continue
        if value != intended(e.name, e.value, ptype):
            said = "; ".join(" ".join(str(x).split()) for x in texts)
            say(f"{e.name} = {e.value:g}: " +
                (f"vehicle: {said}" if said else
                 f"not taken (the vehicle keeps {vl.ParamValue(value, ptype).text()})"))
            refused += 1
    say(f"loaded {len(entries) - refused} of {len(entries)} parameters from {args.file}")
    return 0 if refused == 0 else 1
