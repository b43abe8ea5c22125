"""The hostile flight's relay process (`benchmarks.fuzz.relay`): both directions forwarded,
injected datagrams sent to the client from the server's side, its counters said at the end."""

from __future__ import annotations

import socket

import pytest

from benchmarks.fuzz.relay import Relay

pytestmark = pytest.mark.process


def _udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(5.0)
    return s


def test_relay_forwards_both_ways_and_injects_from_the_servers_side():
    server, client = _udp(), _udp()
    relay = Relay(server.getsockname()[1], priority=0)
    try:
        assert relay.inject(b"too early")  # handed over; dropped: no client yet
        client.sendto(b"state?", ("127.0.0.1", relay.port))
        data, relay_back = server.recvfrom(100)
        assert data == b"state?"
        server.sendto(b"state", relay_back)
        data, seen_from = client.recvfrom(100)
        assert (data, seen_from) == (b"state", ("127.0.0.1", relay.port))
        assert relay.inject(b"\xfd hostile")
        data, seen_from = client.recvfrom(100)
        assert (data, seen_from) == (b"\xfd hostile", ("127.0.0.1", relay.port))
    finally:
        counts = relay.close()
        server.close()
        client.close()
    assert counts == {"to_server": 1, "to_client": 1, "injected": 1,
                      "injected_before_client": 1, "send_errors": 0}
    assert relay.proc.returncode == 0
