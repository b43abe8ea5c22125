"""Process-level tests: real `sitl` and `fcu` processes on free loopback ports, each logging
to its own file, with time limits, cleaned up whatever happens."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from common.links import free_port
from gcs.vehicle_link.session import GcsError, Session

from .waits import cpu_s, until_progressing

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"
VEHICLE = ROOT / "config" / "vehicles" / "hexa_tilted.toml"
PID = ROOT / "config" / "gains" / "pid_eq30.toml"


@dataclass
class Stack:
    session: Session
    procs: dict[str, subprocess.Popen]
    sim_port: int
    gcs_port: int
    logs: Path

    def log(self, name: str) -> str:
        return (self.logs / f"{name}.log").read_text(errors="replace")

    def wait_for(self, types: list[str], predicate=lambda m: True, timeout: float = 20.0):
        # a deadline, not a pause: a state that comes comes late on a loaded machine
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.session.recv(types, timeout=0.1)
            if msg is not None and predicate(msg):
                return msg
        return None


def start(name: str, argv: list[str], logs: Path,
          preexec_fn: Callable[[], None] | None = None) -> subprocess.Popen:
    fh = (logs / f"{name}.log").open("wb")
    proc = subprocess.Popen([sys.executable, "-m", *argv], cwd=ROOT, stdout=fh,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            preexec_fn=preexec_fn)
    fh.close()
    return proc


def stop(procs: dict[str, subprocess.Popen]) -> None:
    for proc in procs.values():
        if proc.poll() is None:
            proc.terminate()
    for proc in procs.values():
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


# A lockstep stack driven by a test through MAVLink is paced (`sitl --speed-factor`): the
# station's timers run on the wall clock, and a free-running pair would take both cores
# while the test waits on them. The flight is the same at any pace.
PACE = ("--speed-factor", "4")


def _heard(session: Session, procs: dict[str, subprocess.Popen], kind: str | None) -> bool:
    """Whether the vehicle's HEARTBEAT (`kind` None: the Session then targets it) or a
    message of `kind` came within a second; AssertionError if a process has ended."""
    for name, proc in procs.items():
        assert proc.poll() is None, f"{name} exited with {proc.returncode} while starting"
    if kind is not None:
        return session.recv([kind], timeout=1.0) is not None
    try:
        session.wait_vehicle(timeout=1.0)
    except GcsError:
        return False
    return True


def launch(tmp_path: Path, scenario: str = "case2_impulse", *, realtime: bool = False,
           sitl: bool = True, sim_port: int | None = None, fcu_args: tuple[str, ...] = (),
           sitl_args: tuple[str, ...] = (), fcu_preexec: Callable[[], None] | None = None) -> Stack:
    sim_port = sim_port or free_port()
    gcs_port = free_port()
    procs: dict[str, subprocess.Popen] = {}
    rt = ["--realtime"] if realtime else []
    if not realtime and "--speed-factor" not in sitl_args:
        sitl_args = (*PACE, *sitl_args)
    session = Session(f"udpin:127.0.0.1:{gcs_port}", tlog=tmp_path / "flight.tlog")
    try:
        if sitl:
            procs["sitl"] = start("sitl", ["sitl.node", str(SCENARIOS / f"{scenario}.toml"),
                                           "--link", f"udpin:127.0.0.1:{sim_port}", *rt,
                                           "--truth-log", str(tmp_path / "truth.ulg"),
                                           *sitl_args],
                                  tmp_path)
        procs["fcu"] = start("fcu", ["fcu.edge.node", "--vehicle", str(VEHICLE), "--gains",
        str(PID),
                                     "--sim", f"udpout:127.0.0.1:{sim_port}", "--gcs",
                                     f"udpout:127.0.0.1:{gcs_port}", *rt, *fcu_args,
                                     "--onboard-log", str(tmp_path / "onboard.ulg")],
                             tmp_path, fcu_preexec)
        # waited for while the processes start up (their CPU time grows: a loaded machine
        # starts them slowly), not for a fixed time
        started = lambda: cpu_s(*(p.pid for p in procs.values()))  # noqa: E731
        until_progressing(lambda: _heard(session, procs, None), started,
                          "the FCU's first HEARTBEAT", stall_s=15.0, ceiling_s=180.0,
                          poll_s=0.0)
        if sitl:  # the FCU reports attitude once the simulator's first state has arrived
            until_progressing(lambda: _heard(session, procs, "ATTITUDE_QUATERNION"),
                              started, "the FCU's first ATTITUDE_QUATERNION", stall_s=15.0,
                              ceiling_s=180.0, poll_s=0.0)
    except BaseException:
        session.close()
        stop(procs)
        raise
    return Stack(session, procs, sim_port, gcs_port, tmp_path)


@pytest.fixture
def stack(tmp_path) -> Iterator[Stack]:
    """Lockstep SITL (Case II start: airborne, ground off, no answer until flight) + FCU."""
    s = launch(tmp_path)
    yield s
    s.session.close()
    stop(s.procs)


@pytest.fixture
def rt_stack(tmp_path) -> Iterator[Stack]:
    """Real-time SITL starting on the ground (Case I) + FCU."""
    s = launch(tmp_path, "case1_figure8", realtime=True)
    yield s
    s.session.close()
    stop(s.procs)
