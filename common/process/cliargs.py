"""The command lines' shared argument parser: errors in one line, exit status 2."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import NoReturn

from common.config.reader import ConfigError


class OneLineParser(argparse.ArgumentParser):
    """argparse whose errors are one line on stderr (`fcu: the following arguments are
    required: --vehicle (see fcu --help)`), exit status 2, instead of the usage block."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


def check_output_path(option: str, path: Path | None) -> None:
    """A file the process will write: its folder must exist (ConfigError otherwise)."""
    if path is None:
        return
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder, not a file")
    if not path.parent.is_dir():
        raise ConfigError(f"{option} {path}: folder {path.parent} does not exist")


def read_text_file(path: Path, error: type[Exception]) -> str:
    """A text file the user named, or `error` with one line saying why it cannot be read."""
    try:
        return path.read_text()
    except OSError as exc:
        raise error(f"{path}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None
