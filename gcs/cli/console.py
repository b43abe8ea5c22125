"""What `gcs` commands share on the terminal: a progress line, and the one-line refusal of
bad input (exit status 2)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """One self-overwriting status line on a terminal; silent when piped."""

    def __init__(self, stream: TextIO = sys.stderr) -> None:
        self.stream = stream
        self.active = stream.isatty()
        self.t0 = time.monotonic()

    def __call__(self, text: str) -> None:
        if self.active:
            self.stream.write(f"\r\033[K{text}")
            self.stream.flush()

    def done(self) -> None:
        if self.active:
            self.stream.write("\r\033[K")
            self.stream.flush()


class InputError(ValueError):
    """Bad input found before anything is opened: one line, exit status 2."""

