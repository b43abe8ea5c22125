"""A real-time flight to attack (sitl + fcu, the mission flying), its telemetry, and the
sockets that attack one of its ports."""

from __future__ import annotations

import itertools
import json
import math
import random
import re
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchmarks.fuzz.config import PID, ROOT, SCENARIO, VEHICLE
from benchmarks.fuzz.listener import LinkListener
from benchmarks.fuzz.relay import Relay
from common.config.scenario import load_scenario
from common.links import free_port
from common.process.parent import child_env
from common.wire.mavlink import MAV
from gcs.run.scenario_mission import scenario_mission
from gcs.vehicle_link.mission_client import upload
from gcs.vehicle_link.session import Session

M = MAV


@dataclass
class Telemetry:
    """What the ground station hears, for windows of the flight."""

    err_pos: list[tuple[float, float]] = field(default_factory=list)  # (wall time, m)
    heartbeats: list[float] = field(default_factory=list)
    errors_comm: list[tuple[float, int]] = field(default_factory=list)
    armed: list[tuple[float, bool]] = field(default_factory=list)
    texts: list[tuple[float, str]] = field(default_factory=list)
    mission: list[tuple[float, int, int]] = field(default_factory=list)  # (t, total, state)

    def window(self, t0: float, t1: float) -> dict[str, Any]:
        errs = [e for t, e in self.err_pos if t0 <= t <= t1]
        beats = [t0, *(t for t in self.heartbeats if t0 <= t <= t1), t1]
        comm = [c for t, c in self.errors_comm if t0 <= t <= t1]
        return {"err_pos_max_m": max(errs, default=math.nan), "err_pos_samples": len(errs),
                "heartbeat_gap_max_s": max(b - a for a, b in itertools.pairwise(beats)),
                "errors_comm": (comm[0], comm[-1]) if comm else None,
                "disarmed": any(not a for t, a in self.armed if t0 <= t <= t1),
                "mission_totals": sorted({n for t, n, _ in self.mission if t0 <= t <= t1}),
                "mission_active": all(s == M.MISSION_STATE_ACTIVE
                                      for t, _, s in self.mission if t0 <= t <= t1),
                "texts": [x for t, x in self.texts if t0 <= t <= t1]}


