"""Link URLs and the byte transports behind them: the one link layer of `fcu`, `sitl` and
`gcs` (docs/architecture.md#links-and-messages).

    udpin:HOST:PORT    bind and answer every peer heard in the last `peer_timeout_s` (at
                       most `max_peers` of them: a flood from many ports cannot make every
                       send a burst of thousands)
    udpout:HOST:PORT   send to HOST:PORT; only its replies are read (datagrams from any
                       other address are dropped and counted in `foreign_datagrams`)
    tcp:HOST:PORT      connect to a TCP server without blocking: an attempt in progress is
                       checked on every call, never waited for; attempts at most once per
                       second, each abandoned after a second without an answer; reconnects
                       when the server goes away; data sent while not connected is dropped
    tcpin:HOST:PORT    listen for TCP clients and serve all of them
    serial:DEVICE:BAUD a serial port (pyserial) in raw mode, 8N1, no flow control
    zenoh:PREFIX[@ENDPOINT,...]   Zenoh pub/sub (`common/links/zenoh_link.py`)

MAVSDK's and pymavlink's spellings are accepted too and mean the same links: `udpin://`,
`udpout://`, `udp://HOST:PORT` and `udp:HOST:PORT` (listen, as MAVSDK's old form and
pymavlink's), `tcp://` and `tcpout://` (client), `tcpin://`, `serial://DEVICE:BAUD`
(`serial:///dev/ttyUSB0:57600`). An empty HOST on a listening link (`udp://:14540`) means
every interface, as in MAVSDK; everywhere else HOST is required. PORT is 1..65535; 0 (any
free port, which the link's `local_port` then tells) only on a listening link (udpin, tcpin).

Errors are `LinkError`s with a one-line message: a URL that does not parse, a port out of
range, a device that does not exist, a port another process holds (never shared: no
SO_REUSEPORT, and UDP ports without SO_REUSEADDR) are bad input (`exit_code` 2); a peer that
is not there (`LinkUnavailable`: a refused TCP connect, for callers that wait for one; a Zenoh
router that cannot be reached) is a runtime failure (`exit_code` 1).

Every link is non-blocking: `recv()` returns the datagrams or stream chunks that are ready,
`send(data)` never waits, and `fileno()` lets one `select` serve all links. Peers are told
apart by `peer` keys so that each byte stream gets its own MAVLink parser.
"""

from __future__ import annotations

from common.links.base import RECV_BATCH, Link
from common.links.errors import LinkError, LinkUnavailable
from common.links.ports import free_port
from common.links.serial_link import SerialLink
from common.links.tcp_client import TcpClientLink
from common.links.tcp_server import TcpServerLink
from common.links.udp import UdpLink
from common.links.url import LinkUrl, parse_url

# The link layer's interface, as the programs use it; each name lives in one part:
# url.py (parsing), errors.py, base.py (Link, RECV_BATCH), udp.py and peers.py (the peer
# table that bounds udpin), tcp_client.py, tcp_server.py, serial_link.py, ports.py.
__all__ = ["RECV_BATCH", "Link", "LinkError", "LinkUnavailable", "LinkUrl", "SerialLink",
           "TcpClientLink", "TcpServerLink", "UdpLink", "free_port", "open_link", "parse_url"]


def open_link(url: str | LinkUrl, *, role: str = "vehicle", system_id: int = 0) -> Link:
    """Open a link from its URL; `role` and `system_id` choose a Zenoh link's keys."""
    parsed = url if isinstance(url, LinkUrl) else parse_url(url)
    if parsed.scheme == "zenoh":
        from common.links.zenoh_link import ZenohLink  # imported only where Zenoh is used

        return ZenohLink(parsed, role=role, system_id=system_id)
    if parsed.scheme in ("udpin", "udpout"):
        return UdpLink(parsed)
    if parsed.scheme == "tcp":
        return TcpClientLink(parsed)
    if parsed.scheme == "tcpin":
        return TcpServerLink(parsed)
    if parsed.scheme == "serial":
        return SerialLink(parsed)
    raise LinkError(f"link '{parsed}': unknown scheme")
