"""tcp: client links (common/links/tcp_client.py) never block their caller: connecting,
failing to connect, losing the server and reconnecting all happen while the caller's loop
keeps running. Everything stays on 127.0.0.1."""

from __future__ import annotations

import itertools
import select
import socket
import time

import pytest

from common.links import LinkError, TcpClientLink, open_link, parse_url

pytestmark = pytest.mark.timeout(60)

BOUND_S = 0.2  # per call; a blocking connect would take its whole timeout (1 s)


def _listener(port: int = 0, backlog: int = 8) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("127.0.0.1", port))
    s.listen(backlog)
    return s


def _unanswering() -> tuple[socket.socket, list[socket.socket]]:
    """A port whose SYNs go unanswered: a listener with a full accept queue (listen(0),
    never accepting, filled by other connections) drops new SYNs, so a connect to it hangs
    until the client gives up, as with an address that does not answer."""
    server = _listener(backlog=0)
    port = server.getsockname()[1]
    fillers = []
    for _ in range(3):
        c = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        c.setblocking(False)
        c.connect_ex(("127.0.0.1", port))
        fillers.append(c)
    time.sleep(0.05)
    probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    probe.settimeout(0.3)
    try:
        with pytest.raises(TimeoutError):
            probe.connect(("127.0.0.1", port))  # the trick works on this kernel
    finally:
        probe.close()
    return server, fillers


def _closed_port() -> int:
    s = _listener()
    port = s.getsockname()[1]
    s.close()
    return port


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _exercise(link: TcpClientLink, calls: int = 20, spacing_s: float = 0.075) -> float:
    """The slowest of `calls` rounds of fileno/filenos/recv/send, spread over more than the
    retry interval so that new attempts start during the measurement."""
    worst = 0.0
    for _ in range(calls):
        worst = max(worst, _timed(link.fileno), _timed(link.filenos), _timed(link.recv),
                    _timed(lambda: link.send(b"x" * 32)))
        time.sleep(spacing_s)
    return worst


def _loop_until(link: TcpClientLink, cond, timeout: float) -> bool:
    """Drive the link as the FCU does: select for reading on filenos(), then recv()."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        fds = link.filenos()
        if fds:
            select.select(fds, [], [], 0.05)
        else:
            time.sleep(0.05)
        link.recv()
        if cond():
            return True
    return cond()


def _accept(server: socket.socket, timeout: float = 3.0) -> socket.socket:
    server.settimeout(timeout)
    conn, _ = server.accept()
    conn.settimeout(2.0)
    return conn


def _both_ways(link: TcpClientLink, conn: socket.socket, tag: bytes) -> None:
    link.send(b"up-" + tag)
    assert conn.recv(100) == b"up-" + tag
    conn.sendall(b"down-" + tag)
    got = b""
    deadline = time.monotonic() + 2.0
    while got != b"down-" + tag and time.monotonic() < deadline:
        select.select(link.filenos(), [], [], 0.05)
        got += b"".join(d for _, d in link.recv())
    assert got == b"down-" + tag


def test_unanswered_connect_never_blocks_then_connects_when_a_server_appears():
    """Before: a blocking connect with a 1 s timeout ran inside fileno()/recv()/send(),
    i.e. inside the FCU's control loop, once per second while the server was absent."""
    server, fillers = _unanswering()
    port = server.getsockname()[1]
    t0 = time.perf_counter()
    link = open_link(f"tcp:127.0.0.1:{port}")
    opened_s = time.perf_counter() - t0
    try:
        assert isinstance(link, TcpClientLink) and link.is_stream
        assert opened_s < BOUND_S
        assert link.connecting and not link.connected
        assert link.filenos() == [link.sock.fileno()]  # a failure would wake a read-select
        worst = _exercise(link)
        assert worst < BOUND_S, f"a call took {worst * 1e3:.1f} ms"
        assert link.connects == 0 and link.dropped_sends >= 20
        print(f"\nunanswered port: open {opened_s * 1e3:.2f} ms, slowest call "
              f"{worst * 1e3:.3f} ms")
        # The server appears: the stale listener goes, a real one takes the port.
        for c in fillers:
            c.close()
        server.close()
        server = _listener(port)
        t1 = time.monotonic()
        assert _loop_until(link, lambda: link.connected, 3.0)
        conn = _accept(server)
        print(f"connected {time.monotonic() - t1:.2f} s after the server appeared")
        assert time.monotonic() - t1 < 2.5
        _both_ways(link, conn, b"1")
        conn.close()
    finally:
        link.close()
        server.close()
        for c in fillers:
            c.close()


def test_refused_connects_are_fast_and_retried_at_most_once_per_second():
    starts = []

    class Counting(TcpClientLink):
        def _start(self, now):
            starts.append(now)
            super()._start(now)

    link = Counting(parse_url(f"tcp:127.0.0.1:{_closed_port()}"))
    try:
        worst = _exercise(link, calls=30, spacing_s=0.05)  # 1.5 s of calls
        assert worst < BOUND_S
        assert not link.connected and link.connects == 0
        assert len(starts) == 2  # at open, then one second later
        assert all(b - a >= 0.999 for a, b in itertools.pairwise(starts))
        print(f"\nrefused port: {len(starts)} attempts in 1.5 s, slowest call "
              f"{worst * 1e3:.3f} ms")
    finally:
        link.close()


