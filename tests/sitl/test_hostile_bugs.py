"""Bugs found by fuzzing (tests/unit/test_fuzz_parsers.py, benchmarks/fuzz_campaign.py,
in-process fuzzing of FlightController) in files changed elsewhere (fcu/edge/node.py,
fcu/vehicle.py, sitl/node.py, fcu/edge/telemetry.py): each test shows one with the smallest input
that triggers it. Each failed when written; all pass since commits 674bea7, 8459807,
1ec21fa (velocity and rate bounds, unsendable telemetry skipped) and 6b5a095 (frames cut at
a datagram's end dropped).

* A COMMAND_LONG GET_MESSAGE_INTERVAL whose p1 does not fit uint16 killed the FCU
  (fcu/edge/node.py `FlightController._command`: MESSAGE_INTERVAL(int(p1)) -> struct.error, which
  `_on_gcs_datagram` does not catch).
* An ODOMETRY with a zero quaternion killed the FCU (fcu/vehicle.py `Vehicle.on_state` ->
  fcu/control/dualquat.py `q_normalize` -> ZeroDivisionError, from fcu/edge/node.py
  `_on_sim_datagram`).
* An ODOMETRY 3000 km up (finite, so accepted) killed the FCU at its next telemetry
  (fcu/edge/node.py `_send_message` -> GLOBAL_POSITION_INT alt in int32 mm -> struct.error).
* The FCU took ODOMETRY from any system id as its own state (fcu/edge/node.py
  `_on_sim_datagram` never looked at `Frame.sysid`).
* The simulator took HIL_ACTUATOR_CONTROLS from any system id (sitl/node.py
  `SimulatorServer._answers` never looked at `Frame.sysid`).
* An ODOMETRY with a finite but absurd velocity (3e38 m/s, each component a valid float32)
  and a 45 degree yaw was accepted; the velocity turned into NED no longer fits a float32
  and the next LOCAL_POSITION_NED killed the FCU (fcu/edge/node.py `_housekeeping` ->
  `_send_message` -> `send` -> pack -> OverflowError: float too large to pack with f format).
* A frame cut one byte short at the end of a datagram was completed by the first byte of the
  sender's next datagram (fcu/edge/node.py `_on_gcs_datagram`, one pymavlink stream parser per UDP
  peer): in the campaign a cut MISSION_CLEAR_ALL so completed cleared the mission in flight.
"""

from __future__ import annotations

import math
import socket
import time

import pytest

from common.links import free_port
from common.wire.mavlink import MAV
from common.wire.simlink import (
    ODOMETRY_ID,
    ActuatorControls,
    Odometry,
    pack_actuator_controls,
    pack_odometry,
    split_frames,
    unpack_odometry,
)

from .conftest import SCENARIOS, launch, start, stop

M = MAV
pytestmark = pytest.mark.timeout(60)
LEVEL = (1.0, 0.0, 0.0, 0.0)


