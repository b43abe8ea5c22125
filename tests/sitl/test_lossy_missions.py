"""Mission upload and download through a lossy link: 100 seeded trials at 20 % loss with
duplication and reordering, between the ground station and a real `fcu` process.

Topology per worker: `fcu --gcs udpin:127.0.0.1:P --gcs udpin:127.0.0.1:Q`; the ground
station under test talks `udpout` to a UdpProxy that forwards to P (system 255); a checker
on Q (system 254, no loss) downloads the vehicle's mission after every trial, as the truth.

Each trial either completes (ACCEPTED, and the lossy download equals the upload) or fails
cleanly (MissionError or a non-ACCEPTED result) with the previous mission intact. One
outcome cannot be told apart by any MAVLink mission client: the vehicle took the mission
but its MISSION_ACK was lost six times running; the error then says so ("may hold the new
mission") and the vehicle must hold the whole new mission. Never a shorter or mixed one.
"""

from __future__ import annotations

import math
import random
import struct
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

import pytest

from common.links import free_port
from common.wire.mavlink import MAV
from common.wire.mission_items import MissionItem, local_xy
from gcs.vehicle_link.mission_client import MissionError, download, upload
from gcs.vehicle_link.session import Session

from ..udp_proxy import Impairment, UdpProxy
from .conftest import PID, VEHICLE, start, stop

M = MAV
TRIALS = 100
WORKERS = 10
LOSSY = Impairment(drop=0.2, duplicate=0.1, reorder=0.1)


def _key(items) -> list[tuple]:
    return [tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in it)
            for it in items]


def _f32(v: float) -> float:
    """v as the wire carries it (float32), so that a round trip compares equal."""
    return struct.unpack("<f", struct.pack("<f", v))[0]


def random_mission(rng: random.Random) -> tuple[list[MissionItem], bool]:
    """1-8 items within the geofence; one trial in ten has an invalid item (NaN z)."""
    n = rng.randint(1, 8)
    items = []
    for i in range(n):
        command = rng.choice([M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME,
                              M.MAV_CMD_NAV_TAKEOFF])
        items.append(MissionItem(i, M.MAV_FRAME_LOCAL_NED, command, int(i == 0), 1,
                                 _f32(rng.uniform(0, 5)), 0.0, 0.0, math.nan,
                                 local_xy(rng.uniform(-50, 50)), local_xy(rng.uniform(-50, 50)),
                                 _f32(rng.uniform(-20, -1))))
    valid = rng.random() >= 0.1
    if not valid:
        k = rng.randrange(n)
        items[k] = items[k]._replace(z=math.nan)
    return items, valid


@dataclass
class Tally:
    outcomes: Counter = field(default_factory=Counter)
    violations: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)  # why the failed trials failed
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, outcome: str, violation: str | None = None, why: str | None = None) -> None:
        with self.lock:
            self.outcomes[outcome] += 1
            if why:
                self.errors.append(f"{outcome}: {why}")
            if violation:
                self.violations.append(violation)


