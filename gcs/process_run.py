"""`gcs run` through processes: start `sitl` and `fcu` on free ports, upload the scenario's
mission over the mission protocol, arm, start, record `flight.tlog`, wait for the end, stop
the children, and write metrics.json from the truth and onboard logs (DESIGN.md 5-6).
"""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from common.binlog import read_log
from common.config import Scenario
from common.links import free_port
from common.mavlink import MAV
from gcs.inprocess import build_metrics
from gcs.mission_client import MissionError, upload
from gcs.runio import ONBOARD_LOG, TRUTH_LOG, write_metrics
from gcs.scenario_mission import scenario_mission
from gcs.session import GcsError, Session

M = MAV
STALL_S = 60.0


class RunError(RuntimeError):
    """A run that could not be carried out (a child died, the vehicle refused, a timeout)."""


@dataclass
class Children:
    """The sitl and fcu child processes of one run, each logging to its own file."""

    out: Path
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)

    def start(self, name: str, argv: list[str]) -> None:
        log = (self.out / f"{name}.log").open("wb")
        self.procs[name] = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL)
        log.close()

    def tails(self) -> str:
        return "\n".join(f"--- {name}.log\n" + (self.out / f"{name}.log").read_text(
            errors="replace")[-600:] for name in self.procs)

    def check(self) -> None:
        for name, proc in self.procs.items():
            code = proc.poll()
            if code is not None:
                tail = (self.out / f"{name}.log").read_text(errors="replace")[-800:]
                raise RunError(f"{name} exited with status {code}:\n{tail}")

    def stop(self, timeout: float = 10.0) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@dataclass
class Progress:
    sim_time_s: float = 0.0
    mission_completed: bool = False
    diverged: bool = False
    messages: list[str] = field(default_factory=list)


def _watch(session: Session, children: Children, progress: Progress, end_s: float,
           total: int, divergence_m: float, wall_timeout_s: float,
           report=None) -> None:
    """Follow the flight until the vehicle's clock reaches end_s, or divergence."""
    end_ms = round(end_s * 1000)
    deadline = time.monotonic() + wall_timeout_s
    last_check = 0.0
    reached_end = False
    last_ms, last_progress = -1, time.monotonic()
    while time.monotonic() < deadline:
        msg = session.recv(["ATTITUDE_QUATERNION", "MISSION_CURRENT", "STATUSTEXT",
                            "NAMED_VALUE_FLOAT", "MISSION_ITEM_REACHED"], timeout=0.2)
        now = time.monotonic()
        if now - last_check > 0.5:
            children.check()
            last_check = now
            if report is not None:
                report(progress)
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "ATTITUDE_QUATERNION":
            progress.sim_time_s = msg.time_boot_ms * 1e-3
            if msg.time_boot_ms != last_ms:
                last_ms, last_progress = msg.time_boot_ms, now
            elif now - last_progress > STALL_S:
                raise RunError(f"the vehicle's clock stopped at {last_ms / 1000:.3f} s for "
                               f"{STALL_S:.0f} s of wall time")
            if msg.time_boot_ms >= end_ms and not reached_end:
                reached_end = True
                deadline = now + 0.3  # let the last mission messages arrive
        elif kind == "MISSION_CURRENT":
            if msg.mission_state == M.MISSION_STATE_COMPLETE and msg.total == total:
                progress.mission_completed = True
        elif kind == "MISSION_ITEM_REACHED" and msg.seq == total - 1:
            progress.mission_completed = True
        elif kind == "STATUSTEXT":
            progress.messages.append(msg.text)
        elif kind == "NAMED_VALUE_FLOAT" and msg.name == "ERR_POS" and \
                msg.value > divergence_m:
            progress.diverged = True
            return
    if reached_end:
        return
    raise RunError(f"the run did not reach t = {end_s} s within {wall_timeout_s:.0f} s "
                   f"of wall time (reached {progress.sim_time_s:.2f} s)")


