"""Zenoh links (common/links/zenoh_link.py) under a flood: the queue fed by Zenoh's threads is
bounded (the oldest samples go, counted), recv() returns bounded batches, and the pipe
that wakes the caller's select never loses a wakeup. A router of the test's own runs in
this process on a free port of 127.0.0.1; multicast scouting is off everywhere."""

from __future__ import annotations

import select
import socket
import threading
import time
from collections.abc import Iterator

import pytest
import zenoh

from common.links import RECV_BATCH, free_port, parse_url
from common.links.zenoh_link import MAX_QUEUE, ZenohLink, client_config, router_running, run_router

pytestmark = pytest.mark.timeout(120)

FLOOD = 20_000


@pytest.fixture(scope="module")
def router() -> Iterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    stop = threading.Event()
    thread = threading.Thread(target=run_router, args=([endpoint], stop), daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 10
        while not router_running(endpoint):
            assert thread.is_alive() and time.monotonic() < deadline, "router did not start"
            time.sleep(0.05)
        yield endpoint
    finally:
        stop.set()
        thread.join(timeout=10)


@pytest.fixture
def session(router) -> Iterator[zenoh.Session]:
    s = zenoh.open(client_config([router]))
    try:
        yield s
    finally:
        s.close()


def _vehicle(router: str, prefix: str, **kw) -> ZenohLink:
    return ZenohLink(parse_url(f"zenoh:{prefix}@{router}"), role="vehicle", system_id=1, **kw)


def _readable(link: ZenohLink, timeout: float) -> bool:
    return bool(select.select([link.fileno()], [], [], timeout)[0])


def _publisher(session: zenoh.Session, key: str):
    # BLOCK: Zenoh itself drops nothing, so every drop is the link's and can be counted.
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)


