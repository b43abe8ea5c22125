"""How fast the host runs plain Python at this moment: one fixed loop, timed over and over.

The speed figures in docs/benchmarks.md come from a virtual machine that shares its host,
and that host's speed moves within seconds, so a figure read alone says as much about the
moment as about the code. Run this beside (or just before and after) a measurement: each
second prints the median time of the loop in it (300,000 float multiply-adds in CPython),
the end p10, p50 and p90 over all passes. The loop does no I/O and allocates nothing
that lives, so only the CPU it gets and how fast that CPU runs move its time.

Usage: host_speed.py [--seconds N] [--cpu K]  (`--cpu`: pinned to that core)
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

LOOP_N = 300_000


def one_pass() -> float:
    """The seconds one pass of the fixed loop takes."""
    t0 = time.perf_counter()
    s = 0.0
    for i in range(LOOP_N):
        s += i * 0.5
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="how long to time (s)")
    ap.add_argument("--cpu", type=int, default=None, help="pin to this core")
    args = ap.parse_args(argv)
    if not args.seconds > 0.0:
        ap.error(f"--seconds must be > 0, got {args.seconds}")
    if args.cpu is not None:
        try:
            os.sched_setaffinity(0, {args.cpu})
        except (OSError, ValueError) as exc:
            ap.error(f"--cpu {args.cpu}: {exc}")
    every: list[float] = []
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        second_end = min(time.monotonic() + 1.0, end)
        passes = [one_pass()]
        while time.monotonic() < second_end:
            passes.append(one_pass())
        every += passes
        print(f"{time.strftime('%H:%M:%S', time.gmtime())} UTC  median "
              f"{statistics.median(passes) * 1e3:6.2f} ms a pass ({len(passes)} passes)",
              flush=True)
    q = statistics.quantiles(every, n=10) if len(every) >= 2 else every * 9
    print(f"{len(every)} passes: p10 {q[0] * 1e3:.2f} ms, p50 "
          f"{statistics.median(every) * 1e3:.2f} ms, p90 {q[-1] * 1e3:.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
