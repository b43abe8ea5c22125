"""Clock discipline through processes (docs/clocks.md): a lockstep run is the same run, sample
for sample, whatever the wall clock does (a paused simulator, a paused FCU, a machine with no
CPU to spare); in real time a simulator that stops answering in the air is a state-input loss,
and the run says so.

Each run is a `gcs run` subprocess; the simulated time (and height) of a run in progress is
read from the tail of its truth log, whose rows are counted as they complete."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from common.logs.ulog import read_topic, tail_record

from .conftest import ROOT, SCENARIOS
from .waits import cpu_s, until

CASE1 = SCENARIOS / "case1_figure8.toml"
DURATION_S = 26.0  # lockstep runs: the climb, the hover and 6 s of the figure-infinity
PAUSE_AT_S = 22.0  # simulated time at which a child is paused (in the figure-infinity)
PAUSE_S = 3.0
HOG_DURATION_S = 6.0  # the run beside the CPU hogs: the take-off, the quiet run's first 6 s
# (the hogs take a core for as long as it lasts: 3,000 steps starved are as telling as 6,000)
RT_DURATION_S = 14.0  # the real-time run
RT_PAUSE_S = 2.0
RT_PAUSE_ABOVE_M = 2.0
# One worker runs the whole module, so the quiet reference run is flown once.
pytestmark = pytest.mark.xdist_group("clock_discipline")
RUN_WAIT_S = 240.0  # wall-clock allowance of one `gcs run` on a loaded machine


# ---------------------------------------------------------------------------- helpers


def _tail(path: Path) -> tuple[tuple[str, ...], tuple[float, ...]] | None:
    """(columns, last complete record) of a truth log that may still be written, None before
    its first record (cheap enough to poll)."""
    return tail_record(path, "dq_truth")


SETTLE_S = 0.5  # after a child is stopped, at least, before simulated time is read


def _sim_time_s(out: Path) -> float | None:
    tail = _tail(out / "truth.ulg")
    return None if tail is None else float(tail[1][0]) * 1e-6


def _height_m(out: Path) -> float | None:
    tail = _tail(out / "truth.ulg")
    return None if tail is None else float(tail[1][tail[0].index("pz")])


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(
            errors="replace")
    except OSError:
        return ""


MODULES = {"sitl": "sitl.node", "fcu": "fcu.edge.node"}  # each child's `python -m` module


def _children(pid: int) -> dict[str, int]:
    """The `sitl` and `fcu` children of process pid, by name."""
    found: dict[str, int] = {}
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids = (task / "children").read_text().split()
        except OSError:
            continue
        for kid in map(int, kids):
            cmd = _cmdline(kid)
            for name, module in MODULES.items():
                if f"-m {module}" in cmd:
                    found[name] = kid
    return found


@dataclass
class Run:
    """One `gcs run` of Case I in progress, its children, and the signals sent to them."""

    out: Path
    proc: subprocess.Popen
    t0: float
    children: dict[str, int] = field(default_factory=dict)
    stopped: set[int] = field(default_factory=set)
    wall_s: float = 0.0
    returncode: int | None = None

    def output(self) -> str:
        return "\n".join((self.out.parent / f"{self.out.name}.{k}").read_text(errors="replace")
                         [-3000:] for k in ("stdout", "stderr"))

    def find_children(self, timeout: float = 60.0) -> dict[str, int]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.proc.poll() is None:
            self.children = _children(self.proc.pid)
            if len(self.children) == 2:
                return self.children
            time.sleep(0.05)
        raise AssertionError(f"no sitl and fcu children of gcs run {self.proc.pid} "
                             f"(found {self.children}):\n{self.output()}")

    def _ours(self, pid: int, name: str) -> bool:
        return _alive(pid) and f"-m {MODULES[name]}" in _cmdline(pid)

    def pause(self, name: str) -> None:
        pid = self.children[name]
        assert self._ours(pid, name), f"the {name} child {pid} is gone:\n{self.output()}"
        self.stopped.add(pid)
        os.kill(pid, signal.SIGSTOP)

    def resume_all(self) -> None:
        for name, pid in self.children.items():
            if pid in self.stopped:
                if self._ours(pid, name):
                    os.kill(pid, signal.SIGCONT)
                self.stopped.discard(pid)

    def wait(self, timeout: float = RUN_WAIT_S) -> int:
        self.resume_all()
        try:
            self.returncode = self.proc.wait(timeout=timeout)
        finally:
            self.wall_s = time.monotonic() - self.t0
        return self.returncode

    def cleanup(self) -> None:
        """Whatever happened: no child left stopped, the `gcs run` process finished (it
        stops its own children)."""
        self.resume_all()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.wall_s == 0.0:
            self.wall_s = time.monotonic() - self.t0

    def metrics(self) -> dict:
        path = self.out / "metrics.json"
        assert path.exists(), f"no metrics.json (exit {self.returncode}):\n{self.output()}"
        return json.loads(path.read_text())


def _start(out: Path, *extra: str) -> Run:
    out.parent.mkdir(parents=True, exist_ok=True)
    with (out.parent / f"{out.name}.stdout").open("wb") as so, \
            (out.parent / f"{out.name}.stderr").open("wb") as se:
        proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "run", str(CASE1), "--out",
                                 str(out), *extra], cwd=ROOT, stdout=so, stderr=se,
                                stdin=subprocess.DEVNULL)
    return Run(out, proc, time.monotonic())


def _wait_until(run: Run, what: str, predicate, timeout: float = RUN_WAIT_S) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        if run.proc.poll() is not None:
            raise AssertionError(f"gcs run ended (exit {run.proc.returncode}, sim time "
                                 f"{_sim_time_s(run.out)}) before {what}:\n{run.output()}")
        time.sleep(0.02)
    raise AssertionError(f"not {what} within {timeout:.0f} s (sim time "
                         f"{_sim_time_s(run.out)}):\n{run.output()}")


def _events(m: dict) -> str:
    return "\n".join(f"  {e.get('t_s', 0.0):9.3f} s  [{e.get('kind')}] {e.get('text')}"
                     for e in m.get("events", []))


def _summary(m: dict) -> str:
    return (f"status={m.get('status')!r} reason={m.get('status_reason')!r} "
            f"failsafe={m.get('failsafe')!r} sim_time_s={m.get('sim_time_s')} "
            f"error={m.get('error')!r}\nevents:\n{_events(m)}")


def _first(log: tuple[tuple[str, ...], np.ndarray], end_s: float
           ) -> tuple[tuple[str, ...], np.ndarray]:
    """The records of a log up to `end_s` of simulated time (what a shorter run writes)."""
    columns, rows = log
    return columns, rows[rows[:, 0] <= end_s * 1e6 + 0.5]


def _differences(name: str, ref: tuple[tuple[str, ...], np.ndarray],
                 got: tuple[tuple[str, ...], np.ndarray], skip: tuple[str, ...] = ()) -> str:
    """'' when the logs are equal sample for sample (columns in `skip` aside), else where
    they first differ: the first differing row and, per column, the time it first differs."""
    (rc, r), (gc, g) = ref, got
    if rc != gc:
        return f"{name}: columns differ: {rc} != {gc}"
    keep = [i for i, c in enumerate(rc) if c not in skip]
    r, g = r[:, keep], g[:, keep]
    cols = [rc[i] for i in keep]
    lines = []
    if r.shape != g.shape:
        lines.append(f"{name}: {len(g)} rows, the quiet run has {len(r)} (last time "
                     f"{g[-1, 0] * 1e-6 if len(g) else None} s vs "
                     f"{r[-1, 0] * 1e-6 if len(r) else None} s)")
    n = min(len(r), len(g))
    a, b = r[:n], g[:n]
    differ = ~((a == b) | (np.isnan(a) & np.isnan(b)))
    if differ.any():
        rows = np.flatnonzero(differ.any(axis=1))
        i = int(rows[0])
        lines.append(f"{name}: {len(rows)} of {n} rows differ, the first is row {i} "
                     f"(time_us {a[i, 0]:.0f} quiet, {b[i, 0]:.0f} starved)")
        for j in np.flatnonzero(differ[i]):
            lines.append(f"    {cols[j]}: quiet {a[i, j]!r}, starved {b[i, j]!r}")
        for j, c in enumerate(cols):
            col_rows = np.flatnonzero(differ[:, j])
            if len(col_rows):
                k = int(col_rows[0])
                lines.append(f"    column {c} differs from t = {a[k, 0] * 1e-6:.6f} s "
                             f"(row {k}) in {len(col_rows)} rows")
    return "\n".join(lines)


def _hog_cpu() -> set[int]:
    """The one CPU the hogs and the starved run share: the rest of the machine stays free
    for the suite's other tests (real-time ones there would be starved too, and fail)."""
    return {max(os.sched_getaffinity(0))}