class Worker:
    """One fcu process, its lossy proxy, and the two ground-station sessions."""

    def __init__(self, index: int, logs) -> None:
        self.index = index
        p, q = free_port(), free_port()
        logs.mkdir(parents=True, exist_ok=True)
        self.procs = {"fcu": start("fcu", [
            "fcu.edge.node", "--vehicle", str(VEHICLE), "--gains", str(PID), "--sim",
            f"udpout:127.0.0.1:{free_port()}", "--gcs", f"udpin:127.0.0.1:{p}", "--gcs",
            f"udpin:127.0.0.1:{q}"], logs)}
        self.logs = logs
        self.proxy = UdpProxy(p, LOSSY, seed=index)
        self.lossy: Session | None = None
        self.clean: Session | None = None
        self.error: BaseException | None = None
        self.counts: Counter = Counter()
        try:
            self.lossy = Session(f"udpout:127.0.0.1:{self.proxy.port}", system_id=255)
            self.clean = Session(f"udpout:127.0.0.1:{q}", system_id=254)
            self.clean.wait_vehicle(timeout=20.0)
            self.lossy.wait_vehicle(timeout=20.0)
        except BaseException:
            self.close()
            raise

    def truth(self) -> list[MissionItem]:
        s = self.clean
        return download(s.conn, s.target_system, s.target_component, send=s.send)

    def run(self, seeds: list[int], tally: Tally) -> None:
        try:
            previous = self.truth()
            for seed in seeds:
                previous = self.trial(seed, previous, tally)
        except BaseException as exc:  # reported by the test
            self.error = exc

    def trial(self, seed: int, previous: list[MissionItem], tally: Tally) -> list[MissionItem]:
        rng = random.Random(seed)
        self.proxy.rng.seed(seed)
        items, valid = random_mission(rng)
        s = self.lossy
        result, error, got = None, None, None
        try:
            result = upload(s.conn, s.target_system, s.target_component, items, send=s.send)
        except MissionError as exc:
            error = str(exc)
        if result == M.MAV_MISSION_ACCEPTED:
            try:
                got = download(s.conn, s.target_system, s.target_component, send=s.send)
            except MissionError as exc:
                error = str(exc)
        truth = self.truth()
        where = f"seed {seed}: result {result}, error {error!r}"
        if got is not None:
            # completed: what came back is what went up, and what the vehicle holds
            ok = _key(got) == _key(items) == _key(truth)
            tally.add("completed", None if ok else f"{where}: download differs")
        elif result == M.MAV_MISSION_ACCEPTED:
            # the upload completed, the lossy download failed cleanly
            ok = _key(truth) == _key(items)
            tally.add("accepted, download failed", None if ok else f"{where}: not stored",
                      error)
        elif error is not None and "may hold the new mission" in error:
            ok = _key(truth) in (_key(previous), _key(items))
            tally.add("upload: last ACK lost", None if ok else f"{where}: partial mission",
                      error)
        else:
            ok = _key(truth) == _key(previous)
            if not ok:
                where += (f"; previous {len(previous)} items, uploaded {len(items)}, vehicle "
                          f"{len(truth)}: vehicle == uploaded {_key(truth) == _key(items)}, "
                          f"uploaded {items}, vehicle {truth}, previous {previous}")
            if ok and not valid and result is not None:
                ok = result != M.MAV_MISSION_ACCEPTED
            outcome = "refused (invalid mission)" if not valid and result is not None else \
                "upload failed cleanly"
            tally.add(outcome, None if ok else f"{where}: previous mission not intact",
                      error or f"MAV_MISSION_RESULT {result}")
        if not valid and result == M.MAV_MISSION_ACCEPTED:
            tally.add("invalid accepted", f"{where}: an invalid mission was accepted")
        self.counts.update(self.proxy.counts)
        return truth

    def close(self) -> None:
        for s in (self.lossy, self.clean):
            if s is not None:
                s.close()
        self.proxy.close()
        stop(self.procs)


@pytest.mark.timeout(300)
def test_missions_through_a_lossy_link_complete_or_fail_cleanly(tmp_path):
    """100 seeded trials (10 fcu processes in parallel, 10 trials each, the protocol's
    timeouts: 1500 ms, 250 ms per item, 5 retries): no trial ends with a mission other than
    the uploaded one (completed) or the previous one (failed), and most complete."""
    t0 = time.monotonic()
    workers: list[Worker] = []
    try:
        for w in range(WORKERS):
            workers.append(Worker(w, tmp_path / f"worker{w}"))
        tally = Tally()
        seeds = list(range(TRIALS))
        threads = [threading.Thread(target=w.run, args=(seeds[i::WORKERS], tally))
                   for i, w in enumerate(workers)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=240)
        for w in workers:
            assert w.error is None, f"worker {w.index}: {w.error!r}"
            assert w.procs["fcu"].poll() is None, (w.logs / "fcu.log").read_text()[-2000:]
    finally:
        proxies = Counter()
        for w in workers:
            proxies.update(w.proxy.counts)
            w.close()
    total = sum(tally.outcomes.values()) - tally.outcomes["invalid accepted"]
    print(f"\nlossy mission trials ({time.monotonic() - t0:.1f} s): {dict(tally.outcomes)}; "
          f"proxy {dict(proxies)}")
    for why in tally.errors:
        print("  ", why)
    for v in tally.violations:
        print("VIOLATION", v)
    assert total == TRIALS
    assert not tally.violations, tally.violations
    assert proxies["dropped"] > 500 and proxies["duplicated"] > 200
    assert proxies["reordered"] > 200
    assert tally.outcomes["completed"] >= 60
    assert tally.outcomes["refused (invalid mission)"] >= 1
