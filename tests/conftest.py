"""Suite-wide set-up: the tiers by folder, a guard that keeps programs out of the fast tier,
and the flight core's kernels compiled on demand.

Tiers: a test that starts a program (`sitl`, `fcu`, `gcs`, a subprocess or a worker process
of ours) lives under tests/sitl/ or tests/docs/ (the README and docs blocks that run), and
is marked `process` here by its folder; the closed-loop flights of tests/closed_loop are marked
`slow` by theirs. `make test-fast` runs the rest (`-m "not slow and not process"`: the unit
tests); `make test` runs everything. A test outside those folders that starts a program
fails (`ProgramStarted`), and a `process` mark outside them stops the run.

Kernels: the first test that flies (tests/sitl, tests/docs, tests/closed_loop, or a module
that imports a flight's entry point) builds them once (`compiled_kernels`, `tests/kernels.py`)
under a file lock in numba's cache folder, so that they are compiled once into the on-disk
cache (`common/jit.py`) and every other worker and every `fcu` and `sitl` process the tests
start loads them from there. A test that flies nothing starts and flies nothing. `make test`
builds them before pytest starts (beside mypy): a fresh cache's compilation then counts
against no test's timeout."""

from __future__ import annotations

import multiprocessing.util
import os
import subprocess
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import pytest

from tests.kernels import build_kernels

ROOT = Path(__file__).resolve().parents[1]
CASE1 = ROOT / "config" / "scenarios" / "case1_figure8.toml"
TESTS = Path(__file__).resolve().parent
PROCESS_DIRS = (TESTS / "sitl", TESTS / "docs")  # the `process` tier, by folder
FLYING_DIRS = (*PROCESS_DIRS, TESTS / "closed_loop")
# A module that imports one of these flies the flight core in the worker.
FLIGHT_ENTRIES = ("run_scenario", "fcu_pipeline", "Plant", "run_table1")


def _under(item: pytest.Item, dirs: tuple[Path, ...]) -> bool:
    parents = Path(str(item.fspath)).parents
    return any(d in parents for d in dirs)


def _flies(item: pytest.Item) -> bool:
    module = getattr(item, "module", None)
    return _under(item, FLYING_DIRS) or any(hasattr(module, name) for name in FLIGHT_ENTRIES)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests of tests/sitl and tests/docs `process` (refused elsewhere), those of
    tests/closed_loop `slow`; a test that flies gets `compiled_kernels` first."""
    misplaced = []
    for item in items:
        if isinstance(item, pytest.Function) and _flies(item) and \
                "compiled_kernels" not in item.fixturenames:
            item.fixturenames.insert(0, "compiled_kernels")  # set up before the others
        if _under(item, (TESTS / "closed_loop",)):
            item.add_marker(pytest.mark.slow)
        if _under(item, PROCESS_DIRS):
            item.add_marker(pytest.mark.process)
        elif item.get_closest_marker("process") is not None:
            misplaced.append(item.nodeid)
    if misplaced:
        raise pytest.UsageError(f"{len(misplaced)} tests are marked process outside tests/sitl "
                                f"and tests/docs (e.g. {misplaced[0]}): move them there")


class ProgramStarted(RuntimeError):
    """A test of the fast tier started a program."""


def _refuse(what: str) -> Callable[..., Any]:
    def refuse(*args: object, **kwargs: object) -> Any:
        raise ProgramStarted(f"{what} in a test outside tests/sitl and tests/docs: a test "
                             "that starts a program belongs to the process tier (move it)")
    return refuse


@contextmanager
def no_programs() -> Iterator[None]:
    """Every way this suite's code starts a process (subprocess, multiprocessing's fork and
    spawn, os.system, posix_spawn) raises ProgramStarted meanwhile."""
    patches: list[tuple[object, str]] = [
        (subprocess.Popen, "_execute_child"), (os, "fork"), (os, "system"),
        (os, "posix_spawn"), (os, "posix_spawnp"), (multiprocessing.util, "spawnv_passfds")]
    with ExitStack() as stack:
        for owner, name in patches:
            old = getattr(owner, name)
            setattr(owner, name, _refuse(f"{getattr(owner, '__name__', owner)}.{name}"))
            stack.callback(setattr, owner, name, old)
        yield


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """A test not marked `process` (its fixtures' set-up and teardown too) starts no
    program: the guard of the fast tier."""
    if item.get_closest_marker("process") is not None:
        return (yield)
    with no_programs():
        return (yield)


@pytest.fixture(scope="session")
def compiled_kernels() -> bool:
    """The kernels in numba's on-disk cache before the first flight (`build_kernels`): the
    first fixture of every test that flies (`pytest_collection_modifyitems`)."""
    return build_kernels()  # at once when `make test` built them first


def pytest_collection_finish(session: pytest.Session) -> None:
    """Under `--dist loadgroup` every xdist_group mark must reach the test's id (`@group`),
    or the groups the suite relies on (one campaign cluster at a time, one clock-discipline
    run at a time, one table1 build) would be scattered over the workers without a word:
    pytest 9.2 with pytest-xdist 3.8 did that."""
    config = session.config
    if not getattr(config.option, "loadgroup", False):
        return
    lost = [item.nodeid for item in session.items
            if any(True for _ in item.iter_markers("xdist_group")) and "@" not in item.nodeid]
    if lost:
        raise pytest.UsageError(f"--dist loadgroup lost the xdist_group of {len(lost)} tests "
                                f"(e.g. {lost[0]}): this pytest and pytest-xdist disagree")
