"""`sitl --protocol ardupilot-json` against a scripted ArduPilot side on loopback, both on one
CPU: servo packets at ArduCopter's 1200 Hz, each sent when the previous one is answered (as
ArduPilot does), motors at a hover-ish PWM so that the plant flies (rotor lag, RK4, ground
contact off the ground), with the truth log written. Printed: frames per wall second, the
real-time factor (simulated / wall time; target >= 2 on one core) and the round trip per
frame.

    python -m benchmarks.bench_ardupilot_json [FRAMES]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common.links import free_port

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "config" / "scenarios" / "ardupilot_hexa.toml"
RATE_HZ = 1200
TARGET = 2.0


def run(frames: int) -> dict[str, Any]:
    cpu = min(os.sched_getaffinity(0))
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        stats = Path(tmp) / "stats.json"
        sitl = subprocess.Popen(
            ["taskset", "-c", str(cpu), sys.executable, "-m", "sitl.node", str(SCENARIO),
             "--protocol", "ardupilot-json", "--link", f"udpin:127.0.0.1:{port}",
             "--truth-log", str(Path(tmp) / "truth.ulg"), "--stats", str(stats)],
            cwd=ROOT, stdout=subprocess.PIPE, text=True)
        os.sched_setaffinity(0, {cpu})
        try:
            assert sitl.stdout is not None
            line = sitl.stdout.readline()
            if "sitl: serving" not in line:
                raise RuntimeError(f"sitl did not start: {line!r}")
            ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            ap.settimeout(5.0)
            target = ("127.0.0.1", port)
            hover = (1590,) * 6 + (1000,) * 10
            start = time.perf_counter()
            for n in range(frames):
                ap.sendto(struct.pack("<HHI16H", 18458, RATE_HZ, n, *hover), target)
                ap.recv(4096)
            wall = time.perf_counter() - start
            ap.close()
        finally:
            sitl.terminate()
            sitl.wait(30)
        st = json.loads(stats.read_text())
    sim_s = st["steps"] * st["step_us"] * 1e-6
    return {"frames": frames, "wall_s": wall, "frames_per_s": frames / wall,
            "real_time_factor": sim_s / wall, "round_trip_us": wall / frames * 1e6,
            "cpu": cpu}


def main(frames: int = 60_000) -> dict[str, Any]:
    return run(frames)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("frames", nargs="?", type=int, default=60_000)
    r = main(p.parse_args().frames)
    print(f"ardupilot-json on one CPU (cpu {r['cpu']}): {r['frames']} frames at {RATE_HZ} Hz "
          f"in {r['wall_s']:.2f} s = {r['frames_per_s']:.0f} frames/s, "
          f"{r['real_time_factor']:.1f}x real time (target >= {TARGET:g}: "
          f"{'met' if r['real_time_factor'] >= TARGET else 'not met'}); "
          f"{r['round_trip_us']:.0f} us per frame")
    sys.exit(0 if r["real_time_factor"] >= TARGET else 1)
