"""The simulator link's relay for a hostile flight: a process of its own between the FCU
(the client, who sends to `port`) and the simulator, that also sends what the attack hands it
on as if it came through the link (a corrupting wire, a man in the middle).

A process and not a thread of the attacking program: a thread there must hold the
interpreter's lock to forward each datagram, and the attack's threads hold it in turn. On a
busy machine one of them can be descheduled while holding it, and the relay, although at
SCHED_FIFO, then waits on a thread at normal priority. The flight's states stopped for up
to a quarter of a second that way, and the FCU's position error grew to 0.2 m in a test that
judges the FCU, not the relay.

    python -m benchmarks.fuzz.relay SERVER_PORT [--rt-priority N]

prints `relay: port P inject I` when it listens, and on SIGTERM its counters as one JSON
line.
"""

from __future__ import annotations

import argparse
import json
import select
import signal
import socket
import subprocess
import sys
from typing import Any

from benchmarks.fuzz.config import ROOT
from common.process.parent import child_env, stop_with_parent
from common.process.realtime import request_fifo

PRIORITY = 48  # below the FCU's loop (50) and the simulator's (49): a wire between them
READY = "relay: port "
START_TIMEOUT_S = 30.0


def _socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


def serve(server_port: int, priority: int) -> dict[str, int]:
    """Relay until SIGTERM; the counters."""
    server = ("127.0.0.1", server_port)
    front, back, inject = _socket(), _socket(), _socket()
    client: tuple[str, int] | None = None
    counts = {"to_server": 0, "to_client": 0, "injected": 0, "injected_before_client": 0,
              "send_errors": 0}
    stopping = False

    def stop(_signum: int, _frame: object) -> None:
        nonlocal stopping
        stopping = True

    signal.signal(signal.SIGTERM, stop)
    refused = request_fifo(priority) if priority else ""
    print(f"{READY}{front.getsockname()[1]} inject {inject.getsockname()[1]}"
          + (f" (normal priority: {refused})" if refused else ""), flush=True)
    while not stopping:
        try:
            readable, _, _ = select.select([inject, front, back], [], [], 0.05)
        except InterruptedError:
            continue
        for sock in readable:
            try:
                data, addr = sock.recvfrom(65535)
                if sock is front:
                    client = addr
                    back.sendto(data, server)
                    counts["to_server"] += 1
                elif client is None:
                    counts["injected_before_client"] += int(sock is inject)
                else:
                    front.sendto(data, client)
                    counts["to_client" if sock is back else "injected"] += 1
            except OSError:  # a full buffer or a peer not there yet: lost, as on a wire
                counts["send_errors"] += 1
    for s in (front, back, inject):
        s.close()
    return counts


class Relay:
    """The relay process, started and stopped from the attacking program. `port` is where
    the FCU's simulator link sends; `inject(data)` hands a datagram to the relay, which sends
    it to the FCU from the simulator's side of the link (dropped until the FCU has sent)."""

    def __init__(self, server_port: int, priority: int = PRIORITY) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.fuzz.relay", str(server_port),
             "--rt-priority", str(priority)],
            cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True,
            env=child_env())
        assert self.proc.stdout is not None  # a pipe was asked for
        said, _, _ = select.select([self.proc.stdout], [], [], START_TIMEOUT_S)
        line = self.proc.stdout.readline() if said else "(nothing within "\
            f"{START_TIMEOUT_S:g} s)"
        if not line.startswith(READY):
            self.proc.kill()
            self.proc.wait()
            raise RuntimeError(f"the relay did not start: {line!r}")
        words = line[len(READY):].split()
        self.port, self.inject_port = int(words[0]), int(words[2])
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.counts: dict[str, Any] = {}

    def inject(self, data: bytes) -> bool:
        """False when it could not be handed over (a full buffer drops it, as a wire would)."""
        try:
            self.sock.sendto(data, ("127.0.0.1", self.inject_port))
        except (BlockingIOError, ConnectionRefusedError):
            return False
        return True

    def close(self) -> dict[str, Any]:
        """Stop the relay; its counters (empty if it did not say them)."""
        self.sock.close()
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            out, _ = self.proc.communicate(timeout=5.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, _ = self.proc.communicate()
        for line in reversed((out or "").splitlines()):
            if line.startswith("{"):
                self.counts = json.loads(line)
                break
        return self.counts


def main(argv: list[str] | None = None) -> int:
    stop_with_parent()
    p = argparse.ArgumentParser(prog="python -m benchmarks.fuzz.relay", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("server_port", type=int, help="the simulator's UDP port on 127.0.0.1")
    p.add_argument("--rt-priority", type=int, default=PRIORITY,
                   help=f"SCHED_FIFO priority where granted, 0: normal (default {PRIORITY})")
    args = p.parse_args(argv)
    print(json.dumps(serve(args.server_port, args.rt_priority)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
