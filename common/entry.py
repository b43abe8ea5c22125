"""The console scripts `fcu`, `sitl` and `gcs`: each imports its program, then runs it.

Importing a program loads numpy, numba and its compiled kernels, which takes a while on a
busy machine; a Ctrl-C (SIGINT) in that time would otherwise end it with a KeyboardInterrupt
traceback and exit 130 before its own `main` could say anything. Here it says
"<prog>: stopped while starting" and exits 0, as each `main` does for a stop while it starts;
`fcu` and `sitl` stop their loops on SIGINT themselves, so one that reaches here from their
`main` came before the loop ran: the same line and exit 0. From `gcs` (an import inside
`main`, say) it is "gcs: interrupted", exit 130, the shell's code for SIGINT.
"""

from __future__ import annotations

import importlib
import sys


def _run(prog: str, module: str, *, loop_handles_sigint: bool) -> int:
    try:
        main = importlib.import_module(module).main
    except KeyboardInterrupt:
        print(f"{prog}: stopped while starting", file=sys.stderr, flush=True)
        return 0
    try:
        return int(main() or 0)
    except KeyboardInterrupt:  # where the program does not handle it itself
        if loop_handles_sigint:  # its loop stops on SIGINT: this came before the loop ran
            print(f"{prog}: stopped while starting", file=sys.stderr, flush=True)
            return 0
        print(f"{prog}: interrupted", file=sys.stderr, flush=True)
        return 130


def fcu() -> int:
    return _run("fcu", "fcu.node", loop_handles_sigint=True)


def sitl() -> int:
    return _run("sitl", "sitl.node", loop_handles_sigint=True)


def gcs() -> int:
    return _run("gcs", "gcs.cli", loop_handles_sigint=False)
