"""Work beside the control loop: the computations a ground station or a mode change asks for
(the mission check, the mission's plan at MISSION_START, POSCTL's envelope fit) run here,
never inside a control step (docs/architecture.md, "Work beside the loop").

A job is a pure function and its arguments; its `Outcome` goes to a callback that the loop
calls at a step boundary (`take`), never half-way through a step. Two kinds:

- `InlineWork`: the job runs at once in the loop's thread, and its callback with it. This is
  the lockstep default: simulated time stands still while it runs (the simulator waits for
  the answer), so nothing flies on stale outputs, and a run is what it always was.
- `ProcessWork` (`fcu.edge.work_process`, the I/O edge): the job runs in a worker process at
  a lower priority (nice +10; a warm-up before the flight at the loop's). A process, not a
  thread: the checks are Python and numpy code that would hold the GIL for milliseconds at a
  time; a process keeps them off the loop's GIL and below its priority whatever they cost.
  This is the real-time default: the loop keeps flying the reference it has and takes the
  result in at the first step boundary after it came. With `wait=True` (lockstep through the
  worker) `submit` waits for the result and calls back at once: the same results as
  `InlineWork`, to the bit.

A worker that dies fails its jobs with the reason (and the next job starts a new worker);
a job that raises fails with the exception's text; neither stops the loop.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

T = TypeVar("T")
KINDS = ("inline", "beside")
HISTORY = 100  # jobs kept in `Work.history`


@dataclass(frozen=True)
class Outcome(Generic[T]):
    """A job's result, or why there is none (`error` not empty)."""

    value: T | None = None
    error: str = ""


Done = Callable[[Outcome[Any]], None]


class Work:
    """Where jobs run (`InlineWork`, `ProcessWork`); `take` calls back the finished ones.

    `steps` (set by the loop) counts control steps; every job's name and the steps the
    loop took while it was under way are kept in `history` (the latest HISTORY): 0 for
    work done where the loop waits for it, the proof that it did not where it ran beside."""

    kind = ""

    def __init__(self) -> None:
        self._finished: list[tuple[Done, Outcome[Any]]] = []
        self.submitted = 0
        self.failed = 0
        self.steps: Callable[[], int] = lambda: 0
        self.history: list[tuple[str, int]] = []  # (job, control steps while under way)

    @property
    def immediate(self) -> bool:
        """Whether `submit` calls back before it returns (the loop waits for the work)."""
        return False

    @property
    def pending(self) -> int:
        """Jobs submitted whose callback has not been called yet."""
        return len(self._finished)

    def submit(self, fn: Callable[..., Any], args: tuple[Any, ...], done: Done, *,
               warm_up: bool = False) -> None:
        """Run `fn(*args)` where this work runs; `done(outcome)` at a step boundary.

        `warm_up`: the job loads what later jobs need (kernels) before the flight; as a
        worker's first job it runs at the FCU's niceness (normal scheduling), and the worker
        lowers its own after it (on a busy machine a warm-up at nice +10 took a minute, and
        the first mission's check waited behind it)."""
        self.submitted += 1
        name, at = getattr(fn, "__name__", "job"), self.steps()

        def tracked(outcome: Outcome[Any]) -> None:
            self.failed += bool(outcome.error)
            del self.history[:-HISTORY + 1]
            self.history.append((name, self.steps() - at))
            done(outcome)

        self._submit(fn, args, tracked, warm_up)

    def _submit(self, fn: Callable[..., Any], args: tuple[Any, ...], done: Done,
                warm_up: bool) -> None:
        raise NotImplementedError

    def filenos(self) -> list[int]:
        """What the loop selects on to learn that a result came (none: results come at
        once)."""
        return []

    def take(self) -> int:
        """Call back every finished job, in the order they were submitted; how many."""
        finished, self._finished = self._finished, []
        for done, outcome in finished:
            done(outcome)
        return len(finished)

    def stats(self) -> dict[str, Any]:
        return {"kind": self.kind, "jobs": self.submitted, "failed": self.failed,
                "history": [{"job": name, "steps": n} for name, n in self.history]}

    def close(self) -> None:
        pass


def run_job(fn: Callable[..., Any], args: tuple[Any, ...]) -> Outcome[Any]:
    try:
        return Outcome(fn(*args))
    except Exception as exc:  # a job's bug: its requester says why, the loop flies on
        return Outcome(None, f"{type(exc).__name__}: {exc}")


class InlineWork(Work):
    """Jobs run at once in the caller's thread; their callbacks at once too."""

    kind = "inline"

    @property
    def immediate(self) -> bool:
        return True

    def _submit(self, fn: Callable[..., Any], args: tuple[Any, ...], done: Done,
                warm_up: bool) -> None:
        done(run_job(fn, args))
