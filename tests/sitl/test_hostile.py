"""Hostile input on every port of a real-time flight (a reduced `benchmarks/fuzz_campaign.py`):
20,000 mixed datagrams per port (random bytes, cut and bit-flipped valid frames, frames for
other systems, floods) at once on the FCU's GCS link, its simulator link (through a relay,
as a corrupting wire; plus straight to its sim port from other sockets) and the simulator's
port. Nothing crashes, the flight goes on (heartbeats, ERR_POS < 0.1 m, still armed), and
the rejection counters show the input was seen and refused."""

from __future__ import annotations

import threading
import time
from collections import Counter

import pytest

from benchmarks.fuzz.config import PORTS
from benchmarks.fuzz.flight import Attack, Flight
from benchmarks.fuzz.traffic import Traffic, blast
from common.wire.mavlink import MAV

from .waits import until

INPUTS = 20_000
RATE = 2_500.0  # per port and second: the three ports together, 7,500 inputs/s


@pytest.mark.timeout(120)
def test_hostile_input_on_every_port_does_not_stop_a_real_time_flight(tmp_path):
    flight = Flight(tmp_path)
    attacks: dict[str, Attack] = {}
    counts = {port: Counter() for port in PORTS}
    try:
        flight.start_mission()
        started = time.monotonic()
        tm = flight.telemetry
        # The attack starts 2 s into the mission (real time: the same part of the flight),
        # once the telemetry shows it under way.
        until(lambda: time.monotonic() >= started + 2.0 and bool(tm.errors_comm)
              and len(tm.err_pos) >= 10
              and any(state == MAV.MISSION_STATE_ACTIVE for _, _, state in tm.mission),
              "the mission under way (ERR_POS, SYS_STATUS, MISSION_CURRENT active)")
        comm_before = tm.errors_comm[-1][1] if tm.errors_comm else 0
        attacks = {port: Attack(flight, port) for port in PORTS}
        threads = [threading.Thread(target=blast, args=(Traffic(port, seed), attacks[port].send,
                                                        INPUTS, RATE, counts[port]))
                   for seed, port in enumerate(PORTS)]
        t0 = time.monotonic()
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
        time.sleep(1.0)  # deliberate: the last inputs, still queued, belong to `during`
        t1 = time.monotonic()
        # `after`: 2.5 s at least, and until it holds what it is judged on (a slow machine
        # sends telemetry late), at most 30 s
        while time.monotonic() < t1 + 30.0:
            after = tm.window(t1, time.monotonic())
            if time.monotonic() >= t1 + 2.5 and after["err_pos_samples"] > 5 and \
                    after["errors_comm"] is not None and after["mission_totals"]:
                break
            time.sleep(0.2)
        during = tm.window(t0, t1)
        after = tm.window(t1, time.monotonic())
        crashed = flight.crashed()
    finally:
        for a in attacks.values():
            a.close()
        stats = flight.stop()
    print(f"\nhostile: {t1 - t0:.1f} s; {({p: dict(c) for p, c in counts.items()})}; "
          f"during {during}; after {after}; stats {stats}")
    assert not crashed and set(stats["exit_codes"].values()) == {0}, stats
    for port in PORTS:
        assert sum(counts[port].values()) == INPUTS, port
        assert set(counts[port]) == {"random", "truncated", "bitflip", "foreign", "flood"}
    # the flight went on: telemetry kept coming, on its path, armed
    assert during["err_pos_samples"] > 20 and after["err_pos_samples"] > 5
    assert during["err_pos_max_m"] < 0.1 and after["err_pos_max_m"] < 0.1
    # HEARTBEAT at 1 Hz, as received by this test beside its three blasting threads on a
    # loaded machine: one beat late (2.03 s seen beside two busy processes) is no loss, two
    # missed in a row would be
    assert during["heartbeat_gap_max_s"] < 3.0 and after["heartbeat_gap_max_s"] < 3.0
    assert not during["disarmed"] and not after["disarmed"]
    assert during["mission_totals"] == after["mission_totals"] == [flight.mission_items]
    assert during["mission_active"] and after["mission_active"]
    # what was refused was counted: bytes on the GCS and simulator links of the FCU,
    # messages for other systems, bytes at the simulator, and in SYS_STATUS
    fcu, sitl = stats["fcu"], stats["sitl"]
    assert fcu["rejected_bytes"] > 100_000 and fcu["ignored_messages"] > 500
    assert sitl["rejected_bytes"] > 50_000
    assert after["errors_comm"] is not None and after["errors_comm"][1] > comm_before
    assert fcu["steps"] > 5000