def _hog(n: int = 2) -> list[subprocess.Popen]:
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                             stdin=subprocess.DEVNULL) for _ in range(n)]
    for h in hogs:
        os.sched_setaffinity(h.pid, _hog_cpu())
    return hogs


def _stat(pid: int) -> list[str]:
    """/proc/PID/stat's fields after the command name: the state (R, S, T, ...) first."""
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def _state(pid: int) -> str:
    return _stat(pid)[0]


def _stop_hogs(hogs: list[subprocess.Popen]) -> None:
    for h in hogs:
        if h.poll() is None:
            h.kill()
    for h in hogs:
        h.wait()


# ---------------------------------------------------------------------------- lockstep


@dataclass
class Reference:
    out: Path
    wall_s: float
    truth: tuple[tuple[str, ...], np.ndarray]
    onboard: tuple[tuple[str, ...], np.ndarray]


@pytest.fixture(scope="module")
def quiet(tmp_path_factory) -> Iterator[Reference]:
    """Case I, lockstep, DURATION_S, on a machine left alone."""
    out = tmp_path_factory.mktemp("clock") / "quiet"
    run = _start(out, "--duration", f"{DURATION_S:g}")
    try:
        code = run.wait()
    finally:
        run.cleanup()
    print(f"\nquiet lockstep run: exit {code}, {run.wall_s:.1f} s of wall time")
    m = run.metrics()
    assert code == 0 and m["status"] == "completed", _summary(m) + "\n" + run.output()
    assert m["sim_time_s"] == pytest.approx(DURATION_S)
    yield Reference(out, run.wall_s, read_topic(out / "truth.ulg", "dq_truth"),
                    read_topic(out / "onboard.ulg", "dq_onboard"))


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("starvation", ["sitl-paused", "fcu-paused", "cpu-hog"])
def test_lockstep_run_is_unchanged_by_starvation(quiet, tmp_path, starvation):
    """Given the quiet lockstep run of Case I (26 s), when the same run is starved (the sitl
    or the fcu child stopped with SIGSTOP for 3 s at about 22 s of simulated time, or its
    core kept busy by two spinning processes for the whole run, 6 s), then it still
    completes (exit 0, status completed) and its truth and onboard logs equal the quiet
    run's (up to its end) sample for sample (all columns but the onboard log's wall-clock
    step_us)."""
    out = tmp_path / starvation
    duration_s = HOG_DURATION_S if starvation == "cpu-hog" else DURATION_S
    hogs: list[subprocess.Popen] = []
    paused_at = resumed_at = None
    try:
        if starvation == "cpu-hog":
            hogs = _hog(2)
            until(lambda: all(cpu_s(h.pid) >= 0.2 for h in hogs),
                  "the hogs spinning before the run starts", 30.0, poll_s=0.05)
        run = _start(out, "--duration", f"{duration_s:g}")
        if hogs:  # before it starts its sitl and fcu (they inherit the CPU)
            os.sched_setaffinity(run.proc.pid, _hog_cpu())
        try:
            if starvation != "cpu-hog":
                name = starvation.split("-")[0]
                run.find_children()
                _wait_until(run, f"{PAUSE_AT_S:g} s of simulated time",
                            lambda: (_sim_time_s(out) or 0.0) >= PAUSE_AT_S)
                run.pause(name)
                paused = time.monotonic()
                # The simulator writes its truth log in batches and when it goes idle: the
                # log's tail is the simulated time once the stop has taken hold (a stopped
                # simulator writes nothing; one waiting for the stopped FCU sleeps in select
                # after its last write).
                sitl, asleep = run.children["sitl"], [0]

                def held() -> bool:
                    asleep[0] = asleep[0] + 1 if _state(sitl) in "ST" else 0
                    return time.monotonic() >= paused + SETTLE_S and asleep[0] >= 3

                until(held, f"the stop of the {name} child taken hold", 30.0, poll_s=0.02)
                paused_at = _sim_time_s(out)
                time.sleep(max(0.0, paused + PAUSE_S - time.monotonic()))  # the pause itself
                resumed_at = _sim_time_s(out)
                run.resume_all()
            code = run.wait()
        finally:
            run.cleanup()
    finally:
        _stop_hogs(hogs)
    m = run.metrics()
    print(f"\n{starvation} lockstep run: exit {code}, {run.wall_s:.1f} s of wall time "
          f"(quiet: {quiet.wall_s:.1f} s)"
          + (f", paused at {paused_at:.3f} s, {resumed_at:.3f} s when resumed"
             if paused_at is not None else "") + f"\n{_summary(m)}")
    if paused_at is not None:
        # the pause happened in the flight and stopped the world with it
        assert paused_at < DURATION_S, f"paused after the end ({paused_at} s)"
        assert resumed_at - paused_at < 0.05, (
            f"simulated time ran on while the {starvation} child was stopped: "
            f"{paused_at:.3f} s -> {resumed_at:.3f} s")
    assert code == 0, _summary(m) + "\n" + run.output()
    assert m["status"] == "completed", _summary(m)
    assert m["sim_time_s"] == pytest.approx(duration_s), _summary(m)

    truth = read_topic(out / "truth.ulg", "dq_truth")
    onboard = read_topic(out / "onboard.ulg", "dq_onboard")
    ref_truth, ref_onboard = _first(quiet.truth, duration_s), _first(quiet.onboard, duration_s)
    diff = "\n".join(d for d in (_differences("truth.ulg", ref_truth, truth),
                                 _differences("onboard.ulg", ref_onboard, onboard,
                                              skip=("step_us",))) if d)
    assert not diff, f"the {starvation} run differs from the quiet run:\n{diff}"
    # and the same through np.array_equal, column by column
    for (qc, q), (sc, s) in ((ref_truth, truth), (ref_onboard, onboard)):
        for j, c in enumerate(qc):
            if c != "step_us":
                assert np.array_equal(q[:, j], s[:, sc.index(c)], equal_nan=True), c