class FakeSimulator:
    """The test as the FCU's simulator: an FCU (lockstep, no sitl) whose simulator link is
    udpout to our socket, so our states come from the address it expects."""

    def __init__(self, tmp_path) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.stack = launch(tmp_path, sitl=False, sim_port=self.sock.getsockname()[1])
        self.fcu_addr = None
        deadline = time.monotonic() + 5
        while self.fcu_addr is None and time.monotonic() < deadline:
            for line in self.stack.log("fcu").splitlines():
                if "sim port" in line:
                    self.fcu_addr = ("127.0.0.1", int(line.rsplit(" ", 1)[1]))
            time.sleep(0.05)
        assert self.fcu_addr is not None, self.stack.log("fcu")

    def state(self, t_us: int, p_ned=(0.0, 0.0, -1.0), q=LEVEL, sysid: int = 1) -> None:
        odo = Odometry(t_us, p_ned, q, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self.sock.sendto(pack_odometry(odo, 0, sysid, M.MAV_COMP_ID_PERIPHERAL), self.fcu_addr)

    def fcu_alive_after(self, seconds: float) -> bool:
        """Whether the FCU lives on after a state sent just before: `seconds` in which its
        telemetry (several messages a second) would have packed that state, then a valid
        state with a position of its own, which the FCU reads after the first (one socket,
        in order) and must report in LOCAL_POSITION_NED."""
        time.sleep(seconds)  # deliberate: the window for the crash at the next telemetry
        marker = (0.25, 0.5, -0.75)
        self.state(1_000_000, p_ned=marker)
        heard = self.stack.wait_for(["LOCAL_POSITION_NED"], lambda m: math.dist(
            (m.x, m.y, m.z), marker) < 1e-3, 30.0)
        return heard is not None and self.stack.procs["fcu"].poll() is None

    def close(self) -> None:
        self.stack.session.close()
        stop(self.stack.procs)
        self.sock.close()


@pytest.fixture
def fake_sim(tmp_path):
    sim = FakeSimulator(tmp_path)
    yield sim
    sim.close()


def test_get_message_interval_beyond_uint16_does_not_kill_the_fcu(stack):
    """GET_MESSAGE_INTERVAL(p1 = 70000), or p1 = -1: the FCU ACKs, then packs
    MESSAGE_INTERVAL(message_id = 70000) and dies:
        fcu/edge/node.py _command -> self.send(MAVLink_message_interval_message(msg_id, ...))
        -> struct.error: ushort format requires 0 <= number <= 65535
    Expected: an answer (DENIED, or MESSAGE_INTERVAL with -1) and the FCU alive."""
    s = stack.session
    s.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, 70000.0)
    # The FCU answers commands one after the other: an answer to the next one shows it
    # lived through the first.
    assert s.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, float(M.MAVLINK_MSG_ID_HEARTBEAT),
                     timeout=10.0) == M.MAV_RESULT_ACCEPTED, stack.log("fcu")[-1500:]
    assert stack.procs["fcu"].poll() is None, stack.log("fcu")[-1500:]
    assert stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1, 3.0) is not None


def test_a_zero_quaternion_state_does_not_kill_the_fcu(fake_sim):
    """ODOMETRY with q = (0, 0, 0, 0) (finite, so it passes the NaN check):
        fcu/edge/node.py _on_sim_datagram -> fcu/vehicle.py Vehicle.on_state -> q_normalize
        -> ZeroDivisionError: float division by zero
    Expected: the state is refused (counted) and the FCU keeps running."""
    fake_sim.state(1000, q=(0.0, 0.0, 0.0, 0.0))
    assert fake_sim.fcu_alive_after(1.0), fake_sim.stack.log("fcu")[-1500:]


def test_a_state_far_away_does_not_kill_the_fcu(fake_sim):
    """ODOMETRY 3000 km up (z = -3e6 m, finite): accepted, then the next GLOBAL_POSITION_INT
    cannot be packed:
        fcu/edge/node.py _housekeeping -> _send_message -> send -> pack
        -> struct.error: 'i' format requires -2147483648 <= number <= 2147483647
    (20,000 km north breaks lat the same way.) Expected: such a state refused, or the
    telemetry clamped, and the FCU alive."""
    fake_sim.state(1000, p_ned=(0.0, 0.0, -3e6))
    assert fake_sim.fcu_alive_after(1.0), fake_sim.stack.log("fcu")[-1500:]


def test_a_state_with_an_absurd_velocity_does_not_kill_the_fcu(fake_sim):
    """ODOMETRY v_frd = (3e38, 3e38, 0) m/s, yaw 45 degrees: every field is a valid float32,
    |q| = 1 and |p| < 1e6 m, so the state is accepted; in NED vx = 4.2e38 > float32 max and
        fcu/edge/node.py _housekeeping -> _send_message(LOCAL_POSITION_NED) -> send -> pack
        -> OverflowError: float too large to pack with f format
    Expected: such a state refused (bound the velocity and rates as the position is), or
    the telemetry clamped, and the FCU alive."""
    yaw45 = (math.cos(math.pi / 8), 0.0, 0.0, math.sin(math.pi / 8))
    odo = Odometry(1000, (0.0, 0.0, -1.0), yaw45, (3e38, 3e38, 0.0), (0.0, 0.0, 0.0))
    fake_sim.sock.sendto(pack_odometry(odo, 0, 1, M.MAV_COMP_ID_PERIPHERAL), fake_sim.fcu_addr)
    assert fake_sim.fcu_alive_after(1.0), fake_sim.stack.log("fcu")[-1500:]


