"""A program's edge, written once for `fcu` and `sitl`: the one line and exit status of a
start that failed (`start_failed`), and the loop served (`serve`): a stop asked for while it
started (`common.process.startup`), the signals that end it, the real-time schedule, the statistics
written whole."""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from common.config.reader import ConfigError
from common.links import LinkError
from common.logs.errors import ULogError
from common.process import startup
from common.process.diagnostics import get_logger, say
from common.process.realtime import schedule_loop
from common.wire.mavlink import SigningKeyError

log = get_logger(__name__)

# a program that cannot start for these says why in one line and exits 2 (`start_failed`)
STARTUP_ERRORS = (ConfigError, SigningKeyError, ULogError)


class Loop(Protocol):
    """A program's main loop as `serve` runs it: `run` until `running` is cleared."""

    running: bool

    def run(self) -> None: ...

    def close(self) -> None: ...


def start_failed(prog: str, exc: BaseException) -> int:
    """The one line and the exit status of a program that could not start: 0 for a stop
    asked for while it started (nothing flown), a link's own status (2: a bad URL, a busy
    port, a missing device; 1: no peer), 2 for bad configuration or a file that cannot be
    written. Anything else is raised again."""
    if isinstance(exc, KeyboardInterrupt):  # Ctrl-C or SIGTERM before the loop ran
        log.warning("%s: stopped while starting", prog)
        return 0
    if isinstance(exc, LinkError):
        log.error("%s: %s", prog, exc)
        return exc.exit_code
    if isinstance(exc, STARTUP_ERRORS):
        log.error("%s: %s", prog, exc)
        return 2
    if isinstance(exc, OSError):  # a file that cannot be written
        log.error("%s: %s: %s", prog, exc.filename or '', exc.strerror or exc)
        return 2
    raise exc


def serve(prog: str, loop: Loop, said: str, *, rt_priority: int | None = None,
          stats: Path | None = None, stats_of: Callable[[], dict[str, Any]] | None = None,
          on_hup: Callable[[], None] | None = None) -> bool:
    """Run a started program's loop; False (and the loop closed) if a stop came while it
    started. Else SIGTERM and SIGINT end the loop (SIGHUP calls `on_hup` where given),
    `said` is written (program output), a real-time loop is scheduled (`rt_priority`,
    `common.process.realtime`), the loop runs, and `stats_of()` is written to `stats` whole
    (a temporary file renamed) when it ends; True."""
    if startup.stop_requested():  # Ctrl-C or SIGTERM while it started: nothing flown
        loop.close()
        log.warning("%s: stopped while starting", prog)
        return False

    def stop(_signum: int, _frame: object) -> None:
        loop.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if on_hup is not None:
        signal.signal(signal.SIGHUP, lambda _signum, _frame: on_hup())
    say(said)
    if rt_priority is not None:
        schedule_loop(prog, rt_priority)
    loop.run()
    if stats is not None and stats_of is not None:
        tmp = stats.with_suffix(".tmp")
        tmp.write_text(json.dumps(stats_of(), indent=2) + "\n")
        os.replace(tmp, stats)
    return True