def _until_heard(link: ZenohLink, pub) -> None:
    """Publish probes until the subscription has reached the router; then drain them."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        pub.put(b"probe")
        if _readable(link, 0.1) and link.recv():
            break
    else:
        pytest.fail("the link never heard the publisher")
    time.sleep(0.2)
    while link.recv():
        pass


class _Peak:
    """Samples link.queued from another thread while a flood runs."""

    def __init__(self, link: ZenohLink) -> None:
        self.link, self.peak, self.samples = link, 0, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, self.link.queued)
            self.samples += 1
            time.sleep(0.0005)

    def stop(self) -> int:
        self._stop.set()
        self._thread.join()
        return self.peak


def test_flood_is_bounded_oldest_dropped_and_read_in_batches(router, session):
    link = _vehicle(router, "flood1")
    try:
        assert link.max_queue == MAX_QUEUE == 1024
        pub = _publisher(session, "flood1/1/in")
        _until_heard(link, pub)
        peak = _Peak(link)
        t0 = time.perf_counter()
        for i in range(FLOOD):
            pub.put(i.to_bytes(4, "big"))
        put_s = time.perf_counter() - t0
        deadline = time.monotonic() + 20
        while link.dropped_samples + link.queued < FLOOD and time.monotonic() < deadline:
            time.sleep(0.02)  # the last samples may still be on their way
        arrived_s = time.perf_counter() - t0
        highest = peak.stop()
        assert highest <= MAX_QUEUE and link.queued == MAX_QUEUE
        assert link.dropped_samples == FLOOD - MAX_QUEUE

        batches, got = [], []
        t1 = time.perf_counter()
        while link.queued:
            assert _readable(link, 0.0)  # the pipe says so after every partial drain
            batch = link.recv()
            batches.append(len(batch))
            got += [int.from_bytes(d, "big") for _, d in batch]
        drain_s = time.perf_counter() - t1
        assert not _readable(link, 0.0) and link.recv() == []
        assert max(batches) == RECV_BATCH and sum(batches) == MAX_QUEUE
        assert got == list(range(FLOOD - MAX_QUEUE, FLOOD))  # the newest, in order

        pub.put(b"fresh")
        assert _readable(link, 2.0)
        assert link.recv() == [("flood1/1/in", b"fresh")]
        print(f"\n{FLOOD} puts in {put_s:.2f} s, all arrived after {arrived_s:.2f} s; "
              f"peak queue {highest} ({peak.samples} samples); dropped "
              f"{link.dropped_samples}; drained in {len(batches)} recv() calls, "
              f"{drain_s * 1e3:.1f} ms")
    finally:
        link.close()


def test_reader_during_a_flood_never_misses_a_wakeup(router, session):
    """The caller sleeps in select() on fileno() and calls recv() only when it is readable,
    as the FCU does: it must see every sample left in the queue, and the last one."""
    link = _vehicle(router, "flood2")
    try:
        pub = _publisher(session, "flood2/1/in")
        _until_heard(link, pub)
        peak = _Peak(link)

        def flood() -> None:
            for i in range(FLOOD):
                pub.put(i.to_bytes(4, "big"))
            pub.put(b"last")

        thread = threading.Thread(target=flood)
        t0 = time.perf_counter()
        thread.start()
        received, calls, biggest, last = 0, 0, 0, False
        longest_call = 0.0
        deadline = time.monotonic() + 60
        while not last and time.monotonic() < deadline:
            if not _readable(link, 1.0):
                assert link.queued == 0, "samples waiting but the pipe is not readable"
                continue
            t = time.perf_counter()
            batch = link.recv()
            longest_call = max(longest_call, time.perf_counter() - t)
            calls += 1
            biggest = max(biggest, len(batch))
            received += len(batch)
            last = any(d == b"last" for _, d in batch)
        elapsed = time.perf_counter() - t0
        thread.join()
        highest = peak.stop()
        assert last and biggest <= RECV_BATCH and highest <= MAX_QUEUE
        assert received + link.dropped_samples == FLOOD + 1
        print(f"\nconcurrent reader: {received} received, {link.dropped_samples} dropped, "
              f"{calls} recv() calls, largest batch {biggest}, slowest recv "
              f"{longest_call * 1e3:.2f} ms, peak queue {highest}, {elapsed:.2f} s")
    finally:
        link.close()


class _Sample:
    def __init__(self, data: bytes) -> None:
        self.key_expr = "k"
        self.payload = self
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


def test_callbacks_on_many_threads_lose_no_wakeup_and_count_every_drop(router):
    """Zenoh may call back from several threads at once: with a small queue, every sample
    is either received or counted as dropped, and the pipe never holds more than a byte."""
    link = _vehicle(router, "flood3", max_queue=64)
    per_thread, threads = 20_000, 4
    try:
        def feed(t: int) -> None:
            for i in range(per_thread):
                link._on_sample(_Sample(bytes([t]) + i.to_bytes(4, "big")))

        workers = [threading.Thread(target=feed, args=(t,)) for t in range(threads)]
        for w in workers:
            w.start()
        received, stalls = 0, 0
        last_seen = [-1] * threads
        while any(w.is_alive() for w in workers) or link.queued:
            if not _readable(link, 0.5):
                stalls += link.queued > 0
                continue
            batch = link.recv()
            assert len(batch) <= RECV_BATCH
            for _, d in batch:
                t, i = d[0], int.from_bytes(d[1:], "big")
                assert i > last_seen[t]  # each thread's samples in order
                last_seen[t] = i
            received += len(batch)
        for w in workers:
            w.join()
        assert stalls == 0
        assert received + link.dropped_samples == threads * per_thread
        assert link.dropped_samples > 0 and not _readable(link, 0.0)
        print(f"\n{threads} feeding threads: {received} received, "
              f"{link.dropped_samples} dropped")
    finally:
        link.close()


def test_liveliness_wakeup_without_samples_is_cleared_by_recv(router):
    link = _vehicle(router, "flood4")
    try:
        link._on_sample_wakeup()
        link._on_sample_wakeup()
        assert _readable(link, 0.0)
        assert link.recv() == []
        assert not _readable(link, 0.0)
    finally:
        link.close()
    link._on_sample(_Sample(b"late"))  # a callback after close writes nowhere
    assert link.fileno() == -1


def test_sends_while_another_thread_retargets_and_closes(router):
    """A ground station's heartbeat thread sends while the caller picks another vehicle
    (set_target undeclares the old publisher) and finally closes the link: no send ever
    lands on an undeclared publisher ("Undeclared publisher"), and a send after close is
    dropped, as on a closed socket."""
    link = ZenohLink(parse_url(f"zenoh:race@{router}"), role="gcs", system_id=0)
    errors: list[BaseException] = []
    stop = threading.Event()

    def sender() -> None:
        try:
            while not stop.is_set():
                link.send(b"\xfd" + bytes(20))
        except BaseException as exc:  # the test reports whatever happened
            errors.append(exc)

    threads = [threading.Thread(target=sender) for _ in range(2)]
    for t in threads:
        t.start()
    try:
        for i in range(200):
            link.set_target(1 + i % 3)
    finally:
        link.close()
        time.sleep(0.05)
        stop.set()
        for t in threads:
            t.join(timeout=10)
    assert errors == []
    link.send(b"after close")
