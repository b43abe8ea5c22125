"""The Zenoh fabric: the same flights as over UDP, fleets, observers, discovery."""

from __future__ import annotations

import dataclasses
import json
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh
from pymavlink.dialects.v20 import common as mavlink2

from common.config.scenario import load_scenario
from common.links import free_port
from common.links.zenoh_link import client_config, router_running
from gcs.run.process_run import run_processes

from .conftest import PACE, ROOT, SCENARIOS

CASE1 = SCENARIOS / "case1_figure8.toml"
pytestmark = pytest.mark.timeout(300)

FIGURES = ("position_error_m", "attitude_error_rad", "samples", "sim_time_s")


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    """A `gcs router` of this module's own on a free port (each test its own key prefix);
    yields its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "router", "--listen", endpoint],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 10
        while not router_running(endpoint):
            assert proc.poll() is None and time.monotonic() < deadline, "router did not start"
            time.sleep(0.05)
        yield endpoint
    finally:
        proc.terminate()
        proc.wait(timeout=10)


SHORT_S = 6.0  # the climb of Case I: every flight of this module is this long
# The flights share one single-vehicle Zenoh run (`single`): they run on one worker.
FLIGHTS = pytest.mark.xdist_group("zenoh_flights")


def _short():
    return dataclasses.replace(load_scenario(CASE1), duration_s=SHORT_S)


@dataclasses.dataclass(frozen=True)
class Single:
    out: Path
    metrics: dict


@pytest.fixture(scope="module")
def single(router, tmp_path_factory) -> Single:
    """Case I's first SHORT_S over Zenoh (GCS and simulator links), one vehicle, lockstep:
    what the UDP run and every vehicle of a fleet are compared with."""
    out = tmp_path_factory.mktemp("zenoh") / "single"
    m = run_processes(_short(), out, transport="zenoh", zenoh_url=f"zenoh:single@{router}")
    return Single(out, dict(m))


@FLIGHTS
def test_case1_over_zenoh_equals_udp_exactly(tmp_path, single):
    """GCS and simulator links both on Zenoh, lockstep: the error figures and the truth log
    of the UDP run."""
    udp = run_processes(_short(), tmp_path / "udp")
    zen = single.metrics
    assert zen["transport"] == "zenoh" and zen["lockstep"] and zen["status"] == "completed"
    assert udp["transport"] == "udp"
    for key in FIGURES:
        assert zen[key] == udp[key]
    assert (tmp_path / "udp" / "truth.ulg").read_bytes() == \
        (single.out / "truth.ulg").read_bytes()


def _observer(router: str, prefix: str, seen: dict, done: Callable[[], bool],
              clock_s: dict | None = None, timeout: float = 90.0) -> None:
    """A plain Zenoh subscriber decoding MAVLink with pymavlink only, until `done()` (at most
    `timeout` s: processes start slowly on a loaded machine); `clock_s` gets each out key's
    newest flight clock (ATTITUDE_QUATERNION time_boot_ms, in s)."""
    session = zenoh.open(client_config([router]))
    parser = mavlink2.MAVLink(None)
    parser.robust_parsing = True

    def on_sample(sample):
        for msg in parser.parse_buffer(sample.payload.to_bytes()) or []:
            key = (str(sample.key_expr), msg.get_type())
            seen[key] = seen.get(key, 0) + 1
            if clock_s is not None and key[1] == "ATTITUDE_QUATERNION":
                clock_s[key[0]] = max(clock_s.get(key[0], 0.0), msg.time_boot_ms / 1000.0)

    sub = session.declare_subscriber(f"{prefix}/*/out", on_sample)
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        time.sleep(0.1)
    sub.undeclare()
    session.close()


@FLIGHTS
def test_fleet_of_four_flies_like_one_with_observers(tmp_path, router, single):
    """A fleet of 4 (ids 1..4) completes with each vehicle's figures equal to the single
    run; an observer joining late and one leaving early change nothing; a plain subscriber
    decodes HEARTBEAT and ATTITUDE_QUATERNION from every vehicle's out key."""
    url = f"zenoh:fleet@{router}"
    seen_early: dict = {}
    seen_late: dict = {}
    # On the fleet's flight clock (6 s): the late observer joins at 2 s, the early one
    # leaves at 4 s once it has heard every vehicle; both leave when the fleet has landed.
    clock_s: dict = {}
    ended = threading.Event()

    def flown_s() -> float:
        return min(clock_s.get(f"fleet/{n}/out", 0.0) for n in range(1, 5))

    def early_done() -> bool:
        return ended.is_set() or (flown_s() >= 4.0 and all(
            seen_early.get((f"fleet/{n}/out", "HEARTBEAT"), 0) >= 1
            and seen_early.get((f"fleet/{n}/out", "ATTITUDE_QUATERNION"), 0) >= 10
            for n in range(1, 5)))

    def late_observer() -> None:
        deadline = time.monotonic() + 90.0
        while flown_s() < 2.0 and not ended.is_set() and time.monotonic() < deadline:
            time.sleep(0.05)
        _observer(router, "fleet", seen_late, lambda: ended.is_set() or bool(seen_late))

    early = threading.Thread(target=_observer, args=(router, "fleet", seen_early, early_done,
                                                     clock_s))
    late = threading.Thread(target=late_observer)
    early.start()
    late.start()
    try:
        fleet = run_processes(_short(), tmp_path / "fleet", transport="zenoh", zenoh_url=url,
                              fleet=4)
    finally:
        ended.set()
        early.join()
        late.join()
    assert fleet["all_completed"] and sorted(fleet["vehicles"]) == ["1", "2", "3", "4"]
    for n in range(1, 5):
        m = json.loads((tmp_path / "fleet" / f"vehicle{n}" / "metrics.json").read_text())
        assert m["system_id"] == n
        for key in FIGURES:
            assert m[key] == single.metrics[key], (n, key)
    assert json.loads((tmp_path / "fleet" / "fleet.json").read_text())["fleet"] == 4
    for n in range(1, 5):
        assert seen_early.get((f"fleet/{n}/out", "HEARTBEAT"), 0) >= 1
        assert seen_early.get((f"fleet/{n}/out", "ATTITUDE_QUATERNION"), 0) >= 10
    assert seen_late  # the late observer heard the fleet too


