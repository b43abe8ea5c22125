"""The console scripts `fcu`, `sitl` and `gcs`: each imports its program, then runs it.

Importing a program loads numpy, numba and its compiled kernels, which takes a while on a
busy machine; a Ctrl-C (SIGINT) in that time would otherwise end it with a KeyboardInterrupt
traceback and exit 130 before its own `main` could say anything. Here it says
"<prog>: stopped while starting" and exits 0, as each `main` does for a stop while it starts;
one that reaches here from a running program (an import inside `main`, say) is
"<prog>: interrupted", exit 130, the shell's code for SIGINT.
"""

from __future__ import annotations

import importlib
import sys


def _run(prog: str, module: str) -> int:
    try:
        main = importlib.import_module(module).main
    except KeyboardInterrupt:
        print(f"{prog}: stopped while starting", file=sys.stderr, flush=True)
        return 0
    try:
        return int(main() or 0)
    except KeyboardInterrupt:  # where the program does not handle it itself (a late import)
        print(f"{prog}: interrupted", file=sys.stderr, flush=True)
        return 130


def fcu() -> int:
    return _run("fcu", "fcu.node")


def sitl() -> int:
    return _run("sitl", "sitl.node")


def gcs() -> int:
    return _run("gcs", "gcs.cli")
