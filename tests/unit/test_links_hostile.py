"""UDP links (common/links/udp.py) facing senders they should not serve: a udpout link reads
only its target's replies, and a udpin link answers a bounded number of peers."""

from __future__ import annotations

import socket
import time

import pytest

from common.links import LinkError, UdpLink, open_link, parse_url


def _sock() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.5)
    return s


def _recv_all(link, want: int, timeout: float = 1.0) -> list:
    got: list = []
    deadline = time.monotonic() + timeout
    while len(got) < want and time.monotonic() < deadline:
        got += link.recv()
        time.sleep(0.005)
    got += link.recv()
    return got


def test_udpout_reads_only_its_targets_replies():
    """Before: any local process could write into the FCU's simulator link (udpout) and be
    taken for the simulator (spoofed states); now datagrams from other addresses are
    dropped and counted."""
    peer, stranger = _sock(), _sock()
    link = open_link(f"udpout:127.0.0.1:{peer.getsockname()[1]}")
    try:
        link.send(b"hello")
        data, addr = peer.recvfrom(100)
        assert data == b"hello" and addr[1] == link.local_port
        for _ in range(5):
            stranger.sendto(b"spoof", ("127.0.0.1", link.local_port))
        peer.sendto(b"reply", ("127.0.0.1", link.local_port))
        got = _recv_all(link, 1)
        assert [d for _, d in got] == [b"reply"]
        assert link.foreign_datagrams == 5
    finally:
        link.close()
        peer.close()
        stranger.close()


def test_udpout_target_is_resolved_once_at_open():
    link = UdpLink(parse_url("udpout:localhost:9"))
    try:
        assert link.target == ("127.0.0.1", 9)
    finally:
        link.close()


def test_udpout_to_a_broadcast_address_is_not_filtered():
    link = UdpLink(parse_url("udpout:255.255.255.255:9"))
    try:
        assert link._only is None
    finally:
        link.close()


def test_udpin_answers_at_most_max_peers_and_keeps_the_first():
    """A flood from many source ports used to make every send() a burst to all of them
    (each state of the simulator, each telemetry message of the FCU); the table is now
    bounded, peers already in it keep being answered, and stale ones make room."""
    link = UdpLink(parse_url("udpin:127.0.0.1:0"), peer_timeout_s=0.3, max_peers=4)
    port = link.local_port
    socks = [_sock() for _ in range(10)]
    try:
        for s in socks:
            s.sendto(b"x", ("127.0.0.1", port))
        assert len(_recv_all(link, 10)) == 10  # everything is delivered
        assert link.peers == 4 and link.unanswered_peers == 6
        link.send(b"answer")
        for s in socks[:4]:
            assert s.recvfrom(100)[0] == b"answer"
        socks[5].settimeout(0.05)
        with pytest.raises(TimeoutError):
            socks[5].recvfrom(100)
        time.sleep(0.35)  # deliberate: the first four go stale (peer_timeout_s 0.3)
        socks[5].sendto(b"y", ("127.0.0.1", port))
        _recv_all(link, 1)
        link.send(b"again")
        assert socks[5].recvfrom(100)[0] == b"again"
        assert link.peers == 1
    finally:
        link.close()
        for s in socks:
            s.close()


def test_bad_udp_urls_are_link_errors():
    with pytest.raises(LinkError):
        open_link("udpout:127.0.0.1:99999")


def test_a_flood_is_read_in_bounded_batches():
    """recv() returns after RECV_BATCH datagrams even when more are waiting, so that a
    caller under a flood gets back to its own work between batches; nothing is lost."""
    from common.links import RECV_BATCH

    link = UdpLink(parse_url("udpin:127.0.0.1:0"))
    s = _sock()
    try:
        n = RECV_BATCH * 3 + 5
        for i in range(n):
            s.sendto(i.to_bytes(4, "big"), ("127.0.0.1", link.local_port))
        time.sleep(0.1)
        batches = []
        while got := link.recv():
            batches.append(len(got))
        assert max(batches) == RECV_BATCH and sum(batches) == n
    finally:
        link.close()
        s.close()


def test_tcpin_serves_at_most_max_clients():
    from common.links import TcpServerLink

    server = TcpServerLink(parse_url("tcpin:127.0.0.1:0"), max_clients=3)
    clients = []
    try:
        for _ in range(6):
            c = socket.create_connection(("127.0.0.1", server.local_port), timeout=1.0)
            clients.append(c)
            time.sleep(0.01)
            server.recv()
        assert server.peers == 3 and server.refused_clients == 3
        clients[0].sendall(b"data")
        time.sleep(0.05)
        assert [d for _, d in server.recv()] == [b"data"]
    finally:
        for c in clients:
            c.close()
        server.close()
