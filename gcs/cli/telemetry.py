"""`gcs log record` (a tlog of everything the vehicle sends) and `gcs view` (the Foxglove
WebSocket view of a live vehicle or of a run folder's logs)."""

from __future__ import annotations

import argparse
import time

from common.process.diagnostics import get_logger, say
from gcs.cli.connection import heartbeat_wait, open_session
from gcs.cli.console import Progress
from gcs.cli.parser import DEFAULT_CONNECT

log = get_logger(__name__)


def cmd_log(args: argparse.Namespace) -> int:
    from gcs.vehicle_link.snapshot import Snapshot, collect

    session = open_session(args, tlog=args.file)
    progress = Progress()
    snap = Snapshot()
    tlog = session.tlog
    assert tlog is not None  # opened with a tlog above

    try:
        end = time.monotonic() + (args.duration or float("inf"))
        while time.monotonic() < end:
            collect(session, snap, min(0.5, max(0.0, end - time.monotonic())))
            progress(f"recording {args.file}: {tlog.records} messages")
    except KeyboardInterrupt:
        pass
    finally:
        session.close()
        progress.done()
    # the records in the file: what was heard and what this station sent (its heartbeats)
    say(f"recorded {tlog.records} messages to {args.file}")
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    """Exit 0 on Ctrl-C, SIGTERM or the end of a replay, 1 without a vehicle, 2 for bad
    input (run folder, port, MCAP path)."""
    from common.wire.mavlink import read_signing_key
    from gcs.view import ViewError, view_live, view_replay

    try:
        if not 0 <= args.port <= 65535:
            raise ViewError(f"--port must be 0..65535, got {args.port}")
        if args.run_dir is not None:
            if args.connect != DEFAULT_CONNECT:
                raise ViewError("give RUN_DIR or --connect, not both")
            return view_replay(args.run_dir, port=args.port, mcap=args.mcap, speed=args.speed,
                               vehicle_file=args.vehicle)
        key = read_signing_key(args.signing_key) if args.signing_key else None
        return view_live(args.connect, port=args.port, mcap=args.mcap,
                         vehicle_file=args.vehicle, system_id=args.sysid,
                         wait_s=heartbeat_wait(args), signing_key=key)
    except ViewError as exc:
        log.error(f"gcs view: {exc}")
        return 2
