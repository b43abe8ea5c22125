"""Warm-ups: kernels run once on sample inputs of their run-time types, so that compiling
them or loading them from the cache (`common.jit`) happens before the first control step,
not in it. Pure: how a warm-up is run (timed, Ctrl-C deferred) is the programs' edge's
choice (`common.process.startup` installs it), so nothing here reads a clock.
"""

from __future__ import annotations

from collections.abc import Callable

_warmed: set[str] = set()
WarmUpRunner = Callable[[Callable[[], object]], None]


def _call(call: Callable[[], object]) -> None:
    call()


_runner: list[WarmUpRunner] = [_call]


def run_warm_ups_with(runner: WarmUpRunner) -> None:
    """How `warm_up` runs its calls from now on: the programs' edge times them and defers
    Ctrl-C around them (`common.process.startup`); this module has no clock of its own."""
    _runner[0] = runner


def warm_up(name: str, call: Callable[[], object]) -> None:
    """Run `call` (kernels on sample inputs of their run-time types) once per process: its
    first call compiles the kernels or loads them from the cache, here rather than in the
    first control step."""
    if name in _warmed:
        return
    _warmed.add(name)
    _runner[0](call)