class Flight:
    """sitl + fcu in real time, the simulator link through a relay process (`self.relay`), the
    FCU's first GCS link `udpin` on `self.gcs_port` with a ground-station session on it and
    a thread that records its telemetry once the mission has started, and its second GCS
    link `udpout` to `self.listener` (a `LinkListener`: nothing is ever sent on it)."""

    def __init__(self, out: Path, scenario: Path = SCENARIO, *, signing: bool = False) -> None:
        self.out = out
        out.mkdir(parents=True, exist_ok=True)
        self.signing_key = secrets.token_bytes(32) if signing else None
        self.scenario = load_scenario(scenario)
        self.sitl_port, self.gcs_port = free_port(), free_port()
        self.relay = Relay(self.sitl_port)
        self.listener = LinkListener()
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.session: Session | None = None
        self.telemetry = Telemetry()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stats: dict[str, Any] = {}
        try:
            self._start(scenario)
        except BaseException:
            self.stop()
            raise

    def _spawn(self, name: str, argv: list[str]) -> None:
        log = (self.out / f"{name}.log").open("wb")
        self.procs[name] = subprocess.Popen([sys.executable, "-m", *argv], cwd=ROOT,
                                            stdout=log, stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL,
                                            env=child_env())
        log.close()

    def _start(self, scenario: Path) -> None:
        self._spawn("sitl", ["sitl.node", str(scenario), "--link",
                             f"udpin:127.0.0.1:{self.sitl_port}", "--realtime"])
        signing = []
        if self.signing_key is not None:  # MAVLink 2 signing on the GCS link
            key = self.out / "signing.key"
            key.write_text(self.signing_key.hex() + "\n")
            signing = ["--signing-key", str(key)]
        self._spawn("fcu", ["fcu.edge.node", "--vehicle", str(VEHICLE), "--gains", str(PID),
                            "--sim", f"udpout:127.0.0.1:{self.relay.port}",
                            "--gcs", f"udpin:127.0.0.1:{self.gcs_port}",
                            "--gcs", f"udpout:127.0.0.1:{self.listener.port}",
                            "--realtime", "--stats", str(self.out / "fcu_stats.json"),
                            *signing])
        self.session = Session(f"udpout:127.0.0.1:{self.gcs_port}",
                               signing_key=self.signing_key)
        self.session.wait_vehicle(timeout=30.0)
        if self.session.recv(["ATTITUDE_QUATERNION"], timeout=15.0) is None:
            raise RuntimeError("the vehicle reports no state:\n" + self.log("fcu")[-2000:])
        port = re.search(r"fcu: sim port (\d+)", self.log("fcu"))
        if port is None:
            raise RuntimeError("the FCU names no sim port:\n" + self.log("fcu")[-2000:])
        self.fcu_sim_port = int(port.group(1))

    def _session(self) -> Session:
        """The ground station's session (there once the flight has started)."""
        if self.session is None:
            raise RuntimeError("the flight has not started")
        return self.session

    def log(self, name: str) -> str:
        return (self.out / f"{name}.log").read_text(errors="replace")

    def start_mission(self) -> None:
        """Upload the scenario's mission, arm, MISSION_START (as `gcs run` does)."""
        s = self._session()
        items = scenario_mission(self.scenario)
        self.mission_items = len(items)
        result = upload(s.conn, s.target_system, s.target_component, items, send=s.send)
        if result != M.MAV_MISSION_ACCEPTED:
            raise RuntimeError(f"mission upload refused: {result}")
        for command, params in ((M.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,)),
                                (M.MAV_CMD_MISSION_START, (0.0, float(len(items) - 1)))):
            ack = s.command(command, *params)
            if ack != M.MAV_RESULT_ACCEPTED:
                raise RuntimeError(f"command {command} refused: {ack}")
        self._thread = threading.Thread(target=self._listen, name="telemetry", daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        tm = self.telemetry
        session = self._session()
        while not self._stop.is_set():
            msg = session.recv(["HEARTBEAT", "NAMED_VALUE_FLOAT", "SYS_STATUS",
                                "STATUSTEXT", "MISSION_CURRENT"], timeout=0.2)
            if msg is None or msg.get_srcSystem() != 1:
                continue
            now = time.monotonic()
            kind = msg.get_type()
            if kind == "HEARTBEAT" and msg.get_srcComponent() == M.MAV_COMP_ID_AUTOPILOT1:
                tm.heartbeats.append(now)
                tm.armed.append((now, bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)))
            elif kind == "NAMED_VALUE_FLOAT" and msg.name == "ERR_POS":
                tm.err_pos.append((now, msg.value))
            elif kind == "SYS_STATUS":
                tm.errors_comm.append((now, msg.errors_comm))
            elif kind == "STATUSTEXT":
                tm.texts.append((now, msg.text))
            elif kind == "MISSION_CURRENT":
                tm.mission.append((now, msg.total, msg.mission_state))

    def pause_telemetry(self) -> None:
        """Stop recording link 1's telemetry (the session goes on sending heartbeats)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def crashed(self) -> dict[str, int]:
        return {name: p.returncode for name, p in self.procs.items() if p.poll() is not None}

    def stop(self) -> dict[str, Any]:
        """Stop everything; the FCU's statistics and the simulator's counters."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.session is not None:
            self.session.close()
        codes = {}
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for name, p in self.procs.items():
            try:
                codes[name] = p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                codes[name] = p.wait()
        relay = self.relay.close()
        self.listener.close()
        stats_path = self.out / "fcu_stats.json"
        fcu = json.loads(stats_path.read_text()) if stats_path.exists() else {}
        sitl = {}
        m = re.search(r"(\d+) re-sends, (\d+) answers ignored, (\d+) bytes rejected",
                      self.log("sitl")) if "sitl" in self.procs else None
        if m:
            sitl = {"resends": int(m.group(1)), "ignored_answers": int(m.group(2)),
                    "rejected_bytes": int(m.group(3))}
        self.stats = {"fcu": fcu, "sitl": sitl, "relay": relay, "exit_codes": codes}
        return self.stats


class Attack:
    """Sockets and send functions for hitting one port of a Flight."""

    def __init__(self, flight: Flight, port: str, sockets: int = 4) -> None:
        self.flight = flight
        self.port = port
        self.socks = []
        for _ in range(sockets):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            s.setblocking(False)
            self.socks.append(s)
        self.rng = random.Random(port)
        self.dropped_by_sender = 0
        self.direct: Counter[str] = Counter()  # sim: inputs sent straight to the FCU's sim port

    def _sendto(self, data: bytes, port: int) -> None:
        try:
            self.rng.choice(self.socks).sendto(data, ("127.0.0.1", port))
        except (BlockingIOError, ConnectionRefusedError):
            self.dropped_by_sender += 1

    def send(self, data: bytes, category: str) -> None:
        f = self.flight
        if self.port == "gcs":
            self._sendto(data, f.gcs_port)
        elif self.port == "sitl":
            self._sendto(data, f.sitl_port)
        elif self.rng.random() < 0.1:
            # straight to the FCU's simulator port from another socket: the link reads only
            # its simulator's replies, so none of these reaches the FCU
            self._sendto(data, f.fcu_sim_port)
            self.direct[category] += 1
        elif not f.relay.inject(data):
            self.dropped_by_sender += 1

    def close(self) -> None:
        for s in self.socks:
            s.close()
