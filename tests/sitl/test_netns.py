"""Across machines, on one machine: FCU and SITL in one network namespace, the ground
station in another, joined by a veth pair; the Zenoh router runs beside the vehicle and the
ground station reaches it over the veth link. Skipped where namespaces cannot be made."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator

import pytest

from common.config.scenario import load_scenario
from gcs.mission_files.toml import format_toml
from gcs.run.scenario_mission import scenario_mission

from .conftest import PACE, PID, ROOT, SCENARIOS, VEHICLE
from .waits import until

pytestmark = pytest.mark.timeout(180)
SUBNET = "10.231.{}.{}"


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=False)


@pytest.fixture
def namespaces() -> Iterator[tuple[str, str, str, str]]:
    """Two namespaces of this test's own (vehicle side, ground side) and their addresses."""
    if shutil.which("ip") is None or os.geteuid() != 0:
        pytest.skip("network namespaces need iproute2 and root")
    tag = f"{os.getpid() % 100000}"
    ns_v, ns_g = f"dqv{tag}", f"dqg{tag}"
    veth_v, veth_g = f"dqv{tag}", f"dqg{tag}"
    octet = os.getpid() % 200 + 20
    addr_v, addr_g = SUBNET.format(octet, 1), SUBNET.format(octet, 2)
    if _ip("netns", "add", ns_v).returncode != 0:
        pytest.skip("cannot create network namespaces here")
    try:
        steps = [("netns", "add", ns_g),
                 ("link", "add", veth_v, "type", "veth", "peer", "name", veth_g),
                 ("link", "set", veth_v, "netns", ns_v),
                 ("link", "set", veth_g, "netns", ns_g),
                 ("-n", ns_v, "addr", "add", f"{addr_v}/24", "dev", veth_v),
                 ("-n", ns_g, "addr", "add", f"{addr_g}/24", "dev", veth_g),
                 ("-n", ns_v, "link", "set", veth_v, "up"),
                 ("-n", ns_g, "link", "set", veth_g, "up"),
                 ("-n", ns_v, "link", "set", "lo", "up"),
                 ("-n", ns_g, "link", "set", "lo", "up")]
        for step in steps:
            done = _ip(*step)
            if done.returncode != 0:
                pytest.skip(f"cannot set up namespaces: ip {' '.join(step)}: {done.stderr}")
        yield ns_v, ns_g, addr_v, addr_g
    finally:
        _ip("netns", "del", ns_g)
        _ip("netns", "del", ns_v)  # the veth pair goes with its namespaces


def test_ground_station_in_another_namespace_flies_the_vehicle(namespaces, tmp_path):
    ns_v, ns_g, addr_v, _ = namespaces
    router = f"tcp/{addr_v}:7447"
    url = f"zenoh:netns@{router}"
    py = sys.executable

    def in_ns(ns: str, name: str, *argv: str) -> subprocess.Popen:
        log = (tmp_path / f"{name}.log").open("wb")
        return subprocess.Popen(["ip", "netns", "exec", ns, py, "-m", *argv], cwd=ROOT,
                                stdout=log, stderr=subprocess.STDOUT)

    def gcs(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["ip", "netns", "exec", ns_g, py, "-m", "gcs.cli", *args,
                               "--connect", url, "--wait", "20"], cwd=ROOT,
                              capture_output=True, text=True, timeout=60, check=False)

    procs = [in_ns(ns_v, "router", "gcs.cli", "router", "--listen", router)]
    try:
        until(lambda: procs[0].poll() is not None or "listening on" in
              (tmp_path / "router.log").read_text(), "the router listening")
        assert procs[0].poll() is None, (tmp_path / "router.log").read_text()
        procs += [in_ns(ns_v, "sitl", "sitl.node", str(SCENARIOS / "case1_figure8.toml"),
                        "--link", url, "--end-time", "600", *PACE),
                  in_ns(ns_v, "fcu", "fcu.edge.node", "--vehicle", str(VEHICLE), "--gains",
                        str(PID), "--sim", url, "--gcs", url)]
        status = gcs("status")
        assert status.returncode == 0, status.stderr + (tmp_path / "fcu.log").read_text()
        assert "MAV_TYPE_HEXAROTOR" in status.stdout and "landed: on ground" in status.stdout
        mission = tmp_path / "case1.toml"
        mission.write_text(format_toml(scenario_mission(
            load_scenario(SCENARIOS / "case1_figure8.toml"))))
        assert gcs("mission", "upload", str(mission)).returncode == 0
        assert gcs("mission", "download", "--format", "toml").stdout == mission.read_text()
        assert gcs("arm").returncode == 0
        assert gcs("mission", "start").returncode == 0

        def in_air() -> str:
            out = gcs("status").stdout
            return out if "landed: in air" in out else ""

        flying = until(in_air, "the vehicle in the air after mission start")
        assert "mode: MISSION" in flying and "landed: in air" in flying
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
