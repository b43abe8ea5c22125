"""Hostile-input campaign against running processes, while a real flight goes on.

A real-time Case I flight (sitl + fcu processes, mission uploaded with the mission protocol,
armed, MISSION_START) is hit on one port at a time with at least 100,000 inputs:

    gcs   the FCU's GCS link (`--gcs udpin:127.0.0.1:PORT`: it reads from any sender), beside
          the ground station's own session on the same port
    sim   the FCU's simulator link: through a relay on the link (as a corrupting wire or a
          man in the middle would), plus datagrams sent straight to the FCU's ephemeral sim
          port ("fcu: sim port N") from other sockets
    sitl  the simulator's port (udpin)
    gcs-signed  the GCS link again, the same inputs, with MAVLink 2 signing required

Inputs per port: random datagrams, valid frames cut short, valid frames with 1-3 bits
flipped (CRC-16 catches every such error), valid frames for or from other system ids that
the target must ignore, and floods (bursts of valid frames at full speed). A baseline
flight without hostile input gives the deadline misses to compare with.

Then two attacks with valid frames that the target must ignore: simulator states from
another system id on the simulator link, and actuator commands from another system id to
the simulator (both were obeyed before commit 674bea7). They run in flights of their own.

Printed per flight: inputs sent by category, crashes (a process that exited), the FCU's
deadline misses, rejected bytes and ignored messages (`--stats`), the simulator's rejected
bytes, SYS_STATUS errors_comm, the largest ERR_POS and heartbeat gap during the attack, and
whether the mission kept flying. Exit status 1 if a process crashed or the flight left its
mission during a non-destructive attack.

    .venv/bin/python benchmarks/fuzz_campaign.py                 # 100,000 inputs per port
    .venv/bin/python benchmarks/fuzz_campaign.py --inputs 20000 --ports gcs,sitl
"""

from __future__ import annotations

import argparse
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
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script: the repository's packages and tests/
    sys.path.insert(0, str(ROOT))

from common.config import load_scenario  # noqa: E402
from common.links import free_port  # noqa: E402
from common.mavlink import MAV, encoder, pack  # noqa: E402
from common.simlink import (  # noqa: E402
    ActuatorControls,
    Odometry,
    pack_actuator_controls,
    pack_odometry,
)
from gcs.mission_client import upload  # noqa: E402
from gcs.scenario_mission import scenario_mission  # noqa: E402
from gcs.session import Session  # noqa: E402
from tests.udp_proxy import Impairment, UdpProxy  # noqa: E402

M = MAV
SCENARIO = ROOT / "config" / "scenarios" / "case1_figure8.toml"
VEHICLE = ROOT / "config" / "vehicles" / "hexa_tilted.toml"
PID = ROOT / "config" / "gains" / "pid_eq30.toml"
PORTS = ("gcs", "sim", "sitl")
CAMPAIGN_PORTS = (*PORTS, "gcs-signed")  # the GCS link again, with MAVLink 2 signing
MIX = (("random", 0.30), ("truncated", 0.20), ("bitflip", 0.25), ("foreign", 0.15),
       ("flood", 0.10))
FLOOD_BURST = 500
ERR_POS_LIMIT_M = 0.1


# ----------------------------------------------------------------------------------------
# Hostile inputs
# ----------------------------------------------------------------------------------------


