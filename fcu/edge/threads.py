"""`SideBySide`: the runner of `fcu.mission.batches` that the FCU's worker process installs
(`install_side_by_side`): a batch kernel's shares at once, one in the calling thread and the
others on a pool of threads the kernels can run on while they hold no GIL."""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

from fcu.mission import batches

MOST_WAYS = 2  # the mission check's shares at once: enough for the 2-core boards in use


class SideBySide:
    """Runs `calls[0]` in the calling thread and the others on `ways - 1` pool threads. The
    pool's threads are made by the thread that makes this runner, and take its priority."""

    def __init__(self, ways: int) -> None:
        self.ways = ways
        self._pool = ThreadPoolExecutor(max_workers=max(1, ways - 1),
                                        thread_name_prefix="fcu-check")

    def __call__(self, calls: Sequence[batches.Call]) -> None:
        futures = [self._pool.submit(call) for call in calls[1:]]
        try:
            if calls:
                calls[0]()
        finally:
            for future in futures:
                future.result()  # every share done (its error raised) before returning


def usable_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def install_side_by_side(most: int = MOST_WAYS) -> int:
    """Install a `SideBySide` of min(most, `usable_cpus()`) ways (none for 1); the ways."""
    ways = min(most, usable_cpus())
    if ways > 1:
        batches.install(SideBySide(ways), ways)
    return ways
