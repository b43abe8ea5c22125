"""What `gcs` checks before it opens a link or waits for a vehicle: URLs, signing keys,
mode names, the files a command reads or writes. A bad one is one line, exit status 2."""

from __future__ import annotations

import argparse
from pathlib import Path

from common.links import parse_url
from gcs.cli.console import InputError


def writable_file(path: Path, what: str) -> None:
    """A file about to be written: its folder must exist and it must not be a folder."""
    if path.is_dir():
        raise InputError(f"{what} {path} is a folder, not a file")
    parent = path.parent
    if not parent.is_dir():
        raise InputError(f"{what} {path}: folder {parent} does not exist"
                         if not parent.exists() else f"{what} {path}: {parent} is not a folder")


def check_input(args: argparse.Namespace) -> None:
    """Everything that can be checked before a link is opened or a vehicle waited for;
    InputError, LinkError or SigningKeyError (all exit status 2). Mission and parameter
    files are read by `read_files`, before any network wait too."""
    if getattr(args, "connect", None) is not None:
        parse_url(args.connect)
    if getattr(args, "signing_key", None):
        from common.wire.mavlink import read_signing_key

        read_signing_key(args.signing_key)
    if args.command == "mode":
        from gcs.autopilot import all_mode_names

        known = all_mode_names()
        if args.name.strip().upper() not in known:
            raise InputError(f"unknown mode {args.name} (one of {', '.join(known)})")
    elif args.command == "log":
        writable_file(args.file, "log file")


def read_files(args: argparse.Namespace) -> None:
    """Read the file a mission or param command takes, before any network wait: a bad one
    raises MissionFileError or InputError (one line, exit status 2); the contents go to
    args.items / args.params. Files to be written must have a folder to go to."""
    from gcs.mission_files import file_format, read_mission_doc
    from gcs.mission_files.param_files import ParamFileError, read_params

    if args.command == "mission" and args.action == "upload":
        args.mission = read_mission_doc(args.file, args.format)
        args.items = args.mission.items
    elif args.command == "mission" and args.action == "download" and args.file is not None:
        file_format(args.file, args.format)
        writable_file(args.file, "mission file")
    elif args.command == "param" and args.action == "save":
        writable_file(args.file, "parameter file")
    elif args.command == "param" and args.action == "load":
        try:
            args.params = read_params(args.file)
        except ParamFileError as exc:
            raise InputError(str(exc)) from None
