"""The console scripts `fcu`, `sitl` and `gcs`: each imports its program, then runs it.

Importing a program loads numpy, numba and its compiled kernels, which takes a while on a
busy machine. A Ctrl-C or SIGTERM in that time is only recorded (`common.process.startup`; raised,
it could land inside numba's ctypes callbacks, which print it as an ignored exception with
its traceback and drop it), and after the import the program says "<prog>: stopped while
starting" and exits 0. `fcu` and `sitl` go on recording until their loops stop on SIGINT and
SIGTERM themselves (in `main` before the loop: the same words). From `gcs`, once imported, a
Ctrl-C is a KeyboardInterrupt again: "gcs: interrupted", exit 130, the shell's code for
SIGINT.

The guard is set as this module loads, before its other imports: what comes before it is
the interpreter's own start (tens of milliseconds of CPU), where a Ctrl-C is Python's.
"""

from __future__ import annotations

from common.process import startup

startup.guard()  # first: a stop from here on is recorded, not raised

import importlib  # noqa: E402  (after the guard, on purpose)

from common.process.diagnostics import get_logger  # noqa: E402

log = get_logger(__name__)


def _run(prog: str, module: str, *, loop_handles_sigint: bool) -> int:
    try:
        main = importlib.import_module(module).main
        if not loop_handles_sigint:
            startup.release()  # a stop recorded meanwhile raises here
    except KeyboardInterrupt:
        log.warning("%s: stopped while starting", prog)
        return 0
    if startup.stop_requested():
        log.warning("%s: stopped while starting", prog)
        return 0
    try:
        return int(main() or 0)
    except KeyboardInterrupt:  # where the program does not handle it itself
        if loop_handles_sigint:  # its loop stops on SIGINT: this came before the loop ran
            log.warning("%s: stopped while starting", prog)
            return 0
        log.error("%s: interrupted", prog)
        return 130


def fcu() -> int:
    return _run("fcu", "fcu.edge.node", loop_handles_sigint=True)


def sitl() -> int:
    return _run("sitl", "sitl.node", loop_handles_sigint=True)


def gcs() -> int:
    return _run("gcs", "gcs.cli", loop_handles_sigint=False)