def run_processes(scenario: Scenario, out: Path, *, realtime: bool = False,
                  wall_timeout_s: float | None = None, report=None,
                  sim_route: Callable[[int], int] | None = None,
                  transport: str = "udp") -> dict[str, Any]:
    """Fly `scenario` through sitl + fcu processes; returns the metrics written to out.

    `sim_route` maps the simulator's port to the port the FCU sends to (a test proxy);
    `transport` is the simulator link's, "udp" or "tcp".
    """
    if transport not in ("udp", "tcp"):
        raise RunError(f"unknown simulator transport {transport!r} (udp or tcp)")
    server, client = ("udpin", "udpout") if transport == "udp" else ("tcpin", "tcp")
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(scenario.source, out / "scenario.toml")
    for name in (TRUTH_LOG, ONBOARD_LOG, "fcu_stats.json", "flight.tlog"):
        (out / name).unlink(missing_ok=True)
    sim_port = free_port() if transport == "udp" else free_port(socket.SOCK_STREAM)
    gcs_port = free_port()
    end_s = scenario.duration_s
    gains = scenario.files["gains_pid" if scenario.controller == "pid" else "gains_pd"]
    py = sys.executable
    sitl_cmd = [py, "-m", "sitl.node", scenario.source, "--link",
                f"{server}:127.0.0.1:{sim_port}", "--truth-log", str(out / TRUTH_LOG),
                "--control-rate", str(scenario.control_rate_hz)]
    if not realtime:  # lockstep: the simulator itself stops at the end, to the microsecond
        sitl_cmd += ["--end-time", repr(end_s)]
    fcu_sim_port = sim_route(sim_port) if sim_route else sim_port
    fcu_cmd = [py, "-m", "fcu.node", "--vehicle", scenario.files["vehicle"], "--gains", gains,
               "--sim", f"{client}:127.0.0.1:{fcu_sim_port}", "--gcs",
               f"udpout:127.0.0.1:{gcs_port}", "--rate", str(scenario.control_rate_hz),
               "--onboard-log", str(out / ONBOARD_LOG), "--stats", str(out / "fcu_stats.json")]
    if realtime:
        sitl_cmd.append("--realtime")
        fcu_cmd.append("--realtime")
    if scenario.ideal_actuators:
        sitl_cmd.append("--ideal-actuators")
    if wall_timeout_s is None:  # a generous cap; a stalled run is caught sooner (STALL_S)
        wall_timeout_s = 120.0 + (2.0 if realtime else 20.0) * end_s
    items = scenario_mission(scenario)
    children = Children(out)
    session = None
    progress = Progress()
    wall0 = time.monotonic()
    try:
        session = Session(f"udpin:127.0.0.1:{gcs_port}", tlog=out / "flight.tlog")
        children.start("sitl", sitl_cmd)
        children.start("fcu", fcu_cmd)
        try:
            session.wait_vehicle(timeout=15.0)
            # the FCU reports attitude once it has a state from the simulator
            if session.recv(["ATTITUDE_QUATERNION"], timeout=15.0) is None:
                children.check()
                raise GcsError("the vehicle reports no state: is the simulator running?\n"
                               + children.tails())
        except GcsError:
            children.check()
            raise
        result = upload(session.conn, session.target_system, session.target_component, items,
                        send=session.send)
        if result != M.MAV_MISSION_ACCEPTED:
            raise RunError(f"mission upload refused: MAV_MISSION_RESULT {result}")
        # The flight's clock starts at MISSION_START: 0 in lockstep (simulated time stands
        # still until then), the FCU's monotonic time in real time.
        start_ms = 0
        if realtime:
            att = session.recv(["ATTITUDE_QUATERNION"], timeout=5.0)
            start_ms = att.time_boot_ms if att is not None else 0
        for command, params, what in (
                (M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), "arming"),
                (M.MAV_CMD_MISSION_START, (0.0, float(len(items) - 1)), "mission start")):
            ack = session.command(command, *params)
            if ack != M.MAV_RESULT_ACCEPTED:
                raise RunError(f"{what} refused: MAV_RESULT {ack}")
        wall0 = time.monotonic()
        _watch(session, children, progress, start_ms * 1e-3 + end_s, len(items),
               scenario.divergence_position_m, wall_timeout_s, report)
    except (GcsError, MissionError) as exc:
        raise RunError(str(exc)) from exc
    finally:
        wall = time.monotonic() - wall0
        children.stop()
        if session is not None:
            session.close()
    stats = json.loads((out / "fcu_stats.json").read_text()) \
        if (out / "fcu_stats.json").exists() else {}
    truth_cols, truth = read_log(out / TRUTH_LOG)
    onboard_cols, onboard = read_log(out / ONBOARD_LOG)
    metrics = build_metrics(scenario, truth_cols, truth, onboard_cols, onboard,
                            status="completed", wall_time_s=wall, transport=transport,
                            lockstep=not realtime,
                            deadline_misses=int(stats.get("deadline_misses", 0)),
                            mission_completed=progress.mission_completed
                            or bool(stats.get("mission_completed")))
    metrics["fcu"] = stats
    metrics["overrides"] = {"controller": scenario.controller,
                            "ideal_actuators": scenario.ideal_actuators,
                            "duration_s": scenario.duration_s}
    write_metrics(out, metrics)
    return metrics