def test_states_from_another_system_are_not_taken(fake_sim):
    """The FCU (system 1) takes ODOMETRY from system 42 as its own state: its position
    jumps to the stranger's. Seen in the campaign: ERR_POS 4-7 m while the real vehicle was
    on its path. Expected: frames whose sysid is not ours are ignored (and counted).
        fcu/edge/node.py _on_sim_datagram: `for f in frames: if f.msg_id != ODOMETRY_ID: ...`
        never compares f.sysid with self.system_id."""
    s = fake_sim.stack

    def position_near(p_ned, timeout=3.0):
        return s.wait_for(["LOCAL_POSITION_NED"], lambda m: math.dist(
            (m.x, m.y, m.z), p_ned) < 1e-3, timeout)

    fake_sim.state(1000, p_ned=(1.0, 2.0, -3.0))
    assert position_near((1.0, 2.0, -3.0)) is not None
    fake_sim.state(2000, p_ned=(10.0, 10.0, -10.0), sysid=42)
    assert position_near((10.0, 10.0, -10.0), timeout=1.5) is None, \
        "the FCU took a state from system 42"


def test_the_simulator_takes_commands_only_from_its_own_system(tmp_path):
    """sitl (system 1, lockstep) advances on a HIL_ACTUATOR_CONTROLS from system 42 that
    echoes its state's time: any process on its port drives the plant (seen in real time in
    the campaign: rotors stopped by a stranger, ERR_POS 0.5-0.9 m). Expected: ignored.
        sitl/node.py SimulatorServer._answers never compares f.sysid with self.system_id."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.3)
    port = free_port()
    procs = {"sitl": start("sitl", ["sitl.node", str(SCENARIOS / "case2_impulse.toml"),
                                    "--link", f"udpin:127.0.0.1:{port}", "--hil-sensor-hz",
                                    "0"], tmp_path)}
    try:
        def states(seconds=0.5):
            out = []
            deadline = time.monotonic() + seconds
            while time.monotonic() < deadline:
                try:
                    data, _ = sock.recvfrom(65535)
                except TimeoutError:
                    continue
                out += [unpack_odometry(f.payload).time_usec for f in split_frames(data)[0]
                        if f.msg_id == ODOMETRY_ID]
            return out

        # make ourselves a peer of the simulator, and hear its state at t = 0 (re-sent)
        deadline = time.monotonic() + 10
        seen: list[int] = []
        while not seen and time.monotonic() < deadline:
            sock.sendto(b"hello", ("127.0.0.1", port))
            seen = states(0.3)
        assert seen and set(seen) == {0}, seen
        answer = ActuatorControls(0, (0.0,) * 16, 0, 1)
        sock.sendto(pack_actuator_controls(answer, 1, 42, M.MAV_COMP_ID_AUTOPILOT1),
                    ("127.0.0.1", port))
        after = states(0.5)
        assert after and max(after) == 0, \
            f"the simulator advanced to t = {max(after)} us on a command from system 42"
    finally:
        stop(procs)
        sock.close()


def test_a_frame_cut_short_is_not_completed_by_the_next_datagram(stack, tmp_path):
    """UDP carries whole frames: MISSION_CLEAR_ALL cut one byte short, then a datagram that
    starts with the missing byte, must not clear the mission (found by the fuzz campaign:
    pymavlink parses one byte stream per sender)."""
    from common.config.scenario import load_scenario
    from common.wire.mavlink import encoder, pack
    from gcs.run.scenario_mission import scenario_mission
    from gcs.vehicle_link.mission_client import download, upload

    s = stack.session
    items = scenario_mission(load_scenario(SCENARIOS / "case1_figure8.toml"))
    assert upload(s.conn, 1, 1, items, send=s.send) == M.MAV_MISSION_ACCEPTED
    frame = pack(encoder(255, 190), M.MAVLink_mission_clear_all_message(1, 1, 0))
    with s.lock:
        s.conn.write(frame[:-1])
        s.conn.write(frame[-1:] + b"\x00" * 8)
    # no wait: the download's requests follow on the same socket, read by the FCU in order
    assert len(download(s.conn, 1, 1, send=s.send)) == len(items)