def test_server_that_goes_away_and_comes_back_is_reconnected():
    server = _listener()
    port = server.getsockname()[1]
    link = open_link(f"tcp:127.0.0.1:{port}")
    try:
        assert _loop_until(link, lambda: link.connected, 2.0)
        conn = _accept(server)
        _both_ways(link, conn, b"a")
        # The server goes away: end of stream on the link's side.
        conn.close()
        server.close()
        assert _loop_until(link, lambda: not link.connected, 2.0)
        worst = _exercise(link, calls=10, spacing_s=0.05)  # refused meanwhile, never blocking
        assert worst < BOUND_S and not link.connected
        # ... and comes back on the same port.
        server = _listener(port)
        t1 = time.monotonic()
        assert _loop_until(link, lambda: link.connected, 3.0)
        conn = _accept(server)
        print(f"\nreconnected {time.monotonic() - t1:.2f} s after the server came back")
        assert link.connects == 2
        _both_ways(link, conn, b"b")
        conn.close()
    finally:
        link.close()
        server.close()


def test_reset_noticed_by_send_and_retried():
    server = _listener()
    port = server.getsockname()[1]
    link = open_link(f"tcp:127.0.0.1:{port}")
    try:
        assert _loop_until(link, lambda: link.connected, 2.0)
        conn = _accept(server)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\1\0\0\0\0\0\0\0")
        conn.close()  # linger 0: an RST, not a FIN
        deadline = time.monotonic() + 2.0
        while link.connected and time.monotonic() < deadline:
            assert _timed(lambda: link.send(b"z" * 64)) < BOUND_S  # send alone notices it
            time.sleep(0.01)
        assert not link.connected
        assert _loop_until(link, lambda: link.connected, 3.0)  # the server still listens
        conn = _accept(server)
        _both_ways(link, conn, b"r")
        conn.close()
    finally:
        link.close()
        server.close()


def test_full_socket_buffer_drops_whole_writes_only():
    """send() on a full buffer never waits and never leaves half a write in the stream."""
    server = _listener()
    link = open_link(f"tcp:127.0.0.1:{server.getsockname()[1]}")
    size = 3000
    try:
        assert _loop_until(link, lambda: link.connected, 2.0)
        conn = _accept(server)
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        assert link.sock is not None  # small buffers both sides: they fill in a few writes
        link.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        seq = 0

        def record(n: int) -> bytes:
            return n.to_bytes(4, "big") + bytes([n % 251]) * (size - 4)

        worst = 0.0
        while link.dropped_sends < 50:  # the peer does not read: buffers fill
            worst = max(worst, _timed(lambda n=seq: link.send(record(n))))
            seq += 1
            assert seq < 100_000
        got = bytearray()
        conn.settimeout(0.01)
        for _ in range(200):  # the reader takes some while the link writes on
            worst = max(worst, _timed(lambda n=seq: link.send(record(n))))
            seq += 1
            try:
                got += conn.recv(1 << 16)
            except TimeoutError:
                pass
        # The stream's end: the rest of a write the link holds goes out with its next send,
        # then the link closes, and the reader takes everything up to the end of the stream
        # (a pause in the data is not its end: a full window reopens when it likes).
        deadline = time.monotonic() + 10.0
        while link.unsent_bytes and time.monotonic() < deadline:
            link.send(b"")
            try:
                got += conn.recv(1 << 16)
            except TimeoutError:
                pass
        assert link.unsent_bytes == 0
        link.close()
        conn.settimeout(10.0)
        while chunk := conn.recv(1 << 16):  # to the end of the stream
            got += chunk
        assert worst < BOUND_S
        assert len(got) % size == 0 and got
        numbers = []
        for i in range(0, len(got), size):
            n = int.from_bytes(got[i:i + 4], "big")
            assert got[i:i + size] == record(n)
            numbers.append(n)
        assert numbers == sorted(numbers) and len(set(numbers)) == len(numbers)
        assert numbers[-1] - numbers[0] + 1 > len(numbers)  # whole writes dropped between
        conn.close()
    finally:
        link.close()
        server.close()


def test_closed_link_does_not_reconnect():
    server = _listener()
    link = open_link(f"tcp:127.0.0.1:{server.getsockname()[1]}")
    try:
        assert _loop_until(link, lambda: link.connected, 2.0)
        _accept(server).close()
        link.close()
        deadline = time.monotonic() + 1.3  # longer than the retry interval
        while time.monotonic() < deadline:
            assert link.filenos() == [] and link.recv() == [] and not link.connected
            link.send(b"after close")
            time.sleep(0.05)
        server.settimeout(0.1)
        with pytest.raises(TimeoutError):
            server.accept()
    finally:
        link.close()
        server.close()


def test_a_connection_to_itself_is_dropped():
    """With nothing listening on a local port, a connect whose source port happens to be
    that port connects to itself (TCP simultaneous open) and would read back its own
    frames; here the source port is forced to make it happen every time."""
    port = _closed_port()

    class SelfConnecting(TcpClientLink):
        def _new_socket(self):
            s = super()._new_socket()
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(("127.0.0.1", port))
            return s

    link = SelfConnecting(parse_url(f"tcp:127.0.0.1:{port}"))
    try:
        _loop_until(link, lambda: False, 0.3)
        link.send(b"echo?")
        assert link.recv() == [] and not link.connected and link.connects == 0
    finally:
        link.close()


def test_bad_tcp_urls_are_link_errors():
    with pytest.raises(LinkError):
        open_link("tcp:127.0.0.1:99999")
