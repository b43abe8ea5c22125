"""`make bench`: every benchmark, one after the other, printing its figures."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = ("bench_step.py", "bench_flight_core.py", "bench_inprocess.py", "bench_lockstep.py",
              "bench_zenoh.py", "bench_ardupilot_json.py",
              "bench_logs.py", "bench_estimator.py", "bench_estimator_fcu.py",
              "lag_compensation_noise.py",
              "divergence_limit.py", "mission_envelope.py", "bench_mission_length.py",
              "bench_planning.py")

if __name__ == "__main__":
    failed = 0
    for name in BENCHMARKS:
        print(f"== {name}", flush=True)
        failed |= subprocess.run([sys.executable, str(HERE / name)], check=False).returncode
    sys.exit(1 if failed else 0)
