"""`gcs run` through processes: start `sitl` and `fcu` on free ports, upload the scenario's
mission over the mission protocol, arm, start, record `flight.tlog`, wait for the end, stop
the children, and write metrics.json from the truth and onboard logs
(docs/architecture.md#a-run-folder).
Every wait is on progress, with a ceiling that names what it waited for (`gcs.run.run_waits`).
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from common.config.scenario import Scenario
from common.links import free_port
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.logs.ulog import ULogError, read_topic
from common.outcome import Event
from common.process.parent import child_env
from common.wire.mavlink import MAV, read_signing_key
from gcs.report.metrics import add_link_timing, build_metrics, onboard_on_truth_clock
from gcs.report.run_metrics import FleetMetrics, RunMetrics
from gcs.run.run_waits import (
    RUN_SILENCE_S,
    STOP_S,
    Progress,
    Report,
    RunError,
    RunTimeout,
    wait_started,
    wait_state,
    watch,
)
from gcs.run.runio import ONBOARD_LOG, ONBOARD_TOPIC, TRUTH_LOG, TRUTH_TOPIC, write_metrics
from gcs.run.scenario_mission import scenario_mission, scenario_params
from gcs.vehicle_link.mission_client import MissionError, upload_detailed
from gcs.vehicle_link.params import param_set
from gcs.vehicle_link.session import GcsError, Session

M = MAV
RTT_PROBES = 2000  # TIMESYNC round trips the FCU times with the simulator before the flight


__all__ = ["ChildDied", "Children", "Progress", "Report", "RunError", "RunTimeout",
           "VehiclePlan", "run_processes", "start_router_if_needed"]
ALIGN_S = 120.0  # arming asked again while TEMPORARILY_REJECTED (aligning), at most


class ChildDied(RunError):
    """A child process of the run ended before the run did."""


@dataclass
class Children:
    """The sitl and fcu child processes of one run, each logging to its own file."""

    out: Path
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    def start(self, name: str, argv: list[str]) -> None:
        log = (self.out / f"{name}.log").open("wb")
        # The child asks for SIGTERM when we die (common.process.parent): no preexec_fn, which is
        # unsafe while our threads run.
        self.procs[name] = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL, env=child_env())
        log.close()

    def tails(self) -> str:
        return "\n".join(f"--- {name}.log\n" + (self.out / f"{name}.log").read_text(
            errors="replace")[-600:] for name in self.procs)

    def check(self) -> None:
        for name, proc in self.procs.items():
            code = proc.poll()
            if code is not None:
                tail = (self.out / f"{name}.log").read_text(errors="replace")[-800:]
                raise ChildDied(f"{name} exited with status {code}:\n{tail}")

    def stop(self, timeout: float = STOP_S) -> None:
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
class VehiclePlan:
    """One vehicle of a run: its system id, folder, scenario and link URLs."""

    sysid: int
    out: Path
    scenario: Scenario
    sim_server: str  # the plant's simulator link
    sim_client: str  # the FCU's simulator link
    fcu_gcs: str  # the FCU's GCS link
    gcs: str  # the ground station's connection


def _shifted(scenario: Scenario, dx: float) -> Scenario:
    """The scenario moved dx metres east (fleets with spacing)."""
    if dx == 0.0:
        return scenario
    x, y, z = scenario.initial_position_enu_m
    tx, ty, tz = scenario.trajectory.position_enu_m
    return dataclasses.replace(
        scenario, initial_position_enu_m=(x + dx, y, z),
        trajectory=dataclasses.replace(scenario.trajectory, position_enu_m=(tx + dx, ty, tz)))


def _plans(scenario: Scenario, out: Path, fleet: int, spacing_m: float, transport: str,
           zenoh_url: str, sim_route: Callable[[int], int] | None) -> list[VehiclePlan]:
    plans = []
    for n in range(1, fleet + 1):
        folder = out if fleet == 1 else out / f"vehicle{n}"
        sc = _shifted(scenario, (n - 1) * spacing_m)
        if transport == "zenoh":
            plans.append(VehiclePlan(n, folder, sc, zenoh_url, zenoh_url, zenoh_url, zenoh_url))
            continue
        server, client = ("udpin", "udpout") if transport == "udp" else ("tcpin", "tcp")
        sim_port = free_port() if transport == "udp" else free_port(socket.SOCK_STREAM)
        fcu_port = sim_route(sim_port) if sim_route else sim_port
        gcs_port = free_port()
        plans.append(VehiclePlan(n, folder, sc, f"{server}:127.0.0.1:{sim_port}",
                                 f"{client}:127.0.0.1:{fcu_port}",
                                 f"udpout:127.0.0.1:{gcs_port}", f"udpin:127.0.0.1:{gcs_port}"))
    return plans


class _Flight:
    """The children and the ground-station side of one vehicle's run."""

    def __init__(self, plan: VehiclePlan, *, realtime: bool, wall_timeout_s: float | None,
                 report: Report | None = None, signing_key_file: str | None = None) -> None:
        self.plan = plan
        self.signing_key_file = signing_key_file
        self.realtime = realtime
        self.wall_timeout_s = wall_timeout_s
        self.report = report
        self.children = Children(plan.out)
        self.progress = Progress()
        self.session: Session | None = None
        self.error: BaseException | None = None
        self.interrupted = False
        self.wall0 = self.wall1 = time.monotonic()

    def start(self) -> None:
        p, sc, py = self.plan, self.plan.scenario, sys.executable
        p.out.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(sc.source, p.out / "scenario.toml")
        for name in (TRUTH_LOG, ONBOARD_LOG, "fcu_stats.json", "sitl_stats.json",
                     "flight.tlog"):
            (p.out / name).unlink(missing_ok=True)
        gains = sc.files["gains_pid" if sc.controller == "pid" else "gains_pd"]
        x, y, z = sc.initial_position_enu_m
        sitl = [py, "-m", "sitl.node", sc.source, "--link", p.sim_server, "--sysid",
                str(p.sysid), "--truth-log", str(p.out / TRUTH_LOG), "--control-rate",
                str(sc.control_rate_hz), "--position", f"{x!r},{y!r},{z!r}",
                "--stats", str(p.out / "sitl_stats.json")]
        fcu = [py, "-m", "fcu.edge.node", "--vehicle", sc.files["vehicle"], "--gains", gains,
               "--sim", p.sim_client, "--gcs", p.fcu_gcs, "--sysid", str(p.sysid),
               "--rate", str(sc.control_rate_hz), "--onboard-log", str(p.out / ONBOARD_LOG),
               "--stats", str(p.out / "fcu_stats.json")]
        if p.sim_client.startswith(("udpout:", "tcp:")):  # sockets: time the round trip
            fcu += ["--rtt-probes", str(RTT_PROBES)]
        if not self.realtime:  # lockstep: the simulator itself stops at the end, exactly
            sitl += ["--end-time", repr(sc.duration_s)]
        else:
            sitl.append("--realtime")
            fcu.append("--realtime")
        if sc.ideal_actuators:
            sitl.append("--ideal-actuators")
        if sc.sensors is not None:
            sitl += ["--sensors", sc.sensors.source]
        sitl += ["--seed", str(sc.seed)]
        key = None
        if self.signing_key_file:
            key = read_signing_key(self.signing_key_file)
            fcu += ["--signing-key", self.signing_key_file]
        self.session = Session(p.gcs, tlog=p.out / "flight.tlog", vehicle=p.sysid,
                               signing_key=key)
        self.children.start("sitl", sitl)
        self.children.start("fcu", fcu)

    def fly(self) -> None:
        """Connect, upload, arm, start, follow to the end (run in a thread per vehicle)."""
        try:
            self._fly()
        except BaseException as exc:  # reported by the caller with the vehicle's id
            self.error = exc
            if isinstance(exc, GcsError | MissionError | RunError) and \
                    not isinstance(exc, ChildDied):
                try:  # a child that died explains what went wrong after it: say that
                    self.children.check()
                except ChildDied as died:
                    self.error = RunError(f"{died}\n(then: {exc})")

    def _fly(self) -> None:
        s, sc = self.session, self.plan.scenario
        assert s is not None
        wait_started(s, self.children, self.plan.sysid)
        # Parameters first: EKF_EN decides what the FCU flies on (its state comes after).
        for name, value in scenario_params(sc).items():
            now, texts = param_set(s, name, value)
            if now != struct.unpack("<f", struct.pack("<f", value))[0]:  # REAL32
                raise RunError(f"the vehicle refused {name} = {value:g} (kept {now:g}): "
                               + "; ".join(texts))
        try:
            # the FCU reports attitude once it has a state (or an aligned estimate)
            if wait_state(s, self.children) is None:
                self.children.check()
                why = ("its estimator did not align (it needs the vehicle still and a pose; "
                       "EKF_GYR_NOISE and EKF_ACC_NOISE must cover the IMU's noise)"
                       if sc.uses_sensors else "is the simulator running?")
                raise GcsError(f"the vehicle reports no state: {why}\n"
                               + self.children.tails())
        except GcsError:
            self.children.check()
            raise
        items = scenario_mission(sc)
        # our own local child: silence while it lives is its (inline) mission check
        answer = upload_detailed(s.conn, s.target_system, s.target_component, items,
                                 send=s.send, silence_s=RUN_SILENCE_S)
        if not answer.accepted:
            raise RunError(f"mission upload refused: {answer.describe()}")
        # The flight's clock starts at MISSION_START: 0 in lockstep (simulated time stands
        # still until then), the FCU's monotonic time in real time.
        # With a sensor profile the flight starts when the estimator has aligned (lockstep:
        # simulated time stands still from then until MISSION_START).
        start_ms = 0
        aligned_by = time.monotonic() + ALIGN_S
        for command, params, what in (
                (M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), "arming"),
                (M.MAV_CMD_MISSION_START, (0.0, float(len(items) - 1)), "mission start")):
            ack = s.command(command, *params)
            while ack == M.MAV_RESULT_TEMPORARILY_REJECTED and time.monotonic() < aligned_by:
                time.sleep(0.2)  # the estimator is aligning: ask again
                ack = s.command(command, *params)
            if ack == M.MAV_RESULT_TEMPORARILY_REJECTED:
                raise RunError(f"{what} refused: {s.describe(ack)} (still, after the "
                               f"{ALIGN_S:g} s ceiling)")
            if ack != M.MAV_RESULT_ACCEPTED:
                raise RunError(f"{what} refused: {s.describe(ack)}")
            if what == "arming" and (self.realtime or sc.uses_sensors):
                att = wait_state(s, self.children)
                start_ms = att.time_boot_ms if att is not None else 0
        self.wall0 = time.monotonic()
        self.items = len(items)
        watch(s, self.children, self.progress, start_ms * 1e-3 + sc.duration_s, len(items),
              self.wall_timeout_s, self.report)
        self.wall1 = time.monotonic()

    def stop(self) -> None:
        if self.wall1 <= self.wall0:  # stopped before the end: the flight lasted until now
            self.wall1 = time.monotonic()
        self.children.stop()
        if self.session is not None:
            self.session.close()

    def metrics(self, transport: str) -> RunMetrics:
        """metrics.json of this vehicle's run, written last: also for a run that could not
        finish (status timeout or aborted, figures over what was flown)."""
        out, sc = self.plan.out, self.plan.scenario
        stats_path = out / "fcu_stats.json"
        stats = json.loads(stats_path.read_text()) if stats_path.exists() else {}
        stopped = ""
        # Read once: a flight thread that outlived the stop may still set self.error.
        error = RunError("interrupted (Ctrl-C)") if self.interrupted else self.error
        if error is not None:
            stopped = "timeout" if isinstance(error, RunTimeout) else "aborted"
        elif not stats:
            stopped = "aborted"  # the FCU did not stop cleanly: its events are unknown
        truth_cols, truth = _read_or_empty(out / TRUTH_LOG, TRUTH_TOPIC, TRUTH_COLUMNS)
        onboard_cols, onboard = onboard_on_truth_clock(
            *_read_or_empty(out / ONBOARD_LOG, ONBOARD_TOPIC, ONBOARD_COLUMNS))
        events = [Event(round(e["t_s"] * 1e6), int(e["severity"]), str(e["text"]),
                        str(e.get("kind", "info"))) for e in stats.get("events", [])]
        metrics = build_metrics(sc, truth_cols, truth, onboard_cols, onboard, events=events,
                                wall_time_s=max(self.wall1 - self.wall0, 0.0),
                                transport=transport, lockstep=not self.realtime,
                                deadline_misses=int(stats.get("deadline_misses", 0)),
                                mission_completed=self.progress.mission_completed
                                or bool(stats.get("mission_completed")), stopped=stopped,
                                reached_end=(not stopped) if self.realtime else None,
                                flight_start_us=int(stats.get("flight_start_us") or 0))
        if error is not None:
            metrics["error"] = str(error)
        metrics["system_id"] = self.plan.sysid
        metrics["fcu_params"] = scenario_params(sc)
        metrics["start_position_enu_m"] = list(sc.initial_position_enu_m)
        metrics["fcu"] = {k: v for k, v in stats.items() if k != "events"}
        sitl_path = out / "sitl_stats.json"
        sitl_stats = json.loads(sitl_path.read_text()) if sitl_path.exists() else {}
        if sitl_stats:
            metrics["sitl"] = sitl_stats
        add_link_timing(metrics, stats, sitl_stats, transport, lockstep=not self.realtime)
        # Both processes' kernels, compiled or loaded from the cache before their loops ran.
        if "compile_time_s" in stats or "compile_time_s" in sitl_stats:
            metrics["compile_time_s"] = float(stats.get("compile_time_s", 0.0)) + \
                float(sitl_stats.get("compile_time_s", 0.0))
        metrics["overrides"] = {"controller": sc.controller,
                                "ideal_actuators": sc.ideal_actuators,
                                "duration_s": sc.duration_s}
        write_metrics(out, metrics)
        return metrics


