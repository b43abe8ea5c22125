"""Zenoh fabric benchmarks.

1. Lockstep Case I over Zenoh (GCS and simulator links) against UDP, in one run: real-time
   factors and their ratio.
2. Telemetry fan-out through a router: MAVLink frames (SYSTEM_TIME stamped with the send
   time) published at a fixed rate, delivered to 1, 4 and 16 subscribers in their own
   processes: frames per second per subscriber and latency p50/p99.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
RATE_HZ = 2000
SECONDS = 3.0


def lockstep(duration_s: float, router: str) -> dict[str, float]:
    from common.config.scenario import load_scenario
    from gcs.run.process_run import one_vehicle, run_processes

    sc = dataclasses.replace(load_scenario(ROOT / "config/scenarios/case1_figure8.toml"),
                             duration_s=duration_s)
    with tempfile.TemporaryDirectory() as tmp:
        udp = one_vehicle(run_processes(sc, Path(tmp) / "udp"))
        zen = one_vehicle(run_processes(sc, Path(tmp) / "zenoh", transport="zenoh",
                                        zenoh_url=f"zenoh:bench@{router}"))
    return {"udp_rtf": udp["real_time_factor"], "zenoh_rtf": zen["real_time_factor"],
            "same_figures": udp["position_error_m"] == zen["position_error_m"]}


def _subscriber(router: str, ready: Any, results: Any, seconds: float) -> None:
    import zenoh

    from common.links.zenoh_link import client_config
    from common.wire.mavlink import parser

    session: Any = zenoh.open(client_config([router]))  # zenoh 1.x: partly annotated
    mav = parser()
    latencies: list[float] = []

    def on_sample(sample: Any) -> None:
        now = time.time_ns() // 1000
        for msg in mav.parse_buffer(sample.payload.to_bytes()) or []:
            latencies.append(now - msg.time_unix_usec)

    sub = session.declare_subscriber("fanout/1/out", on_sample)
    ready.set()
    time.sleep(seconds)
    sub.undeclare()
    session.close()
    results.put(latencies)


def fanout(router: str, subscribers: int) -> dict[str, float]:
    import zenoh

    from common.links.zenoh_link import client_config
    from common.wire.mavlink import MAV, encoder, pack

    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    readies = [ctx.Event() for _ in range(subscribers)]
    procs = [ctx.Process(target=_subscriber, args=(router, r, results, SECONDS + 3.0))
             for r in readies]
    for p in procs:
        p.start()
    for r in readies:
        r.wait(30)
    time.sleep(0.5)
    session: Any = zenoh.open(client_config([router]))  # zenoh 1.x: partly annotated
    pub = session.declare_publisher("fanout/1/out", express=True)
    mav = encoder(1, 1)
    period = 1.0 / RATE_HZ
    t0 = time.perf_counter()
    sent = 0
    while time.perf_counter() - t0 < SECONDS:
        target = t0 + sent * period
        while time.perf_counter() < target:
            pass
        pub.put(pack(mav, MAV.MAVLink_system_time_message(time.time_ns() // 1000, 0)))
        sent += 1
    session.close()
    lats = [results.get(timeout=60) for _ in procs]
    for p in procs:
        p.join()
    all_lat = sorted(x for lat in lats for x in lat)
    delivered = [len(lat) for lat in lats]
    return {"sent": sent, "fps_per_subscriber": sum(delivered) / len(delivered) / SECONDS,
            "delivered_ratio": sum(delivered) / (sent * subscribers),
            "latency_p50_us": all_lat[len(all_lat) // 2] if all_lat else float("nan"),
            "latency_p99_us": all_lat[int(0.99 * len(all_lat))] if all_lat else float("nan")}


def main(duration_s: float = 160.0) -> None:
    sys.path.insert(0, str(ROOT))
    from common.links import free_port
    from common.links.zenoh_link import router_running

    router = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "router", "--listen", router],
                            cwd=ROOT, stdout=subprocess.DEVNULL)
    try:
        while not router_running(router):
            time.sleep(0.05)
        r = lockstep(duration_s, router)
        print(f"lockstep Case I ({duration_s:.0f} s): UDP {r['udp_rtf']:.1f}x, Zenoh "
              f"{r['zenoh_rtf']:.1f}x real time; Zenoh/UDP = "
              f"{r['zenoh_rtf'] / r['udp_rtf']:.2f}; identical figures: {r['same_figures']}")
        for n in (1, 4, 16):
            f = fanout(router, n)
            print(f"fan-out to {n:2d} subscribers: {f['fps_per_subscriber']:7.0f} frames/s each "
                  f"(published {RATE_HZ}/s, delivered {100 * f['delivered_ratio']:.1f} %), "
                  f"latency p50 {f['latency_p50_us']:.0f} us, p99 {f['latency_p99_us']:.0f} us")
    finally:
        proc.terminate()
        proc.wait()


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 160.0)