# ---------------------------------------------------------------------------- real time


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_realtime_simulator_pause_in_the_air_is_a_state_input_loss(tmp_path):
    """Given a real-time run of Case I (14 s), when the sitl child is stopped with SIGSTOP
    for 2 s once the vehicle is above 2 m, then the FCU loses its state input in the air:
    `gcs run` exits 1, and metrics.json says failsafe or crashed, with an event on the state
    input loss (and, for crashed, one on the disarm in the air)."""
    out = tmp_path / "realtime"
    run = _start(out, "--realtime", "--duration", f"{RT_DURATION_S:g}")
    height = None
    try:
        run.find_children()
        _wait_until(run, f"the vehicle above {RT_PAUSE_ABOVE_M:g} m",
                    lambda: (_height_m(out) or 0.0) > RT_PAUSE_ABOVE_M)
        height, at = _height_m(out), _sim_time_s(out)
        run.pause("sitl")
        time.sleep(RT_PAUSE_S)  # deliberate: the state input lost for RT_PAUSE_S in the air
        run.resume_all()
        code = run.wait()
    finally:
        run.cleanup()
    m = run.metrics()
    print(f"\nreal-time run: exit {code}, {run.wall_s:.1f} s of wall time, sitl paused "
          f"at {at:.3f} s, {height:.2f} m up\n{_summary(m)}")
    texts = [str(e.get("text", "")) for e in m.get("events", [])]
    assert code == 1, _summary(m) + "\n" + run.output()
    assert m["status"] in ("failsafe", "crashed"), _summary(m)
    assert any("state input lost" in t for t in texts), _summary(m)
    if m["status"] == "crashed":
        assert any("in the air" in t and e.get("kind") == "crash"
                   for t, e in zip(texts, m["events"], strict=True)), _summary(m)
