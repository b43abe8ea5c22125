"""Hostile-input campaign against running processes, while a real flight goes on.

A real-time Case I flight (sitl + fcu processes, mission uploaded with the mission protocol,
armed, MISSION_START) is hit on one port at a time with at least 100,000 inputs:

    gcs   the FCU's first GCS link (`--gcs udpin:127.0.0.1:PORT`: it reads from any sender),
          beside the ground station's own session on the same port
    sim   the FCU's simulator link: through a relay on the link (as a corrupting wire or a
          man in the middle would), plus datagrams sent straight to the FCU's ephemeral sim
          port ("fcu: sim port N") from other sockets
    sitl  the simulator's port (udpin)
    gcs-signed  the GCS link again, the same inputs, with MAVLink 2 signing required

The FCU has two GCS links: the first is attacked, the second (`--gcs
udpout:127.0.0.1:PORT2`) only listens. Nothing is ever sent to it; a listener records every
datagram it brings with its kernel arrival time. Its HEARTBEAT must never stop (no gap of
`--gap-limit`, 2.5 s, or more over the whole flight) and its messages per second show that
no stream went unbounded, whatever happened on the first link.

Non-destructive inputs (every port): random datagrams, valid frames cut short, valid frames
with 1-3 bits flipped (CRC-16 catches every such error), valid frames for or from other
system ids that the target must ignore, and floods (bursts of valid frames at full speed).
A baseline flight without hostile input gives the deadline misses to compare with.

Then, on the GCS ports, in the same flight, a second campaign of `--inputs` inputs that the
FCU reads and obeys, so that the flight's state changes under it: SEQUENCES, where what one
message sets the next one reads,

    set_get          SET_MESSAGE_INTERVAL with extreme, boundary, NaN, +-inf or negative
                     intervals (and ids), then GET_MESSAGE_INTERVAL of the same id
    request_stream   REQUEST_MESSAGE for every requestable id (and some that are not), then
                     SET_MESSAGE_INTERVAL of every stream (all fast, slow, off, default, any)
    mission          MISSION_COUNT then items with extreme fields; uploads cut short or
                     aborted (MISSION_ACK, CLEAR_ALL, another GCS's COUNT, COUNT 0);
                     downloads; set current; valid missions uploaded, armed and started
    param            PARAM_SET then PARAM_REQUEST_READ (by name or index), extreme values
    mode_arm         arm/disarm (forced too), modes (DO_SET_MODE, SET_MODE, NAV_LAND,
                     MISSION_START), offboard set-point streams then OFFBOARD

and single inputs: every message type the FCU handles with random field values (extremes of
each integer type, NaN, +-inf, 0, huge floats, random float32 bit patterns, any bytes in
names), frames with a valid CRC around random payloads of any length, several frames in one
datagram, damaged frames, and the non-destructive categories above. On the signed link they
are signed (a few unsigned, wrongly signed or replayed). The simulator runs in real time
beside the FCU, so arming, mission starts and offboard act on a live state.

Probes check the answers from a socket of their own, each after a sync (the FCU has read
everything sent before): the interval GET reads is the one SET put in force (or the old one
when refused); a parameter read back is the value set (or the old one) and within its range;
every requestable id is answered and no other; with link 1's streams off, some asked at
1 kHz stay within the link budget, and all go back to their defaults; HEARTBEAT turned off
on link 1 stops there and goes on on link 2;
(signed link) a replayed frame is refused, and a frame with a wrong signature cannot lock a
signed stream out.

Printed per flight: inputs sent by category, crashes (a process that exited), the FCU's
deadline misses, rejected bytes and ignored messages (`--stats`), the simulator's rejected
bytes, SYS_STATUS errors_comm, the largest ERR_POS and heartbeat gap during the attack,
whether the mission kept flying, the listening link, the sequence campaign and its probes.
At the end, one summary per port: inputs sent, how many in sequences, whether the FCU was
alive (and its exit code), its `internal_errors`, `ignored_messages` and `rejected_bytes`,
the longest HEARTBEAT gap on the listening link and the messages per second it received.
Exit status 0 only when, on every port, the FCU survived with internal_errors == 0, the
listening link's HEARTBEAT gap stayed below the bound, every probe agreed, and the flight
kept its mission under the non-destructive attack.

    .venv/bin/python benchmarks/fuzz_campaign.py                 # 100,000 inputs per port
    .venv/bin/python benchmarks/fuzz_campaign.py --inputs 20000 --ports gcs,sitl --seed 7
    .venv/bin/python benchmarks/fuzz_campaign.py --ports gcs --seq-rate 4000 --out DIR
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a script: the repository's packages and tests/
    sys.path.insert(0, str(ROOT))

from benchmarks.fuzz.config import CAMPAIGN_PORTS, GAP_LIMIT_S, PORTS  # noqa: E402
from benchmarks.fuzz.report import report_port, report_spoof, summarize  # noqa: E402
from benchmarks.fuzz.runner import run_port, run_spoof  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--inputs", type=int, default=100_000,
                   help="inputs per port (the GCS ports: that many again in sequences)")
    p.add_argument("--rate", type=float, default=5000.0,
                   help="non-destructive inputs per second (average)")
    p.add_argument("--seq-rate", type=float, default=2500.0,
                   help="sequence campaign inputs per second (average)")
    p.add_argument("--probe-every", type=int, default=2000,
                   help="a probe every this many sequence campaign inputs")
    p.add_argument("--gap-limit", type=float, default=GAP_LIMIT_S,
                   help="longest HEARTBEAT gap allowed on the listening link, s")
    p.add_argument("--ports", default=",".join(CAMPAIGN_PORTS),
                   help=f"comma-separated, some of {','.join(CAMPAIGN_PORTS)}")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--no-spoof", action="store_true", help="skip the spoofing findings")
    p.add_argument("--out", type=Path, help="keep the flights' logs here")
    args = p.parse_args(argv)
    ports = [x for x in args.ports.split(",") if x]
    if any(x not in CAMPAIGN_PORTS for x in ports):
        p.error(f"--ports: expected some of {','.join(CAMPAIGN_PORTS)}")
    if args.inputs < 0 or args.rate <= 0 or args.seq_rate <= 0:
        p.error("--inputs must be >= 0, --rate and --seq-rate > 0")
    tmp = None
    if args.out is None:
        tmp = tempfile.TemporaryDirectory(prefix="fuzz_campaign_")
        out = Path(tmp.name)
    else:
        out = args.out
    results: list[tuple[dict[str, Any], bool]] = []
    try:
        base = run_port(None, out / "baseline", 0, args.rate, args.seed,
                        baseline_s=max(args.inputs / args.rate, 5.0))
        results.append((base, report_port(base)))
        for port in ports:  # the signed GCS link gets the very inputs of the unsigned one
            seed = args.seed + PORTS.index(port.removesuffix("-signed"))
            r = run_port(port, out / port, args.inputs, args.rate, seed,
                         seq_rate=args.seq_rate, probe_every=args.probe_every)
            results.append((r, report_port(r)))
        if not args.no_spoof:
            for kind in ("states", "commands"):
                report_spoof(run_spoof(kind, out / f"spoof_{kind}"))
        failed = [(r["port"], summarize(r, ok, args.gap_limit)) for r, ok in results]
    finally:
        if tmp is not None:
            tmp.cleanup()
    bad = [f"{port}: {'; '.join(why)}" for port, why in failed if why]
    print("campaign:", "every port passed (fcu alive, no internal error, listening link's "
          "heartbeat within the bound, probes agreed, mission kept)" if not bad else
          "FAILED: " + " | ".join(bad))
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
