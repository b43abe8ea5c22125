"""Link URLs: every spelling (this project's, MAVSDK's, pymavlink's) parsed into a LinkUrl.

Only the text is checked here (no name lookups, no file system): opening the link checks
that the host resolves, the port is free, the device exists.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.links.errors import LinkError

SCHEMES = ("udpin", "udpout", "tcp", "tcpin", "serial", "zenoh")
# Other spellings (MAVSDK, pymavlink) -> the scheme they mean.
ALIASES = {"udp": "udpin", "tcpout": "tcp"}
LISTENING = ("udpin", "tcpin")
FORMS = ("udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT, "
         "serial:DEVICE:BAUD, zenoh:PREFIX[@ENDPOINT] (or MAVSDK's udpin://, udpout://, "
         "udp://, tcp://, tcpin://, serial://)")
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"  # the Zenoh router a zenoh: link connects to


@dataclass(frozen=True)
class LinkUrl:
    scheme: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    text: str = ""

    def __str__(self) -> str:
        return self.text

    @property
    def canonical(self) -> str:
        """The URL in this project's own spelling (`udp://:14540` -> `udpin:0.0.0.0:14540`)."""
        if self.scheme == "zenoh":
            return f"zenoh:{self.device}"
        if self.scheme == "serial":
            return f"serial:{self.device}:{self.baud}"
        return f"{self.scheme}:{self.host}:{self.port}"


def parse_zenoh(rest: str) -> tuple[str, list[str]]:
    """'PREFIX@EP1,EP2' -> (prefix, endpoints); defaults 'mavlink' and the local router."""
    prefix, _, endpoints = rest.partition("@")
    prefix = prefix.strip("/") or "mavlink"
    if any(c in prefix for c in "*$#?") or "//" in prefix:
        raise LinkError(f"zenoh prefix '{prefix}': no wildcards or empty chunks")
    eps = [e for e in endpoints.split(",") if e] or [DEFAULT_ROUTER]
    for e in eps:
        if "/" not in e:
            raise LinkError(f"zenoh endpoint '{e}': expected PROTO/ADDRESS, e.g. {DEFAULT_ROUTER}")
    return prefix, eps


def parse_url(text: str) -> LinkUrl:
    """Parse a link URL (any spelling of `common.links`); raises LinkError naming what is
    wrong."""
    given, sep, rest = text.partition(":")
    name = given.lower()
    scheme = ALIASES.get(name, name)
    if not sep or scheme not in SCHEMES:
        what = f"unknown link type '{given}'" if sep and given else "not a link URL"
        raise LinkError(f"link '{text}': {what}; expected {FORMS}")
    if rest.startswith("//"):
        rest = rest[2:]  # MAVSDK's scheme://...; serial:///dev/x keeps its leading /
    if scheme == "zenoh":
        try:
            parse_zenoh(rest)
        except LinkError as exc:
            raise LinkError(f"link '{text}': {exc}") from None
        return LinkUrl(scheme, device=rest or "mavlink", text=text)
    if scheme == "serial":
        return _parse_serial(text, rest)
    return _parse_host_port(text, given, scheme, rest)


def _parse_serial(text: str, rest: str) -> LinkUrl:
    device, colon, baud = rest.rpartition(":")
    if not colon or not device or not baud.isdigit() or baud.startswith("0"):
        raise LinkError(f"link '{text}': expected serial:DEVICE:BAUD, e.g. "
                        "serial:/dev/ttyUSB0:57600")
    if not 50 <= int(baud) <= 20_000_000:
        raise LinkError(f"link '{text}': baud rate {baud} out of range (50..20000000)")
    return LinkUrl("serial", device=device, baud=int(baud), text=text)


def _parse_host_port(text: str, given: str, scheme: str, rest: str) -> LinkUrl:
    host, colon, port = rest.rpartition(":")
    if not colon or not port:
        raise LinkError(f"link '{text}': no port; expected {given}:HOST:PORT")
    if not port.isascii() or not port.isdigit():
        raise LinkError(f"link '{text}': port '{port}' is not a number")
    number = int(port)
    listening = scheme in LISTENING
    if not 1 <= number <= 65535 and not (number == 0 and listening):
        allowed = "1..65535, or 0 for any free port" if listening else "1..65535"
        raise LinkError(f"link '{text}': port {port} out of range ({allowed})")
    if host.startswith("[") or ":" in host:
        raise LinkError(f"link '{text}': IPv6 addresses are not supported; use an IPv4 "
                        "address or a host name")
    if not host:
        if not listening:
            raise LinkError(f"link '{text}': no host; expected {given}:HOST:PORT")
        host = "0.0.0.0"  # MAVSDK's udp://:14540: every interface
    if any(c.isspace() or c in "/@?#" for c in host):
        raise LinkError(f"link '{text}': '{host}' is not a host name or IPv4 address")
    return LinkUrl(scheme, host=host, port=number, text=text)