@FLIGHTS
def test_fleet_with_spacing_within_a_micrometre(tmp_path, router, single):
    """Spread 3 m apart, each vehicle flies its own offset copy of the mission."""
    url = f"zenoh:spaced@{router}"
    fleet = run_processes(_short(), tmp_path / "fleet", transport="zenoh", zenoh_url=url,
                          fleet=2, spacing_m=3.0)
    assert fleet["all_completed"]
    two = fleet["vehicles"]["2"]
    assert two["start_position_enu_m"] == [3.0, 0.0, 0.0]
    for part in ("position_error_m", "attitude_error_rad"):
        for stat in ("max", "mean", "rmse"):
            assert abs(two[part][stat] - single.metrics[part][stat]) < 1e-6


def test_ground_station_discovers_and_picks_vehicles(tmp_path, router):
    """`gcs status --connect zenoh:...` finds the vehicles from liveliness and picks one by
    system id; `gcs watch --all` shows every vehicle."""
    from .conftest import PID, VEHICLE, start, stop

    url = f"zenoh:disc@{router}"
    procs = {}
    for n in (3, 7):
        procs[f"sitl{n}"] = start(f"sitl{n}", ["sitl.node", str(CASE1), "--link", url,
                                               "--sysid", str(n), *PACE], tmp_path)
        procs[f"fcu{n}"] = start(f"fcu{n}", ["fcu.edge.node", "--vehicle", str(VEHICLE), "--gains",
                                             str(PID), "--sim", url, "--gcs", url, "--sysid",
                                             str(n)], tmp_path)
    try:
        def gcs(*args):
            return subprocess.run([sys.executable, "-m", "gcs.cli", *args, "--connect", url],
                                  cwd=ROOT, capture_output=True, text=True, timeout=60,
                                  check=False)

        out = gcs("status", "--sysid", "7")
        assert out.returncode == 0, out.stderr
        assert "system: 7" in out.stdout and "MAV_TYPE_HEXAROTOR" in out.stdout
        vehicles = gcs("vehicles", "--wait", "5")
        assert vehicles.returncode == 0 and vehicles.stdout.split() == ["3", "7"]
        watch = gcs("watch", "--all", "--duration", "3")
        assert watch.returncode == 0
        assert "system 3" in watch.stdout and "system 7" in watch.stdout
        stop({k: v for k, v in procs.items() if k.endswith("7")})
        vehicles = gcs("vehicles", "--wait", "3")
        assert vehicles.stdout.split() == ["3"]  # vehicle 7 left: its token is gone
    finally:
        stop(procs)
