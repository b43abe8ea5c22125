"""The 1,000-run Case II campaign (magnitude x direction x controller) with its envelope
report, on a local Dask cluster, then (with --scheduler-check) the same campaign on a
`dask scheduler` and two `dask worker` processes started here on 127.0.0.1, whose results
table must equal the first one's (timing columns aside).

    python benchmarks/campaign_envelope.py [--out DIR] [--workers N] [--scheduler-check]

Prints the aggregate throughput in simulated seconds per wall second (target: >= 300 on 2
cores), counting from the first submitted run to the last result (the cluster's start-up
apart, printed too).
"""

from __future__ import annotations

import argparse
import csv
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common.links import free_port
from gcs.campaign.load import load_campaign
from gcs.campaign.run import run_campaign

HERE = Path(__file__).resolve().parent
CAMPAIGN = HERE / "case2_envelope_1000.toml"
TIMING = ("wall_time_s", "real_time_factor", "run_wall_s", "fcu_step_us", "compile_time_s")


def flight_table(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open() as fh:
        return [{k: v for k, v in r.items() if not k.startswith(TIMING)}
                for r in csv.DictReader(fh)]


def fly(out: Path, **kwargs: Any) -> dict[str, float]:
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.monotonic()
    outcome = run_campaign(load_campaign(CAMPAIGN), out, **kwargs)
    total = time.monotonic() - t0
    ok = sum(r.get("status") == "completed" for r in outcome.rows)
    return {"runs": float(len(outcome.rows)), "completed": float(ok),
            "not_executed": float(len(outcome.failed)), "sim_s": outcome.sim_s,
            "campaign_wall_s": outcome.wall_s, "total_wall_s": total,
            "throughput": outcome.sim_s / outcome.wall_s, "workers": float(outcome.workers)}


def external_cluster(logs: Path) -> tuple[str, list[subprocess.Popen[bytes]]]:
    port = free_port(socket.SOCK_STREAM)
    address = f"tcp://127.0.0.1:{port}"
    procs: list[subprocess.Popen[bytes]] = []
    for name, argv in (("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", str(port),
                                      "--no-dashboard"]),
                       ("worker0", ["worker", address, "--nthreads", "1", "--host",
                                    "127.0.0.1", "--no-dashboard"]),
                       ("worker1", ["worker", address, "--nthreads", "1", "--host",
                                    "127.0.0.1", "--no-dashboard"])):
        with (logs / f"{name}.log").open("wb") as fh:
            procs.append(subprocess.Popen([sys.executable, "-m", "dask", *argv],
                                          stdout=fh, stderr=subprocess.STDOUT))
        time.sleep(1.0 if name == "scheduler" else 0.0)
    from dask.distributed import Client

    connect: Any = Client  # distributed's constructors are not annotated
    with connect(address, timeout=30) as client:
        client.wait_for_workers(2, timeout=60)
    return address, procs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="campaign folder (default: temp)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler-check", action="store_true",
                    help="fly it again on a separate scheduler and two workers; compare")
    args = ap.parse_args()
    root = args.out or Path(tempfile.mkdtemp(prefix="campaign-bench-"))
    local = root / "local"
    r = fly(local, workers=args.workers, dashboard=None)
    print(f"local cluster ({int(r['workers'])} workers): {int(r['runs'])} runs "
          f"({int(r['completed'])} completed, {int(r['not_executed'])} not executed), "
          f"{r['sim_s']:.0f} simulated s in {r['campaign_wall_s']:.1f} s = "
          f"{r['throughput']:.1f} simulated s per wall s (target >= 300); "
          f"{r['total_wall_s']:.1f} s with the cluster's start and the report")
    print(f"  envelope report: {local / 'summary.md'}, {local / 'envelope.png'}")
    status = 0 if r["runs"] >= 1000 and not r["not_executed"] else 1
    if args.scheduler_check:
        logs = root / "cluster_logs"
        logs.mkdir(parents=True, exist_ok=True)
        address, procs = external_cluster(logs)
        try:
            e = fly(root / "external", scheduler=address)
        finally:
            for p in procs:
                p.terminate()
            for p in procs:
                try:
                    p.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    p.kill()
        same = flight_table(local) == flight_table(root / "external")
        print(f"dask scheduler + 2 dask workers at {address}: {int(e['runs'])} runs in "
              f"{e['campaign_wall_s']:.1f} s = {e['throughput']:.1f} simulated s per wall s; "
              f"results table {'identical' if same else 'DIFFERENT'} to the local one")
        status |= 0 if same else 1
    return status


if __name__ == "__main__":
    sys.exit(main())
