"""The link to the vehicle that the vehicle commands share: opening the session (waiting
for the heartbeat, asking for the telemetry the command needs) and printing its answers."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from common.process.diagnostics import say
from gcs.cli.parser import HEARTBEAT_WAIT_S

if TYPE_CHECKING:
    from gcs.vehicle_link.session import Session


def open_session(args: argparse.Namespace, tlog: Path | None = None) -> Session:
    from common.wire.mavlink import read_signing_key
    from gcs.vehicle_link.session import Session

    key = read_signing_key(args.signing_key) if args.signing_key else None
    session = Session(args.connect, tlog=tlog, vehicle=args.sysid or 0, signing_key=key)
    try:
        session.wait_vehicle(timeout=heartbeat_wait(args), system_id=args.sysid)
        _request_streams(session, args)
    except BaseException:
        session.close()
        raise
    return session


def heartbeat_wait(args: argparse.Namespace) -> float:
    return HEARTBEAT_WAIT_S if args.wait is None else args.wait


def _request_streams(session: Session, args: argparse.Namespace) -> None:
    """Ask the vehicle for the telemetry the command needs (ArduPilot sends little until
    asked); the session gives back what it changed when it closes."""
    from gcs.autopilot.streams import needs

    if session.autopilot is not None:
        session.request_streams(needs(args.command, session.autopilot.kind))


def print_result(what: str, result: int, session: Session | None = None) -> int:
    """The vehicle's answer; a refusal with the reason it gave (its STATUSTEXT)."""
    from common.wire.mavlink import MAV

    if result == MAV.MAV_RESULT_ACCEPTED:
        say(f"{what}: MAV_RESULT_ACCEPTED")
        return 0
    if session is not None:
        say(f"{what} refused: {session.describe(result)}")
    else:
        enum = MAV.enums["MAV_RESULT"]
        say(f"{what} refused: {enum[result].name if result in enum else result}")
    return 1
