"""How the mission check's batch kernels (`fcu.mission.verdicts.fits_many`,
`fcu.mission.stretch.stretch_many`) go through their moves: cut into contiguous shares of
about equal work (`shares`), a compiled call per share, each releasing the GIL while it runs.
The calls are made one after another, unless the process has installed a runner that makes
them side by side (`install`: the FCU's worker process runs them on two threads,
`fcu.edge.work_process`). Each move is computed alone, from the same inputs by the same code,
so every verdict and every stretched duration is the same to the bit however the moves are
shared out and whatever runs the shares.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

Call = Callable[[], None]
Runner = Callable[[Sequence[Call]], None]
LEAST_PER_SHARE = 16  # moves: fewer are not worth a share of their own


def in_turn(calls: Sequence[Call]) -> None:
    """The calls, one after another in this thread (the runner a process starts with)."""
    for call in calls:
        call()


_RUNNER: list[tuple[Runner, int]] = [(in_turn, 1)]


def install(runner: Runner, ways: int) -> None:
    """Run the shares with `runner`, cut `ways` ways (`in_turn`, 1: back to the start)."""
    if ways < 1:
        raise ValueError(f"ways must be at least 1, not {ways}")
    _RUNNER[0] = (runner, ways)


def ways() -> int:
    """How many shares the installed runner takes at most."""
    return _RUNNER[0][1]


def run(calls: Sequence[Call]) -> None:
    """The calls, by the installed runner; every one has returned when this returns."""
    _RUNNER[0][0](calls)


def shares(order: np.ndarray, work: np.ndarray) -> list[np.ndarray]:
    """`order` (move indices, in the order a kernel takes them) cut into at most `ways()`
    contiguous pieces of about equal `work` (one value per entry of `order`): a piece per
    LEAST_PER_SHARE moves at most, and no cut within the first or the last LEAST_PER_SHARE."""
    count = min(ways(), len(order) // LEAST_PER_SHARE)
    if count <= 1:
        return [order]
    done = np.cumsum(work, dtype=np.float64)
    cuts = np.searchsorted(done, done[-1] * np.arange(1, count) / count)
    cuts = np.clip(cuts, LEAST_PER_SHARE, len(order) - LEAST_PER_SHARE)
    return [piece for piece in np.split(order, np.unique(cuts)) if len(piece)]