class Traffic:
    """Hostile datagrams for one target: "gcs" (the FCU's MAVLink GCS side), "sim" (the
    FCU's simulator side) or "sitl" (the simulator). Seeded."""

    def __init__(self, target: str, seed: int = 0) -> None:
        if target not in PORTS:
            raise ValueError(target)
        self.target = target
        self.rng = random.Random(seed)
        self._mavs: dict[int, MAV.MAVLink] = {}
        self._seq = 0
        # MIX gives shares of the inputs; a flood pick sends FLOOD_BURST of them at once
        self._categories = [c for c, _ in MIX]
        self._weights = [w / (FLOOD_BURST if c == "flood" else 1) for c, w in MIX]

    # -- building blocks

    def _mav(self, sysid: int, compid: int = M.MAV_COMP_ID_MISSIONPLANNER) -> MAV.MAVLink:
        key = sysid << 8 | compid
        mav = self._mavs.get(key)
        if mav is None:
            mav = self._mavs[key] = encoder(sysid, compid)
        return mav

    def _f(self) -> float:
        r = self.rng
        return r.choice([0.0, 1.0, -1.0, math.nan, math.inf, 3.4e38, 1e-45]) \
            if r.random() < 0.2 else r.uniform(-10.0, 10.0)

    def _odometry(self, sysid: int = 1) -> bytes:
        r = self.rng
        odo = Odometry(r.getrandbits(40), (r.uniform(-5, 5), r.uniform(-5, 5), -r.uniform(0, 10)),
                       (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self._seq = (self._seq + 1) & 0xFF
        return pack_odometry(odo, self._seq, sysid, M.MAV_COMP_ID_PERIPHERAL)

    def _controls(self, sysid: int = 1) -> bytes:
        r = self.rng
        a = ActuatorControls(r.getrandbits(40), tuple(r.uniform(0, 1) for _ in range(16)),
                             r.choice([0, M.MAV_MODE_FLAG_SAFETY_ARMED]), 1)
        self._seq = (self._seq + 1) & 0xFF
        return pack_actuator_controls(a, self._seq, sysid, M.MAV_COMP_ID_AUTOPILOT1)

    def _hil_sensor(self, sysid: int) -> bytes:
        msg = M.MAVLink_hil_sensor_message(self.rng.getrandbits(40),
                                           *(self._f() for _ in range(13)), 0x1A3F, 0)
        return pack(self._mav(sysid, M.MAV_COMP_ID_PERIPHERAL), msg)

    def _heartbeat(self, sysid: int, kind: int = M.MAV_TYPE_GCS) -> bytes:
        msg = M.MAVLink_heartbeat_message(kind, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                          M.MAV_STATE_ACTIVE, 3)
        return pack(self._mav(sysid), msg)

    def _gcs_message(self, target_system: int) -> bytes:
        """A command or request of the kinds a ground station sends, to `target_system`."""
        r = self.rng
        t = (target_system, r.choice([0, 1]))
        kind = r.randrange(8)
        if kind == 0:
            msg = M.MAVLink_command_long_message(*t, M.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                 r.choice([0.0, 1.0]), 21196.0, 0, 0, 0, 0, 0)
        elif kind == 1:
            msg = M.MAVLink_command_long_message(*t, M.MAV_CMD_DO_SET_MODE, 0, 1.0,
                                                 r.choice([4.0, 6.0]), r.choice([3.0, 6.0]),
                                                 0, 0, 0, 0)
        elif kind == 2:
            msg = M.MAVLink_command_long_message(*t, M.MAV_CMD_NAV_LAND, 0, *(0.0,) * 7)
        elif kind == 3:
            msg = M.MAVLink_param_set_message(*t, b"MIS_CRUISE_SPD", self._f(),
                                              M.MAV_PARAM_TYPE_REAL32)
        elif kind == 4:
            msg = M.MAVLink_mission_count_message(*t, r.randint(0, 500), 0)
        elif kind == 5:
            msg = M.MAVLink_mission_clear_all_message(*t, 0)
        elif kind == 6:
            msg = M.MAVLink_set_position_target_local_ned_message(
                0, *t, M.MAV_FRAME_LOCAL_NED, 0, *(self._f() for _ in range(11)))
        else:
            msg = M.MAVLink_command_int_message(*t, 0, M.MAV_CMD_MISSION_START, 0, 0,
                                                *(0.0,) * 4, 0, 0, 0.0)
        return pack(self._mav(r.randint(1, 255)), msg)

    def valid_frame(self) -> bytes:
        """A valid frame of what the target reads, from and for the systems it serves (used
        only as the base of damaged frames: never sent whole)."""
        if self.target == "gcs":
            return self._gcs_message(1)
        if self.target == "sim":
            return self._odometry(1) if self.rng.random() < 0.8 else self._hil_sensor(1)
        return self._controls(1)

    def foreign_frame(self) -> bytes:
        """A valid frame the target must ignore: for another system, or a message of another
        system that the target has no use for."""
        r = self.rng
        other = r.randint(2, 254)
        if self.target == "gcs":
            return self._gcs_message(other)
        if r.random() < 0.5:
            return self._hil_sensor(other)
        return self._heartbeat(other, M.MAV_TYPE_HEXAROTOR)

    def flood_frame(self) -> bytes:
        """What a flood is made of: valid frames the target reads and drops cheaply."""
        r = self.rng
        if self.target == "gcs":
            return self._heartbeat(r.randint(200, 250)) if r.random() < 0.5 else \
                self._gcs_message(r.randint(2, 254))
        if self.target == "sim":
            return self._hil_sensor(1)
        return self._heartbeat(r.randint(2, 254), M.MAV_TYPE_HEXAROTOR)

    # -- categories

    def random_datagram(self) -> bytes:
        r = self.rng
        n = r.randint(1, 300)
        if r.random() < 0.5:
            return r.randbytes(n)
        # rich in start markers and plausible header bytes
        return bytes(r.choice((0xFD, 0xFD, 0xFE, 0x00, 0xFF, 0x4B, 0x01, 0x5D, r.getrandbits(8)))
                     for _ in range(n))

    def truncated(self) -> bytes:
        frame = self.valid_frame()
        return frame[:self.rng.randint(1, len(frame) - 1)]

    def bitflip(self) -> bytes:
        """1 to 3 flipped bits: CRC-16/MCRF4XX detects every such error in these lengths."""
        data = bytearray(self.valid_frame())
        for bit in self.rng.sample(range(8 * len(data)), self.rng.randint(1, 3)):
            data[bit // 8] ^= 1 << (bit % 8)
        return bytes(data)

    def next(self) -> tuple[str, list[bytes]]:
        """The next input's category and its datagrams (a flood is a burst of them)."""
        category = self.rng.choices(self._categories, self._weights)[0]
        if category == "random":
            return category, [self.random_datagram()]
        if category == "truncated":
            return category, [self.truncated()]
        if category == "bitflip":
            return category, [self.bitflip()]
        if category == "foreign":
            return category, [self.foreign_frame()]
        return category, [self.flood_frame() for _ in range(FLOOD_BURST)]


def blast(traffic: Traffic, send: Callable[[bytes, str], None], n: int, rate: float,
          counts: Counter, stop: threading.Event | None = None) -> None:
    """Send `n` inputs at about `rate` per second on average (floods go out at full speed
    within their burst). `send(data, category)`."""
    t0 = time.monotonic()
    sent = 0
    while sent < n and not (stop is not None and stop.is_set()):
        category, datagrams = traffic.next()
        for data in datagrams[:n - sent]:
            send(data, category)
            counts[category] += 1
            sent += 1
        ahead = sent / rate - (time.monotonic() - t0)
        if ahead > 0.002:
            time.sleep(ahead)


# ----------------------------------------------------------------------------------------
# A real-time flight to attack
# ----------------------------------------------------------------------------------------


def _stop_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


@dataclass
class Telemetry:
    """What the ground station hears, for windows of the flight."""

    err_pos: list[tuple[float, float]] = field(default_factory=list)  # (wall time, m)
    heartbeats: list[float] = field(default_factory=list)
    errors_comm: list[tuple[float, int]] = field(default_factory=list)
    armed: list[tuple[float, bool]] = field(default_factory=list)
    texts: list[tuple[float, str]] = field(default_factory=list)
    mission: list[tuple[float, int, int]] = field(default_factory=list)  # (t, total, state)

    def window(self, t0: float, t1: float) -> dict:
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
    """sitl + fcu in real time, the simulator link through a relay (`self.relay`), the
    FCU's GCS link `udpin` on `self.gcs_port`, a ground-station session on it, and a
    thread that records telemetry once the mission has started."""

    def __init__(self, out: Path, scenario: Path = SCENARIO, *, signing: bool = False) -> None:
        self.out = out
        out.mkdir(parents=True, exist_ok=True)
        self.signing_key = secrets.token_bytes(32) if signing else None
        self.scenario = load_scenario(scenario)
        self.sitl_port, self.gcs_port = free_port(), free_port()
        self.relay = UdpProxy(self.sitl_port, Impairment(), seed=0)
        self.procs: dict[str, subprocess.Popen] = {}
        self.session: Session | None = None
        self.telemetry = Telemetry()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stats: dict = {}
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
                                            preexec_fn=_stop_with_parent)
        log.close()

    def _start(self, scenario: Path) -> None:
        self._spawn("sitl", ["sitl.node", str(scenario), "--link",
                             f"udpin:127.0.0.1:{self.sitl_port}", "--realtime"])
        signing = []
        if self.signing_key is not None:  # MAVLink 2 signing on the GCS link
            key = self.out / "signing.key"
            key.write_text(self.signing_key.hex() + "\n")
            signing = ["--signing-key", str(key)]
        self._spawn("fcu", ["fcu.node", "--vehicle", str(VEHICLE), "--gains", str(PID),
                            "--sim", f"udpout:127.0.0.1:{self.relay.port}", "--gcs",
                            f"udpin:127.0.0.1:{self.gcs_port}", "--realtime", "--stats",
                            str(self.out / "fcu_stats.json"), *signing])
        self.session = Session(f"udpout:127.0.0.1:{self.gcs_port}",
                               signing_key=self.signing_key)
        self.session.wait_vehicle(timeout=30.0)
        if self.session.recv(["ATTITUDE_QUATERNION"], timeout=15.0) is None:
            raise RuntimeError("the vehicle reports no state:\n" + self.log("fcu")[-2000:])
        self.fcu_sim_port = int(re.search(r"fcu: sim port (\d+)", self.log("fcu")).group(1))

    def log(self, name: str) -> str:
        return (self.out / f"{name}.log").read_text(errors="replace")

    def start_mission(self) -> None:
        """Upload the scenario's mission, arm, MISSION_START (as `gcs run` does)."""
        s = self.session
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
        while not self._stop.is_set():
            msg = self.session.recv(["HEARTBEAT", "NAMED_VALUE_FLOAT", "SYS_STATUS",
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

    def crashed(self) -> dict[str, int]:
        return {name: p.returncode for name, p in self.procs.items() if p.poll() is not None}

    def stop(self) -> dict:
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
        self.relay.close()
        stats_path = self.out / "fcu_stats.json"
        fcu = json.loads(stats_path.read_text()) if stats_path.exists() else {}
        sitl = {}
        m = re.search(r"(\d+) re-sends, (\d+) answers ignored, (\d+) bytes rejected",
                      self.log("sitl")) if "sitl" in self.procs else None
        if m:
            sitl = {"resends": int(m.group(1)), "ignored_answers": int(m.group(2)),
                    "rejected_bytes": int(m.group(3))}
        self.stats = {"fcu": fcu, "sitl": sitl, "exit_codes": codes}
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
        self.direct = Counter()  # sim: inputs sent straight to the FCU's sim port

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


# ----------------------------------------------------------------------------------------
# The campaign
# ----------------------------------------------------------------------------------------


def _fmt(d: dict) -> str:
    return ", ".join(f"{k} {v}" for k, v in d.items())


def run_port(port: str | None, out: Path, inputs: int, rate: float, seed: int,
             settle_s: float = 4.0, baseline_s: float = 20.0) -> dict:
    """One flight attacked on `port` (None: a baseline flight of `baseline_s`); "gcs-signed"
    attacks the GCS link of an FCU that requires MAVLink 2 signing."""
    signed = port == "gcs-signed"
    target = "gcs" if signed else port
    flight = Flight(out, signing=signed)
    counts: Counter = Counter()
    attack = None
    try:
        flight.start_mission()
        time.sleep(settle_s)
        t0 = time.monotonic()
        if target is None:
            time.sleep(baseline_s)
        else:
            attack = Attack(flight, target)
            blast(Traffic(target, seed), attack.send, inputs, rate, counts)
            time.sleep(1.0)  # let the last inputs be read
        t1 = time.monotonic()
        time.sleep(2.0)  # and the flight go on after the attack
        after = flight.telemetry.window(t1, time.monotonic())
        during = flight.telemetry.window(t0, t1)
        crashed = flight.crashed()
    finally:
        if attack is not None:
            attack.close()
        stats = flight.stop()
    return {"port": port or "baseline", "inputs": sum(counts.values()), "by_category": counts,
            "mission_items": flight.mission_items,
            "direct_to_fcu_sim_port": sum(attack.direct.values()) if attack else 0,
            "not_sent_buffer_full": attack.dropped_by_sender if attack else 0,
            "seconds": t1 - t0, "crashed": crashed, "during": during, "after": after,
            "stats": stats}


def run_spoof(kind: str, out: Path, seconds: float = 2.0) -> dict:
    """Valid frames from another system id that the target should ignore: simulator states
    to the FCU (through the relay) or actuator commands to the simulator."""
    flight = Flight(out)
    sent = 0
    try:
        flight.start_mission()
        time.sleep(4.0)
        t0 = time.monotonic()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        seq = 0
        while time.monotonic() - t0 < seconds:
            seq = (seq + 1) & 0xFF
            if kind == "states":
                odo = Odometry(int(time.monotonic() * 1e6), (3.0, 3.0, -3.0),
                               (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
                flight.relay.inject(pack_odometry(odo, seq, 42, M.MAV_COMP_ID_PERIPHERAL))
            else:
                a = ActuatorControls(0, (0.0,) * 16, 0, 1)  # disarmed: rotors stopped
                sock.sendto(pack_actuator_controls(a, seq, 42, M.MAV_COMP_ID_AUTOPILOT1),
                            ("127.0.0.1", flight.sitl_port))
            sent += 1
            time.sleep(0.002)
        sock.close()
        t1 = time.monotonic()
        time.sleep(2.0)
        during = flight.telemetry.window(t0, time.monotonic())
        crashed = flight.crashed()
    finally:
        stats = flight.stop()
    return {"attack": kind, "sent": sent, "seconds": t1 - t0, "crashed": crashed,
            "during_and_after": during, "stats": stats}


def report_port(r: dict) -> bool:
    d, a, st = r["during"], r["after"], r["stats"]
    fcu, sitl = st["fcu"], st["sitl"]
    mission_kept = d["mission_totals"] == a["mission_totals"] == [r["mission_items"]] and \
        d["mission_active"] and a["mission_active"]
    ok = not r["crashed"] and d["err_pos_max_m"] < ERR_POS_LIMIT_M and \
        a["err_pos_max_m"] < ERR_POS_LIMIT_M and not d["disarmed"] and \
        a["heartbeat_gap_max_s"] < 2.0 and mission_kept
    print(f"== {r['port']}: {r['inputs']} inputs in {r['seconds']:.1f} s "
          f"({r['inputs'] / max(r['seconds'], 1e-9):.0f}/s)")
    if r["inputs"]:
        print(f"   by category: {_fmt(dict(sorted(r['by_category'].items())))}")
    if r["direct_to_fcu_sim_port"]:
        print(f"   of which {r['direct_to_fcu_sim_port']} straight to the FCU's sim port from "
              "other sockets (dropped by its link), the rest through the relay")
    if r["not_sent_buffer_full"]:
        print(f"   not sent (our socket buffer full): {r['not_sent_buffer_full']}")
    print(f"   crashed: {r['crashed'] or 'none'}; exit codes {st['exit_codes']}")
    print(f"   FCU: {fcu.get('steps')} steps, {fcu.get('deadline_misses')} deadline misses, "
          f"{fcu.get('rejected_bytes')} bytes rejected, {fcu.get('ignored_messages')} "
          f"messages ignored, {fcu.get('signing_rejects')} refused by signing")
    if sitl:
        print(f"   SITL: {sitl['rejected_bytes']} bytes rejected, "
              f"{sitl['ignored_answers']} answers ignored")
    print(f"   during: ERR_POS max {d['err_pos_max_m']:.4f} m ({d['err_pos_samples']} "
          f"samples), heartbeat gap max {d['heartbeat_gap_max_s']:.2f} s, SYS_STATUS "
          f"errors_comm {d['errors_comm']}, disarmed {d['disarmed']}")
    print(f"   after:  ERR_POS max {a['err_pos_max_m']:.4f} m, heartbeat gap max "
          f"{a['heartbeat_gap_max_s']:.2f} s")
    if d["texts"]:
        print(f"   STATUSTEXT: {sorted(set(d['texts']))[:6]}")
    print(f"   mission: {r['mission_items']} items uploaded; MISSION_CURRENT totals during "
          f"{d['mission_totals']}, after {a['mission_totals']}; active throughout "
          f"{d['mission_active'] and a['mission_active']}")
    print(f"   flight kept its mission: {'yes' if ok else 'NO'}")
    return ok


def report_spoof(r: dict) -> None:
    d, st = r["during_and_after"], r["stats"]
    what = {"states": "ODOMETRY from system 42 through the simulator link (3 m away)",
            "commands": "HIL_ACTUATOR_CONTROLS from system 42 to the simulator (rotors off)"}
    print(f"== spoof: {r['sent']} x {what[r['attack']]} in {r['seconds']:.1f} s")
    print(f"   crashed: {r['crashed'] or 'none'}; ERR_POS max {d['err_pos_max_m']:.3f} m, "
          f"disarmed {d['disarmed']}, STATUSTEXT {sorted(set(d['texts']))[:4]}")
    print(f"   FCU: {st['fcu'].get('deadline_misses')} deadline misses, "
          f"{st['fcu'].get('ignored_messages')} messages ignored; SITL: "
          f"{st['sitl'].get('ignored_answers')} answers ignored; ignored as it should: "
          f"{'yes' if d['err_pos_max_m'] < ERR_POS_LIMIT_M and not d['disarmed'] else 'NO'}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--inputs", type=int, default=100_000, help="inputs per port")
    p.add_argument("--rate", type=float, default=5000.0, help="inputs per second (average)")
    p.add_argument("--ports", default=",".join(CAMPAIGN_PORTS),
                   help=f"comma-separated, some of {','.join(CAMPAIGN_PORTS)}")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--no-spoof", action="store_true", help="skip the spoofing findings")
    p.add_argument("--out", type=Path, help="keep the flights' logs here")
    args = p.parse_args(argv)
    ports = [x for x in args.ports.split(",") if x]
    if any(x not in CAMPAIGN_PORTS for x in ports):
        p.error(f"--ports: expected some of {','.join(CAMPAIGN_PORTS)}")
    tmp = None
    if args.out is None:
        tmp = tempfile.TemporaryDirectory(prefix="fuzz_campaign_")
        out = Path(tmp.name)
    else:
        out = args.out
    ok = True
    try:
        base = run_port(None, out / "baseline", 0, args.rate, args.seed,
                        baseline_s=args.inputs / args.rate)
        ok &= report_port(base)
        for port in ports:  # the signed GCS link gets the very inputs of the unsigned one
            seed = args.seed + PORTS.index(port.removesuffix("-signed"))
            ok &= report_port(run_port(port, out / port, args.inputs, args.rate, seed))
        if not args.no_spoof:
            for kind in ("states", "commands"):
                report_spoof(run_spoof(kind, out / f"spoof_{kind}"))
    finally:
        if tmp is not None:
            tmp.cleanup()
    print("campaign:", "no crash, the flight kept its mission on every port" if ok else
          "FAILED (see above)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
