"""`gcs view`'s WebSocket front (gcs/view/ws_front.py): a client written to the published
spec (subprotocol `foxglove.websocket.v1`) and one speaking foxglove-sdk's name
(`foxglove.sdk.v1`) both get the serverInfo and the advertised channels; the handshake
rewrite touches only the subprotocol; everything stays on 127.0.0.1."""

from __future__ import annotations

import asyncio
import json
import socket

import pytest

from common.config.scenario import load_vehicle
from gcs.view.publisher import Outputs, Publisher
from gcs.view.settings import DEFAULT_VEHICLE, TOPICS
from gcs.view.ws_front import (
    SDK_SUBPROTOCOL,
    SPEC_SUBPROTOCOL,
    rewrite_request,
    rewrite_response,
)

pytest.importorskip("foxglove")
websockets = pytest.importorskip("websockets")


@pytest.fixture
def outputs():
    out = Outputs(0, None)
    Publisher(out.context, load_vehicle(DEFAULT_VEHICLE), "live")
    try:
        yield out
    finally:
        out.close()


async def _hello(url: str, subprotocol: str) -> tuple[str | None, dict, set[str]]:
    """Connect offering `subprotocol`; the chosen one, serverInfo and the advertised topics."""
    async with websockets.connect(url, subprotocols=[subprotocol], open_timeout=10) as ws:
        info: dict = {}
        topics: set[str] = set()
        while not info or topics != set(TOPICS):
            msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
            if msg["op"] == "serverInfo":
                info = msg
            elif msg["op"] == "advertise":
                topics |= {ch["topic"] for ch in msg["channels"]}
        return ws.subprotocol, info, topics


@pytest.mark.parametrize("subprotocol", [SPEC_SUBPROTOCOL, SDK_SUBPROTOCOL])
def test_both_names_get_server_info_and_the_channels(outputs, subprotocol):
    """Given the view's outputs with its five channels, when a client offers the spec's
    name or the SDK's, then the handshake names what it offered and the client gets the
    serverInfo and every channel advertised."""
    chosen, info, topics = asyncio.run(_hello(outputs.url, subprotocol))
    assert chosen == subprotocol
    assert info["name"] == "dqflight gcs view"
    assert topics == set(TOPICS)


def test_two_clients_at_once_one_of_each(outputs):
    """Given one client of each name at the same time, then both are served."""
    async def both():
        return await asyncio.gather(_hello(outputs.url, SPEC_SUBPROTOCOL),
                                    _hello(outputs.url, SDK_SUBPROTOCOL))

    (a, _, ta), (b, _, tb) = asyncio.run(both())
    assert (a, b) == (SPEC_SUBPROTOCOL, SDK_SUBPROTOCOL)
    assert ta == tb == set(TOPICS)


def test_unknown_subprotocol_is_refused(outputs):
    """Given a request offering neither name, then the SDK's HTTP 400 comes back."""
    port = int(outputs.url.rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=5) as c:
        c.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                  b"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: chat\r\n\r\n")
        assert c.recv(4096).startswith(b"HTTP/1.1 400")


def test_front_and_server_bind_loopback_only(outputs):
    """Given the outputs, then the front listens on 127.0.0.1 and the SDK's server is
    reached on 127.0.0.1 too."""
    assert outputs.url.startswith("ws://127.0.0.1:")
    assert outputs.front._listener.getsockname()[0] == "127.0.0.1"
    with socket.create_connection(("127.0.0.1", outputs.server.port), timeout=5):
        pass


def test_rewrite_touches_only_the_subprotocol():
    """Given a request offering the spec's name, then only its subprotocol header changes
    (to the SDK's), and the answer's header is renamed back; a request already offering an
    SDK name, or offering nothing known, passes unchanged."""
    head = [b"GET / HTTP/1.1", b"Host: x", b"Sec-WebSocket-Key: k",
            b"sec-websocket-protocol: foxglove.websocket.v1"]
    lines, rename = rewrite_request(head)
    assert rename and lines == [*head[:3], b"Sec-WebSocket-Protocol: foxglove.sdk.v1"]
    both = [*head[:3], b"Sec-WebSocket-Protocol: foxglove.websocket.v1, foxglove.sdk.v1"]
    assert rewrite_request(both) == (both, False)
    other = [*head[:3], b"Sec-WebSocket-Protocol: chat"]
    assert rewrite_request(other) == (other, False)
    answer = [b"HTTP/1.1 101 Switching Protocols", b"sec-websocket-accept: a",
              b"sec-websocket-protocol: foxglove.sdk.v1"]
    assert rewrite_response(answer) == [*answer[:2],
                                        b"sec-websocket-protocol: foxglove.websocket.v1"]
