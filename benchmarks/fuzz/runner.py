"""One flight per port: the non-destructive attack, then (GCS ports) the sequence campaign;
and the spoofing findings."""

from __future__ import annotations

import socket
import time
from collections import Counter
from pathlib import Path
from typing import Any

from benchmarks.fuzz.flight import Attack, Flight
from benchmarks.fuzz.sequence_campaign import SequenceCampaign
from benchmarks.fuzz.traffic import Traffic, blast
from common.wire.mavlink import MAV
from common.wire.simlink import ActuatorControls, Odometry, pack_actuator_controls, pack_odometry

M = MAV


def run_port(port: str | None, out: Path, inputs: int, rate: float, seed: int,
             settle_s: float = 4.0, baseline_s: float = 20.0, *, seq_rate: float = 2500.0,
             probe_every: int = 2000) -> dict[str, Any]:
    """One flight attacked on `port` (None: a baseline flight of `baseline_s`); "gcs-signed"
    attacks the GCS link of an FCU that requires MAVLink 2 signing. On the GCS ports the
    non-destructive attack is followed by the sequence campaign, in the same flight."""
    signed = port == "gcs-signed"
    target = "gcs" if signed else port
    flight = Flight(out, signing=signed)
    counts: Counter[str] = Counter()
    attack = None
    campaign = None
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
        if target == "gcs" and inputs > 0 and not crashed:
            flight.pause_telemetry()  # link 1 is about to be reconfigured at will
            assert attack is not None
            campaign = SequenceCampaign(flight, attack, seed, seq_rate, probe_every)
            campaign.run(inputs)
            time.sleep(2.0)  # the answers and streams after the last input
        fcu_alive = flight.procs["fcu"].poll() is None
        listen = flight.listener.summary(time.time())
        crashed_end = flight.crashed()
    finally:
        if attack is not None:
            attack.close()
        if campaign is not None:
            campaign.close()
        stats = flight.stop()
    seq = None
    if campaign is not None:
        pr = campaign.prober
        seq = {"inputs": campaign.sent, "in_sequences": campaign.in_sequences,
               "sequences": campaign.sequences, "by_category": campaign.counts,
               "seconds": campaign.seconds, "probe_seconds": campaign.probe_seconds,
               "not_sent": campaign.not_sent, "probes": pr.summary(),
               "probe_failures": pr.failures, "probes_failed": pr.failed,
               "link1_stream_msg_s_max": max(pr.stream_rates, default=None),
               "internal_errors": campaign.report_errors(out)}
    internal = stats["fcu"].get("internal_errors")
    log_tail = flight.log("fcu")[-4000:] if not fcu_alive or internal else ""
    return {"port": port or "baseline", "inputs": sum(counts.values()), "by_category": counts,
            "mission_items": flight.mission_items,
            "direct_to_fcu_sim_port": sum(attack.direct.values()) if attack else 0,
            "not_sent_buffer_full": attack.dropped_by_sender if attack else 0,
            "seconds": t1 - t0, "crashed": crashed, "crashed_end": crashed_end,
            "during": during, "after": after, "stats": stats, "fcu_alive": fcu_alive,
            "listen": listen, "sequences": seq, "fcu_log_tail": log_tail}


def run_spoof(kind: str, out: Path, seconds: float = 2.0) -> dict[str, Any]:
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
