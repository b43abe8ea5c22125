"""Full-stack lockstep: Case I through sitl + fcu processes over UDP, beside the bare UDP
round trip between two Python processes measured in the same run.

Prints the real-time factor (target >= 10x on 2 cores), the wall time per control step and
its ratio to the bare round trip (target <= 2.5x).
"""

from __future__ import annotations

import dataclasses
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common.config import load_scenario
from gcs.process_run import run_processes

ROOT = Path(__file__).resolve().parent.parent
ECHO = """
import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind(("127.0.0.1", 0))
print(s.getsockname()[1], flush=True)
while True:
    data, addr = s.recvfrom(2048)
    if data == b"stop":
        break
    s.sendto(data, addr)
"""


def udp_round_trip_us(n: int = 20000) -> float:
    """Median round trip of a 250-byte datagram to an echo in another Python process."""
    echo = subprocess.Popen([sys.executable, "-c", ECHO], stdout=subprocess.PIPE, text=True)
    try:
        port = int(echo.stdout.readline())
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.connect(("127.0.0.1", port))
        payload = bytes(250)
        samples = []
        for _ in range(n):
            t0 = time.perf_counter_ns()
            s.send(payload)
            s.recv(2048)
            samples.append((time.perf_counter_ns() - t0) / 1000.0)
        s.send(b"stop")
        s.close()
        return statistics.median(samples)
    finally:
        echo.wait(timeout=5)


def main(duration_s: float | None = None) -> dict[str, float]:
    rtt = udp_round_trip_us()
    scenario = load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml")
    if duration_s is not None:
        scenario = dataclasses.replace(scenario, duration_s=duration_s)
    with tempfile.TemporaryDirectory() as tmp:
        m = run_processes(scenario, Path(tmp))
    steps = m["samples"]
    per_step_us = m["wall_time_s"] / max(steps, 1) * 1e6
    return {"real_time_factor": m["real_time_factor"], "sim_time_s": m["sim_time_s"],
            "wall_time_s": m["wall_time_s"], "per_step_us": per_step_us,
            "udp_round_trip_us": rtt, "ratio": per_step_us / rtt,
            "fcu_step_p50_us": m["fcu_step_us"]["p50"]}


if __name__ == "__main__":
    r = main(float(sys.argv[1]) if len(sys.argv) > 1 else None)
    print(f"lockstep Case I over UDP: {r['sim_time_s']:.0f} s simulated in "
          f"{r['wall_time_s']:.1f} s = {r['real_time_factor']:.1f}x real time (target >= 10x)")
    print(f"  per control step {r['per_step_us']:.0f} us wall; bare UDP round trip "
          f"{r['udp_round_trip_us']:.0f} us; ratio {r['ratio']:.2f} (target <= 2.5); "
          f"FCU step p50 {r['fcu_step_p50_us']:.0f} us")
