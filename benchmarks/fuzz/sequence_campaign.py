"""The sequence campaign on the GCS ports: inputs the FCU obeys, with probes between them."""

from __future__ import annotations

import random
import time
from collections import Counter, deque
from pathlib import Path

from benchmarks.fuzz.flight import Attack, Flight
from benchmarks.fuzz.gcs_messages import describe
from benchmarks.fuzz.gcs_sequences import GcsSequences
from benchmarks.fuzz.prober import Prober
from benchmarks.fuzz.report import counts_text

Sent = tuple[float, str, bytes]  # an input sent: (wall time, category, datagram)


class SequenceCampaign:
    """The GCS ports' second campaign: `GcsSequences` inputs on link 1 at `rate` per second,
    a probe every `probe_every` inputs, internal errors (STATUSTEXT on the listening link)
    recorded with the inputs sent before them."""

    RING = 400

    def __init__(self, flight: Flight, attack: Attack, seed: int, rate: float,
                 probe_every: int) -> None:
        self.flight = flight
        self.attack = attack
        self.rate = rate
        self.probe_every = max(1, probe_every)
        self.gen = GcsSequences(seed, flight.signing_key)
        self.prober = Prober(flight.gcs_port, flight.listener, flight.signing_key, seed)
        self.rng = random.Random(seed + 2)
        self.ring: deque[Sent] = deque(maxlen=self.RING)
        self.errors: list[tuple[float, str, list[Sent]]] = []  # the first ones, with inputs
        self.error_texts: Counter[str] = Counter()  # every one seen
        self.counts: Counter[str] = Counter()
        self.sequences: Counter[str] = Counter()
        self.in_sequences = 0
        self.sent = 0
        self.not_sent = 0
        self.seconds = 0.0  # sending, probes between inputs excluded
        self.probe_seconds = 0.0
        flight.listener.on_text = self._on_text

    def _on_text(self, t: float, text: str) -> None:
        if "internal error" not in text:
            return
        self.error_texts[text] += 1
        if len(self.errors) < 20:
            self.errors.append((t, text, list(self.ring.copy())))

    def _probe(self, kind: str | None = None) -> None:
        t = time.monotonic()
        self.prober.run(kind)
        self.probe_seconds += time.monotonic() - t

    def run(self, n: int) -> None:
        t0 = time.monotonic()
        paced_from, paced_sent = t0, 0
        next_probe = self.probe_every // 2
        if self.flight.signing_key is not None:
            self._probe("signing")
        fcu = self.flight.procs["fcu"]
        while self.sent < n and fcu.poll() is None:
            if self.sent >= next_probe:
                t = time.monotonic()
                self._probe()
                next_probe += self.probe_every
                paced_from += time.monotonic() - t
            inp = self.gen.next()
            sock = self.rng.choice(self.attack.socks)
            for data in inp.frames[:n - self.sent]:
                try:
                    sock.sendto(data, ("127.0.0.1", self.flight.gcs_port))
                except (BlockingIOError, ConnectionRefusedError):
                    self.not_sent += 1
                self.ring.append((time.time(), inp.category, data))
                self.counts[inp.category] += 1
                self.sent += 1
                paced_sent += 1
                if inp.sequence:
                    self.in_sequences += 1
            if inp.sequence:
                self.sequences[inp.category] += 1
            ahead = paced_sent / self.rate - (time.monotonic() - paced_from)
            if ahead > 0.002:
                time.sleep(ahead)
        self.seconds = time.monotonic() - t0 - self.probe_seconds
        if fcu.poll() is None:  # one probe of each kind after the last input
            for kind in ("set_get", "param", "streams", "heartbeat_off"):
                self._probe(kind)
            if self.flight.signing_key is not None:
                self._probe("signing")

    def report_errors(self, out: Path, detailed: int = 3) -> list[str]:
        """The internal errors seen on the listening link, by text; the first `detailed`
        with the inputs sent just before them (the first 20 with the last RING inputs in
        files beside the flight's logs)."""
        if not self.error_texts:
            return []
        lines = [f"{sum(self.error_texts.values())} STATUSTEXT 'internal error' on the "
                 f"listening link: " + counts_text(dict(self.error_texts.most_common()))]
        for k, (t, text, ring) in enumerate(self.errors):
            path = out / f"internal_error_{k}.txt"
            with path.open("w") as fh:
                fh.write(f"{text}\n")
                for ts, category, data in ring:
                    fh.write(f"{ts - t:+.4f} s {category}: {data.hex()} {describe(data)}\n")
            if k >= detailed:
                continue
            recent = [(ts, c, d) for ts, c, d in ring if t - 2.0 <= ts <= t][-8:]
            lines.append(f"#{k} '{text}' ({path}); last inputs before it:")
            lines += [f"      {ts - t:+.3f} s {c}: {describe(d)[:300]}" for ts, c, d in recent]
        return lines

    def close(self) -> None:
        self.prober.close()
