"""`gcs mission upload`, `download`, `clear` and `start` against a vehicle (the file was
read before the link was opened: `gcs.cli.inputs`).

An upload to ArduPilot is not atomic (ArduPilot's GCS_MAVLink mission protocol truncates
its mission at MISSION_COUNT and writes each item as it comes): the upload first reads the
mission the vehicle holds and, when the vehicle refuses an item, puts it back, or says what
the vehicle now holds. PX4 and this project's FCU replace their mission only when the whole
upload succeeds. A plan written for another firmware says so and what was converted."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from common.process.diagnostics import get_logger, say
from gcs.cli.connection import print_result
from gcs.cli.console import Progress

log = get_logger(__name__)

if TYPE_CHECKING:
    from common.wire.mission_items import MissionItem
    from gcs.vehicle_link.mission_client import UploadResult
    from gcs.vehicle_link.session import Session


def mission_command(args: argparse.Namespace, session: Session) -> int:
    from common.wire.mavlink import MAV
    from common.wire.mission_items import plain_frame
    from gcs.autopilot import autopilot_of
    from gcs.mission_files import file_format, format_mission
    from gcs.mission_files.frames import to_frame
    from gcs.vehicle_link.mission_client import clear, download, home_position, result_name
    from gcs.vehicle_link.mission_home import is_home_item, split_home

    t, c, send = session.target_system, session.target_component, session.send
    progress = Progress()
    pilot = autopilot_of(session.heartbeat_msg)
    at_seq0 = pilot.mission_home_at_seq0  # ArduPilot: home is seq 0, the plan from seq 1

    def report(done: int, total: int) -> None:
        progress(f"mission: {done}/{total} items")

    if args.action == "upload":
        return _upload(args, session)
    if args.action == "download":
        # the _INT frames as the plain ones: PX4 answers in them whatever was uploaded
        items = [plain_frame(it) for it in
                 download(session.conn, t, c, progress=report, send=send)]
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
                log.error(f"gcs mission: --frame {frame}: the vehicle sent no HOME_POSITION")
                return 1
            frame = None  # a plan of global items needs no conversion
        hb = session.heartbeat_msg
        written = to_frame(items, frame, home)
        home_line = at_seq0
        if fmt == "wpl" and not at_seq0 and written and is_home_item(written[0]):
            # a first item that reads as a home line (an AMSL NAV_WAYPOINT) goes after the
            # vehicle's home, so that QGC and `gcs mission upload` take it for an item
            home = home or home_position(session.conn, t, c, send=send)
            if home is None:
                log.error("gcs mission: the first item is a NAV_WAYPOINT at an AMSL position, "
                          "which a QGC WPL 110 reader takes for home, and the vehicle sent no "
                          "HOME_POSITION to write before it: use --format plan or toml")
                return 1
            home_line = True
        text = format_mission(written, fmt, home, home_at_seq0=home_line,
                              firmware_type=pilot.firmware_type, vehicle_type=hb.type)
        if args.file is None:
            say(text, end="")
        else:
            args.file.write_text(text)
            say(f"downloaded {len(items)} items to {args.file}"
                + (" (and home, seq 0)" if at_seq0 and home is not None else "")
                + (" after the vehicle's home as line 0" if home_line and not at_seq0
                   else ""))
        return 0
    if args.action == "clear":
        result = clear(session.conn, t, c, send=send)
        say(f"clear: {result_name(result)}")
        return 0 if result == MAV.MAV_MISSION_ACCEPTED else 1
    return _start(args, session)


def _start(args: argparse.Namespace, session: Session) -> int:
    """`gcs mission start`: MISSION_START to an armed vehicle, or with `--arm` armed first.
    A disarmed vehicle without `--arm` is refused before anything is sent (exit 1): PX4 arms
    on MISSION_START and takes off (Commander's VEHICLE_CMD_MISSION_START), where ArduCopter
    and this FCU wait to be armed, so the same command would do two different things."""
    from common.wire.mavlink import MAV
    from gcs.autopilot.commands import flight_state
    from gcs.vehicle_link.actions import arm

    if not flight_state(session)[0]:
        if not args.arm:
            log.error("gcs mission start: the vehicle is disarmed: arm it first (gcs arm) or "
                      "give --arm; nothing sent")
            return 1
        if (armed := arm(session, True)) != MAV.MAV_RESULT_ACCEPTED:
            return print_result("arm", armed, session)
        say("arm: MAV_RESULT_ACCEPTED")
    return print_result("mission start", session.command(MAV.MAV_CMD_MISSION_START), session)


def _upload(args: argparse.Namespace, session: Session) -> int:
    """`gcs mission upload`: 0 accepted, 1 refused or failed at the vehicle, 2 a plan of
    another firmware whose conversion is not exact (nothing sent)."""
    from common.wire.mavlink import MAV
    from gcs.autopilot import ARDUPILOT, autopilot_of
    from gcs.vehicle_link.mission_client import (
        MissionError,
        download,
        home_position,
        result_name,
        upload_detailed,
    )
    from gcs.vehicle_link.mission_home import (
        HomeError,
        WireMission,
        for_ardupilot,
        is_home_item,
        plan_conversion,
        split_home,
        yaw_ignored,
    )

    t, c, send = session.target_system, session.target_component, session.send
    pilot = autopilot_of(session.heartbeat_msg)
    at_seq0 = pilot.mission_home_at_seq0  # ArduPilot: home is seq 0, the plan from seq 1
    items, doc = args.items, args.mission
    conversion = plan_conversion(doc.firmware, pilot.firmware_type, items) \
        if doc.fmt == "plan" else None
    if conversion is not None and conversion.refusal:
        log.error(f"gcs mission: {conversion.refusal}")
        return 2
    if conversion is not None:
        say(conversion.notice)
    wire = WireMission(list(items))
    if not at_seq0 and doc.fmt == "wpl" and items and is_home_item(items[0]):
        home, rest = split_home(items)  # line 0 is home, as QGC and MAVProxy read WPL 110
        assert home is not None
        say(f"line 0 is a home (lat {home.lat_deg:.7f}, lon {home.lon_deg:.7f} deg, alt "
            f"{home.alt_m:.2f} m AMSL), as QGC reads a QGC WPL 110 file: not sent (it would "
            f"fly as a waypoint at that altitude)")
        wire = WireMission(rest)
    if at_seq0:
        need_home = doc.home is None or any(it.frame == MAV.MAV_FRAME_LOCAL_NED for it in items)
        vehicle_home = home_position(session.conn, t, c, send=send) if need_home else None
        try:
            wire = for_ardupilot(items, doc.fmt, doc.home, vehicle_home)
        except HomeError as exc:
            log.error(f"gcs mission: {exc}")
            return 1
        h = wire.home
        assert h is not None
        say(f"home (seq 0): lat {h.lat_deg:.7f}, lon {h.lon_deg:.7f} deg, alt "
            f"{h.alt_m:.2f} m AMSL, from {wire.home_source}")
        if pilot.vehicle == "copter" and (yawed := yaw_ignored(wire.items[1:])):
            say(f"note: ArduCopter does not fly a waypoint's yaw (param4): item"
                f"{'s' if len(yawed) > 1 else ''} {', '.join(str(i + 1) for i in yawed)} of "
                f"{len(wire.items) - 1} point as its WP_YAW_BEHAVIOR says")
    progress = Progress()
    old: list[MissionItem] | None = None
    if pilot.kind == ARDUPILOT:  # not atomic: keep what it holds, to put it back
        try:
            old = download(session.conn, t, c, send=send, progress=lambda d, n: progress(
                f"reading the vehicle's mission: {d}/{n} items"))
        except MissionError as exc:
            progress.done()
            log.error(f"gcs mission: reading the mission the vehicle holds (to put it back if "
                      f"the upload is refused) failed: {exc}; nothing uploaded")
            return 1
    n = len(wire.items) - (1 if at_seq0 else 0)  # the plan's items, home not counted
    answer = upload_detailed(session.conn, t, c, wire.items, send=send,
                             progress=lambda d, total: progress(f"mission: {d}/{total} items"))
    progress.done()
    if answer.accepted:
        say(f"upload of {n} items: {result_name(answer.result)}")
        return 0
    which = "the home item (seq 0)" if at_seq0 and answer.asked == 0 else \
        f"item {answer.asked + (0 if at_seq0 else 1)} of {n}"
    where = f": {which}" if answer.about_item and not answer.notes else ""
    say(f"upload of {n} items refused: {answer.describe()}{where}")
    if old is not None and answer.asked >= 0:  # it had begun to take the new items
        _restore(session, old, wire.items, answer, f"vehicle refused {which} "
                 f"({answer.describe()})", at_seq0)
    return 1


def _restore(session: Session, old: list[MissionItem], new: list[MissionItem],
             refused: UploadResult, what: str, at_seq0: bool) -> None:
    """Put back the mission `old` that a non-atomic vehicle held before it refused part of
    `new`; say so, or say what it now holds (read back, else by ArduPilot's rule)."""
    from common.wire.mavlink import MAV
    from gcs.vehicle_link.mission_client import MissionError, clear, download, upload_detailed
    from gcs.vehicle_link.mission_home import after_refusal, describe_held, label_held

    t, c, send = session.target_system, session.target_component, session.send
    expected: list[str] | None = after_refusal(["old"] * len(old), len(new), refused.asked,
                                               "new")
    size = f"{len(old)}-item mission" + (
        f" (home at seq 0 and {len(old) - 1} items)" if at_seq0 and old else "")
    why = ""
    try:
        if old:
            back = upload_detailed(session.conn, t, c, old, send=send)
            if not back.accepted:
                why = f"refused: {back.describe()}"
                if back.asked >= 0 and expected is not None:
                    expected = after_refusal(expected, len(old), back.asked, "old")
        elif clear(session.conn, t, c, send=send) != MAV.MAV_MISSION_ACCEPTED:
            why, expected = "MISSION_CLEAR_ALL refused", None
    except MissionError as exc:
        why, expected = str(exc), None
    if not why:
        say(f"{what}; restored the {size} it held before")
        return
    try:
        held = download(session.conn, t, c, send=send)
        labels, how = label_held(held, old, new, expected or []), ""
    except MissionError as exc:
        labels = expected or []
        how = f" (by ArduPilot's rule; reading it back failed: {exc})" if expected is not None \
            else ""
    now = f"the vehicle now holds {describe_held(labels, at_seq0)}{how}" \
        if labels or how else "what the vehicle now holds is unknown (it could not be read)"
    say(f"{what}; putting back the {size} it held before failed: {why}; {now}")
