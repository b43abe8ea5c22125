"""`gcs mission upload`, `download`, `clear` and `start` against a vehicle (the file was
read before the link was opened: `gcs.cli.inputs`)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from gcs.cli.connection import print_result
from gcs.cli.console import Progress

if TYPE_CHECKING:
    from gcs.session import Session


def mission_command(args: argparse.Namespace, session: Session) -> int:
    from common.mavlink import MAV
    from gcs.autopilot import autopilot_of
    from gcs.mission_client import clear, download, home_position, result_name, upload_detailed
    from gcs.mission_files import file_format, format_mission
    from gcs.mission_files.frames import to_frame
    from gcs.mission_home import HomeError, WireMission, for_ardupilot, split_home

    t, c, send = session.target_system, session.target_component, session.send
    progress = Progress()
    pilot = autopilot_of(session.heartbeat_msg)
    at_seq0 = pilot.mission_home_at_seq0  # ArduPilot: home is seq 0, the plan from seq 1

    def report(done: int, total: int) -> None:
        progress(f"mission: {done}/{total} items")

    if args.action == "upload":
        items = args.items
        wire = WireMission(list(items))
        if at_seq0:
            need_home = args.mission.home is None or any(
                it.frame == MAV.MAV_FRAME_LOCAL_NED for it in items)
            vehicle_home = home_position(session.conn, t, c, send=send) if need_home \
                else None
            try:
                wire = for_ardupilot(items, args.mission.fmt, args.mission.home, vehicle_home)
            except HomeError as exc:
                print(f"gcs mission: {exc}", file=sys.stderr)
                return 1
            h = wire.home
            assert h is not None
            print(f"home (seq 0): lat {h.lat_deg:.7f}, lon {h.lon_deg:.7f} deg, alt "
                  f"{h.alt_m:.2f} m AMSL, from {wire.home_source}")
        n = len(wire.items) - (1 if at_seq0 else 0)  # the plan's items, home not counted
        answer = upload_detailed(session.conn, t, c, wire.items, progress=report, send=send)
        progress.done()
        if not answer.accepted:
            where = ""
            if answer.about_item and not answer.notes:  # the vehicle said not which
                where = ": the home item (seq 0)" if at_seq0 and answer.asked == 0 else \
                    f": item {answer.asked + (0 if at_seq0 else 1)} of {n}"
            print(f"upload of {n} items refused: {answer.describe()}{where}")
            return 1
        print(f"upload of {n} items: {result_name(answer.result)}")
        return 0
    if args.action == "download":
        items = download(session.conn, t, c, progress=report, send=send)
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
                print(f"gcs mission: --frame {frame}: the vehicle sent no HOME_POSITION",
                      file=sys.stderr)
                return 1
            frame = None  # a plan of global items needs no conversion
        hb = session.heartbeat_msg
        text = format_mission(to_frame(items, frame, home), fmt, home,
                              home_at_seq0=at_seq0, firmware_type=pilot.firmware_type,
                              vehicle_type=hb.type)
        if args.file is None:
            print(text, end="")
        else:
            args.file.write_text(text)
            print(f"downloaded {len(items)} items to {args.file}"
                  + (" (and home, seq 0)" if at_seq0 and home is not None else ""))
        return 0
    if args.action == "clear":
        result = clear(session.conn, t, c, send=send)
        print(f"clear: {result_name(result)}")
        return 0 if result == MAV.MAV_MISSION_ACCEPTED else 1
    return print_result("mission start", session.command(MAV.MAV_CMD_MISSION_START), session)
