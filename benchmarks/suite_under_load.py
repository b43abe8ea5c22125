"""The whole suite beside a CPU load: two busy processes at nice 19, as on a shared machine.

    .venv/bin/python benchmarks/suite_under_load.py [--times N] [--busy K] [--nice P]
        [-- pytest args]

Runs `make test`'s steps (ruff, mypy over the packages, then benchmarks/ and tools/, the
kernels into numba's cache (`tests/kernels.py`), then pytest with the arguments given, by
default `make test`'s: `-n 4 --dist loadgroup tests`) N times in a row beside K busy-looping
children at nice P (default 19; `--busy 8 --nice 0` is a load of 8 at
normal priority), prints each run's wall time and result, stops at the first failure, and
exits with that run's code (0 when all passed). The busy children are this script's own and
are stopped, by their process ids, on every way out, Ctrl-C included.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUSY = "while True:\n    pass\n"


def busy_children(count: int, niceness: int = 19) -> list[subprocess.Popen[bytes]]:
    """`count` busy-looping children at `niceness` (stop them with `stop_children`)."""
    return [subprocess.Popen([sys.executable, "-c", BUSY], preexec_fn=lambda: os.nice(niceness),
                             stdin=subprocess.DEVNULL) for _ in range(count)]


def stop_children(children: list[subprocess.Popen[bytes]]) -> None:
    """Stop these children, by their process ids, and reap them."""
    for child in children:
        child.send_signal(signal.SIGTERM)
    for child in children:
        child.wait()


def _suite(pytest_args: list[str]) -> int:
    steps = [[sys.executable, "-m", "ruff", "check", "."], [sys.executable, "-m", "mypy"],
             [sys.executable, "-m", "mypy", "benchmarks", "tools"],
             [sys.executable, "-m", "tests.kernels"],
             [sys.executable, "-m", "pytest", "-q",
              *(pytest_args or ["-n", "4", "--dist", "loadgroup", "tests"])]]
    for step in steps:
        code = subprocess.call(step, cwd=ROOT)
        if code != 0:
            return code
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--times", type=int, default=2, help="runs in a row (default 2)")
    parser.add_argument("--busy", type=int, default=2,
                        help="busy processes beside the suite (default 2)")
    parser.add_argument("--nice", type=int, default=19, choices=range(20), metavar="P",
                        help="their niceness, 0..19 (default 19)")
    parser.add_argument("pytest_args", nargs="*", help="after --: pytest's arguments")
    args = parser.parse_args(argv)
    if args.times < 1 or args.busy < 0:
        parser.error("--times must be at least 1 and --busy at least 0")
    busy = busy_children(args.busy, args.nice)
    code = 0
    try:
        for run in range(1, args.times + 1):
            start = time.monotonic()
            code = _suite(args.pytest_args)
            minutes, seconds = divmod(time.monotonic() - start, 60)
            result = "passed" if code == 0 else f"failed (exit {code})"
            print(f"run {run}/{args.times} beside {args.busy} busy at nice {args.nice}: {result} "
                  f"in {int(minutes)} min {seconds:.0f} s", flush=True)
            if code != 0:
                break
    except KeyboardInterrupt:
        code = 130
    finally:
        stop_children(busy)
    return code


if __name__ == "__main__":
    sys.exit(main())