def _read_or_empty(path: Path, topic: str, columns: tuple[str, ...]
                   ) -> tuple[tuple[str, ...], Any]:
    """A log's float64 topic; none when the process never wrote the log (it did not start).
    """
    try:
        return read_topic(path, topic)
    except ULogError:
        return columns, np.zeros((0, len(columns)))


def run_processes(scenario: Scenario, out: Path, *, realtime: bool = False,
                  wall_timeout_s: float | None = None, report: Report | None = None,
                  sim_route: Callable[[int], int] | None = None,
                  transport: str = "udp", fleet: int = 1, spacing_m: float = 0.0,
                  zenoh_url: str = "zenoh:mavlink",
                  signing_key_file: str | None = None) -> RunMetrics | FleetMetrics:
    """Fly `scenario` through sitl + fcu processes; returns the metrics written to out.

    `transport` is the links' ("udp", "tcp" for the simulator link with UDP to the GCS, or
    "zenoh" for both, through the routers of `zenoh_url`, started here when none runs).
    `sim_route` maps the simulator's port to the port the FCU sends to (a test proxy). A
    fleet of N flies N vehicles (system ids 1..N, `spacing_m` apart along east) and returns
    the content of DIR/fleet.json, each vehicle's metrics in DIR/vehicle<N>/.
    """
    if transport not in ("udp", "tcp", "zenoh"):
        raise RunError(f"unknown transport {transport!r} (udp, tcp or zenoh)")
    if fleet < 1:
        raise RunError(f"a fleet needs at least one vehicle, got {fleet}")
    out.mkdir(parents=True, exist_ok=True)
    if wall_timeout_s is None and realtime:  # real time: the flight's own length, and more
        wall_timeout_s = 120.0 + 2.0 * scenario.duration_s * fleet
    # lockstep: no wall-clock ceiling; a run whose clock stands still ends (STALL_S)
    router = start_router_if_needed(zenoh_url, out) if transport == "zenoh" else None
    flights = [_Flight(plan, realtime=realtime, wall_timeout_s=wall_timeout_s,
                       report=report if fleet == 1 else None, signing_key_file=signing_key_file)
               for plan in _plans(scenario, out, fleet, spacing_m, transport, zenoh_url,
                                  sim_route)]
    _fly_all(flights, router)
    for f in flights:
        if f.error is not None and not isinstance(f.error, GcsError | MissionError | RunError):
            raise f.error  # a bug, not something that happened to the vehicle
    results = [f.metrics(transport) for f in flights]
    if fleet == 1:
        return results[0]
    summary = _fleet_summary(results, fleet, spacing_m, transport, scenario.name)
    (out / "fleet.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def _fly_all(flights: list[_Flight], router: Children | None) -> None:
    """Start every flight's processes and fly them side by side (a thread each); then stop
    them all and the router, however it ended (Ctrl-C: the flights are aborted)."""
    threads: list[threading.Thread] = []
    try:
        for f in flights:
            f.start()
        threads = [threading.Thread(target=f.fly, name=f"vehicle{f.plan.sysid}", daemon=True)
                   for f in flights]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    except KeyboardInterrupt:  # Ctrl-C: the run is aborted, and its folder says so
        for f in flights:
            f.interrupted = True
    finally:
        for f in flights:
            f.stop()
        for t in threads:
            t.join(timeout=10.0)
        if router is not None:
            router.stop()


def _fleet_summary(results: list[RunMetrics], fleet: int, spacing_m: float,
                   transport: str, scenario: str) -> FleetMetrics:
    """fleet.json: the fleet's settings, whether every vehicle completed, each one's
    metrics by system id."""
    return {"fleet": fleet, "spacing_m": spacing_m, "transport": transport,
            "scenario": scenario,
            "all_completed": all(m["status"] == "completed" for m in results),
            "vehicles": {str(m["system_id"]): m for m in results}}


def one_vehicle(metrics: RunMetrics | FleetMetrics) -> RunMetrics:
    """The metrics of a run of one vehicle (`run_processes` with `fleet=1`)."""
    if "vehicles" in metrics:
        raise ValueError("a fleet's metrics where one vehicle was flown")
    return metrics


def fleet_of(metrics: RunMetrics | FleetMetrics) -> FleetMetrics:
    """The metrics of a fleet's run (`run_processes` with `fleet` > 1)."""
    if "vehicles" not in metrics:
        raise ValueError("one vehicle's metrics where a fleet was flown")
    return cast(FleetMetrics, metrics)


def start_router_if_needed(zenoh_url: str, out: Path) -> Children | None:
    """Start `gcs router` on the first endpoint of `zenoh_url` when nothing listens there."""
    from common.links.url import parse_zenoh
    from common.links.zenoh_link import router_running

    _, endpoints = parse_zenoh(zenoh_url.partition(":")[2])
    if router_running(endpoints[0]):
        return None
    children = Children(out)
    children.start("router", [sys.executable, "-m", "gcs.cli", "router", "--listen",
                              endpoints[0]])
    deadline = time.monotonic() + 10.0
    while not router_running(endpoints[0]):
        children.check()
        if time.monotonic() > deadline:
            children.stop()
            raise RunError(f"no Zenoh router came up at {endpoints[0]}")
        time.sleep(0.05)
    return children
