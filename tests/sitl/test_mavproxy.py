"""MAVProxy as the ground station of the FCU: a real `mavproxy.py` process on a second GCS
link, driven through its command line on stdin (no GUI modules, no logs: `--no-state`),
with its default modules and `gcs.mavproxy_px4modes` (which makes its `mode NAME` work with
PX4's mode table, README). The FCU's own HEARTBEAT, seen by the test's Session, confirms
each mode change."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from common.links import free_port
from common.wire.mavlink import MAV
from common.wire.modes import Mode

from .conftest import launch, stop
from .waits import FlightClock, flight_wait, until_progressing

M = MAV
MAVPROXY = Path(sys.executable).parent / "mavproxy.py"
pytestmark = [pytest.mark.timeout(180),
              pytest.mark.skipif(not MAVPROXY.exists(), reason="MAVProxy not installed")]


class MavProxy:
    """mavproxy.py on `udpin:127.0.0.1:PORT`; its output collected by a thread."""

    def __init__(self, port: int, cwd: Path, modules: tuple[str, ...]) -> None:
        argv = [str(MAVPROXY), f"--master=udpin:127.0.0.1:{port}", "--no-state"]
        for module in modules:
            argv += ["--load-module", module]
        self.proc = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        self.out = ""
        self.lock = threading.Lock()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        while True:
            chunk = os.read(fd, 4096)
            if not chunk:
                return
            with self.lock:
                self.out += chunk.decode(errors="replace")

    def text(self) -> str:
        with self.lock:
            return self.out

    def send(self, line: str) -> int:
        """Type a command; returns the output's length before it (to search after)."""
        mark = len(self.text())
        assert self.proc.stdin is not None
        self.proc.stdin.write((line + "\n").encode())
        self.proc.stdin.flush()
        return mark

    def wait_for(self, needle: str, since: int = 0, timeout: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if needle in self.text()[since:]:
                return True
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        return needle in self.text()[since:]

    def flown_to(self, needle: str, since: int, clock: FlightClock, within_s: float) -> bool:
        """Whether `needle` appears after `since` within `within_s` of the flight's time
        (simulated in lockstep), waited for while the flight clock advances."""
        until_progressing(lambda: needle in self.text()[since:], clock, repr(needle),
                          within=within_s, stall_s=30.0, ceiling_s=600.0)
        return True

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.reader.join(timeout=5)


def _mode(stack, mode: Mode, armed: bool, timeout: float = 10.0):
    """The FCU's next HEARTBEAT in `mode` and arming state (the test's own Session)."""
    return stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                          m.custom_mode == mode.custom_mode and
                          bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED) == armed, timeout)


def _at(stack, ned: tuple[float, float, float], within_s: float = 10.0):
    """The FCU's next LOCAL_POSITION_NED within 5 cm of `ned`, within `within_s` of the
    flight's time."""
    return flight_wait(stack, ["LOCAL_POSITION_NED"], lambda m: max(
        abs(m.x - ned[0]), abs(m.y - ned[1]), abs(m.z - ned[2])) < 0.05, f"at {ned}",
        within_s=within_s)


@pytest.mark.timeout(1200)  # a ceiling: the flight is waited for while it advances
def test_mavproxy_names_and_changes_px4_modes(tmp_path):
    """Given MAVProxy (default modules) on a second link of the FCU (Case I, on the ground),
    then it names the mode LOITER (prompt and mode printout) and prints no fence warning at
    connect; `mode MISSION` without a mission and `mode POSCTL` without MANUAL_CONTROL are
    refused (DENIED) and the FCU stays in HOLD; armed, `mode TAKEOFF` climbs and holds
    (LOITER), `mode RTL` returns, lands and disarms, `mode LOITER` holds: each change seen in
    the FCU's HEARTBEAT and in MAVProxy's prompt."""
    port = free_port()
    stack = launch(tmp_path, "case1_figure8", fcu_args=("--gcs", f"udpout:127.0.0.1:{port}"))
    mp = MavProxy(port, tmp_path, ("gcs.mavproxy_px4modes",))
    try:
        assert mp.wait_for("LOITER>", timeout=30), mp.text()
        assert "Mode LOITER" in mp.text()
        # Deliberate: 3 s and at least three SYS_STATUS from the vehicle (the test's own link
        # hears them as MAVProxy's does): the fence module would have spoken by then.
        heard, quiet_until = 0, time.monotonic() + 3.0
        while heard < 3 or time.monotonic() < quiet_until:
            assert stack.wait_for(["SYS_STATUS"], timeout=30.0) is not None, \
                "no SYS_STATUS from the vehicle in 30 s"
            heard += 1
        assert "fence" not in mp.text().lower(), mp.text()

        mark = mp.send("mode MISSION")
        assert mp.wait_for("DO_SET_MODE: DENIED", mark), mp.text()[mark:]
        assert mp.wait_for("no mission", mark), mp.text()[mark:]
        mark = mp.send("mode POSCTL")
        assert mp.wait_for("DO_SET_MODE: DENIED", mark), mp.text()[mark:]
        assert _mode(stack, Mode.HOLD, armed=False, timeout=3.0) is not None

        mark = mp.send("arm throttle")
        assert mp.wait_for("ARMED", mark), mp.text()[mark:]
        mark = mp.send("mode TAKEOFF")
        assert mp.wait_for("DO_SET_MODE: ACCEPTED", mark), mp.text()[mark:]
        clock = FlightClock(stack.session)
        assert mp.flown_to("takeoff complete", mark, clock, 20.0), mp.text()[mark:]
        assert _mode(stack, Mode.HOLD, armed=True) is not None
        assert _at(stack, (0.0, 0.0, -2.5)) is not None  # MIS_TAKEOFF_ALT

        mark = mp.send("mode RTL")
        assert mp.wait_for("RTL>", mark), mp.text()[mark:]
        assert _mode(stack, Mode.RTL, armed=True) is not None
        assert mp.flown_to("DISARMED", mark, clock, 60.0), mp.text()[mark:]
        assert _mode(stack, Mode.RTL, armed=False) is not None
        assert _at(stack, (0.0, 0.0, 0.0)) is not None

        mark = mp.send("mode LOITER")
        assert mp.wait_for("LOITER>", mark), mp.text()[mark:]
        assert _mode(stack, Mode.HOLD, armed=False) is not None
        out = mp.text()
        assert "ERROR in command" not in out and "fence" not in out.lower(), out
    finally:
        mp.close()
        stack.session.close()
        stop(stack.procs)
