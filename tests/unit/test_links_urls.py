"""Link URLs (common/links/url.py): the one parser of `gcs`, `fcu` and `sitl`. Every spelling
users bring (ours, MAVSDK's, pymavlink's) parses to the right transport, host and port;
every bad one is one line naming what is wrong; a port another process holds is refused,
never shared; a refused TCP connect is told apart (exit status 1) from bad input (2);
serial links work end to end over a pseudo-terminal pair."""

from __future__ import annotations

import errno
import os
import select
import socket
import threading
import time
import tty

import pytest

from common.links import (
    LinkError,
    LinkUnavailable,
    SerialLink,
    TcpClientLink,
    TcpServerLink,
    UdpLink,
    open_link,
    parse_url,
)

pytestmark = pytest.mark.timeout(60)

GOOD = [
    # ours
    ("udpin:127.0.0.1:14550", "udpin", "127.0.0.1", 14550),
    ("udpout:127.0.0.1:14540", "udpout", "127.0.0.1", 14540),
    ("tcp:localhost:5760", "tcp", "localhost", 5760),
    ("tcpin:0.0.0.0:5760", "tcpin", "0.0.0.0", 5760),
    # MAVSDK's
    ("udpin://127.0.0.1:14550", "udpin", "127.0.0.1", 14550),
    ("udpin://0.0.0.0:14540", "udpin", "0.0.0.0", 14540),
    ("udpout://10.0.0.5:14550", "udpout", "10.0.0.5", 14550),
    ("udp://127.0.0.1:14540", "udpin", "127.0.0.1", 14540),  # the old form: listen
    ("udp://:14540", "udpin", "0.0.0.0", 14540),  # MAVSDK's default: every interface
    ("tcp://127.0.0.1:5760", "tcp", "127.0.0.1", 5760),
    ("tcpout://127.0.0.1:5760", "tcp", "127.0.0.1", 5760),
    ("tcpin://127.0.0.1:5760", "tcpin", "127.0.0.1", 5760),
    # pymavlink's udp: (listen)
    ("udp:127.0.0.1:14550", "udpin", "127.0.0.1", 14550),
    # case of the scheme does not matter; port 0 = any free port where we listen
    ("UDPIN:127.0.0.1:1", "udpin", "127.0.0.1", 1),
    ("udpin:127.0.0.1:0", "udpin", "127.0.0.1", 0),
    ("tcpin:127.0.0.1:0", "tcpin", "127.0.0.1", 0),
    ("udpout:127.0.0.1:65535", "udpout", "127.0.0.1", 65535),
]


@pytest.mark.parametrize(("text", "scheme", "host", "port"), GOOD)
def test_every_spelling_parses_to_its_transport(text, scheme, host, port):
    url = parse_url(text)
    assert (url.scheme, url.host, url.port) == (scheme, host, port)
    assert str(url) == text
    assert parse_url(url.canonical) == parse_url(url.canonical)  # canonical parses again
    assert (parse_url(url.canonical).scheme, parse_url(url.canonical).port) == (scheme, port)


@pytest.mark.parametrize(("text", "device", "baud"), [
    ("serial:/dev/ttyUSB0:57600", "/dev/ttyUSB0", 57600),
    ("serial:///dev/ttyACM0:115200", "/dev/ttyACM0", 115200),  # MAVSDK's
    ("serial://COM3:921600", "COM3", 921600),
    ("serial:/dev/serial/by-id/usb-X:Y-if00:57600", "/dev/serial/by-id/usb-X:Y-if00", 57600),
])
def test_serial_urls(text, device, baud):
    url = parse_url(text)
    assert (url.scheme, url.device, url.baud) == ("serial", device, baud)
    assert url.canonical == f"serial:{device}:{baud}"


def test_zenoh_urls_are_checked_when_parsed():
    assert parse_url("zenoh:mavlink").device == "mavlink"
    assert parse_url("zenoh:fleet@tcp/127.0.0.1:7447").device == "fleet@tcp/127.0.0.1:7447"
    with pytest.raises(LinkError, match="wildcards"):
        parse_url("zenoh:a*b")
    with pytest.raises(LinkError, match="PROTO/ADDRESS"):
        parse_url("zenoh:x@127.0.0.1:7447")


BAD = [
    ("udpin:127.0.0.1", "no port"),
    ("udpin://127.0.0.1", "no port"),
    ("tcp:127.0.0.1:", "no port"),
    ("udpin:127.0.0.1:65536", "port 65536 out of range (1..65535, or 0 for any free port)"),
    ("udpin://127.0.0.1:99999", "port 99999 out of range"),
    ("udpout:127.0.0.1:0", "port 0 out of range (1..65535)"),  # cannot send to port 0
    ("tcp://127.0.0.1:0", "port 0 out of range (1..65535)"),
    ("udpout:127.0.0.1:-1", "is not a number"),
    ("udpin:127.0.0.1:14550x", "is not a number"),
    ("udpin:127.0.0.1:١٢", "is not a number"),  # digits, but not ASCII ones
    ("udpout://:14550", "no host"),
    ("tcp::5760", "no host"),
    ("udpin:::1:14550", "IPv6"),
    ("udpin:[::1]:14550", "IPv6"),
    ("udpin:a/b:1", "not a host name"),
    ("http://127.0.0.1:80", "unknown link type 'http'"),
    ("127.0.0.1:14550", "unknown link type '127.0.0.1'"),
    ("/dev/ttyUSB0", "not a link URL"),
    ("", "not a link URL"),
    ("serial:/dev/ttyUSB0", "expected serial:DEVICE:BAUD"),
    ("serial:///dev/ttyUSB0", "expected serial:DEVICE:BAUD"),
    ("serial:/dev/ttyUSB0:0", "expected serial:DEVICE:BAUD"),
    ("serial:/dev/ttyUSB0:fast", "expected serial:DEVICE:BAUD"),
    ("serial::57600", "expected serial:DEVICE:BAUD"),
    ("serial:/dev/ttyUSB0:10", "baud rate 10 out of range"),
]


@pytest.mark.parametrize(("text", "message"), BAD)
def test_bad_urls_are_one_line_errors(text, message):
    with pytest.raises(LinkError) as err:
        parse_url(text)
    assert message in str(err.value)
    assert "\n" not in str(err.value) and f"'{text}'" in str(err.value)
    assert err.value.exit_code == 2


def test_unknown_type_lists_the_forms():
    with pytest.raises(LinkError) as err:
        parse_url("udpbcast:1.2.3.4:5")
    for form in ("udpin:HOST:PORT", "tcpin:HOST:PORT", "serial:DEVICE:BAUD", "udpin://",
                 "zenoh:"):
        assert form in str(err.value)


def test_open_link_parses_every_spelling():
    for text in ("udp://127.0.0.1:0", "udpin://127.0.0.1:0"):
        link = open_link(text)
        try:
            assert isinstance(link, UdpLink) and link.target is None and link.local_port
        finally:
            link.close()
    link = open_link("tcpin://127.0.0.1:0")
    try:
        assert isinstance(link, TcpServerLink) and link.local_port
    finally:
        link.close()


def test_an_unresolvable_host_is_a_link_error():
    with pytest.raises(LinkError, match="cannot resolve"):
        open_link("udpout:no-such-host.invalid:14550")
    with pytest.raises(LinkError, match="cannot resolve"):
        open_link("udpin:no-such-host.invalid:14550")


# ------------------------------------------------------------------ busy ports


def _held(kind: int, reuseaddr: bool) -> socket.socket:
    s = socket.socket(socket.AF_INET, kind)
    if reuseaddr:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("127.0.0.1", 0))
    if kind == socket.SOCK_STREAM:
        s.listen(1)
    return s


@pytest.mark.parametrize("reuseaddr", [False, True], ids=["plain", "pymavlink-style"])
@pytest.mark.parametrize("form", ["udpin:127.0.0.1:{}", "udpin://127.0.0.1:{}",
                                  "udp://127.0.0.1:{}", "udpin:0.0.0.0:{}"])
def test_busy_udp_port_is_refused(form, reuseaddr):
    """pymavlink binds udpin ports with SO_REUSEADDR, and on Linux two such sockets share
    a UDP port, each getting some of the datagrams; our links never set it, so the second
    bind fails whoever holds the port."""
    with _held(socket.SOCK_DGRAM, reuseaddr) as held:
        port = held.getsockname()[1]
        with pytest.raises(LinkError) as err:
            open_link(form.format(port))
    host = form.split(":")[-2].lstrip("/")
    assert str(err.value).endswith(f"{host}:{port} is in use by another process")


def test_our_udpin_cannot_be_shared_by_a_pymavlink_style_socket():
    link = open_link("udpin:127.0.0.1:0")
    try:
        assert link.sock.getsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR) == 0
        assert link.sock.getsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT) == 0
        other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        with pytest.raises(OSError) as err:
            other.bind(("127.0.0.1", link.local_port))
        other.close()
        assert err.value.errno == errno.EADDRINUSE
    finally:
        link.close()


def test_busy_tcp_port_is_refused():
    with _held(socket.SOCK_STREAM, True) as held:
        port = held.getsockname()[1]
        with pytest.raises(LinkError, match=f"127.0.0.1:{port} is in use by another process"):
            open_link(f"tcpin:127.0.0.1:{port}")
    server = open_link("tcpin:127.0.0.1:0")
    try:
        assert server.server.getsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT) == 0
        with pytest.raises(LinkError, match="in use by another process"):
            open_link(f"tcpin://127.0.0.1:{server.local_port}")
    finally:
        server.close()


def test_a_port_that_needs_privileges():
    if os.geteuid() == 0:
        pytest.skip("root may bind any port")
    with pytest.raises(LinkError, match="no permission"):
        open_link("udpin:127.0.0.1:1")


# ------------------------------------------------------------------ tcp: refused


def _closed_port() -> tuple[socket.socket, int]:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))  # bound, never listening: connects are refused, port kept
    return s, s.getsockname()[1]


def test_refused_tcp_connect_is_link_unavailable_at_once():
    holder, port = _closed_port()
    try:
        link = open_link(f"tcp://127.0.0.1:{port}")
        assert isinstance(link, TcpClientLink)
        t0 = time.monotonic()
        with pytest.raises(LinkUnavailable) as err:
            link.wait_connected(3.0)
        assert time.monotonic() - t0 < 0.5
        assert err.value.exit_code == 1 and isinstance(err.value, LinkError)
        assert str(err.value) == (f"link 'tcp://127.0.0.1:{port}': cannot connect to "
                                  f"127.0.0.1:{port}: connection refused (nothing listens "
                                  "there)")
        link.close()
    finally:
        holder.close()


def test_wait_connected_returns_once_connected():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    try:
        link = open_link(f"tcp:127.0.0.1:{server.getsockname()[1]}")
        link.wait_connected(3.0)
        assert link.connected and link.last_error == 0
        link.close()
    finally:
        server.close()


# ------------------------------------------------------------------ serial


def test_missing_and_wrong_serial_devices():
    with pytest.raises(LinkError, match=r"no such device /dev/ttyNOPE0$"):
        open_link("serial:/dev/ttyNOPE0:57600")
    with pytest.raises(LinkError, match="is not a serial device"):
        open_link(f"serial:{__file__}:57600")
    with pytest.raises(LinkError, match="is not a serial device"):
        open_link("serial:/tmp:57600")


@pytest.fixture
def pty_pair():
    """(master fd, slave device path): a serial line in the kernel, no hardware."""
    master, slave = os.openpty()
    tty.setraw(master)
    path = os.ttyname(slave)
    os.close(slave)  # the link opens the device by name
    yield master, path
    try:
        os.close(master)
    except OSError:
        pass


def _read_master(master: int, want: int, timeout: float = 2.0) -> bytes:
    got = b""
    deadline = time.monotonic() + timeout
    while len(got) < want and time.monotonic() < deadline:
        if select.select([master], [], [], 0.05)[0]:
            got += os.read(master, 4096)
    return got


def test_serial_link_over_a_pty_both_ways(pty_pair):
    master, path = pty_pair
    for text in (f"serial:{path}:57600", f"serial://{path}:115200"):
        link = open_link(text)
        try:
            assert isinstance(link, SerialLink) and link.is_stream
            link.send(b"\xfd frame out")
            assert _read_master(master, 11) == b"\xfd frame out"
            os.write(master, b"frame in")
            got = b""
            deadline = time.monotonic() + 2
            while got != b"frame in" and time.monotonic() < deadline:
                select.select(link.filenos(), [], [], 0.05)
                got += b"".join(d for _, d in link.recv())
            assert got == b"frame in"
            assert link.recv() == []  # nothing waiting: an empty list, at once
        finally:
            link.close()


def test_serial_device_in_use_is_refused(pty_pair):
    _, path = pty_pair
    first = open_link(f"serial:{path}:57600")
    try:
        with pytest.raises(LinkError, match=f"{path} is in use by another process"):
            open_link(f"serial:{path}:57600")
    finally:
        first.close()
    open_link(f"serial:{path}:57600").close()  # free again once closed


def test_serial_device_that_goes_away_is_not_a_busy_loop(pty_pair):
    """The far end closes: the link closes the device instead of reporting it readable
    forever, drops writes, and tries to reopen at most once per retry interval."""
    master, path = pty_pair
    link = SerialLink(parse_url(f"serial:{path}:57600"), retry_s=0.2)
    try:
        os.close(master)
        deadline = time.monotonic() + 2
        while link.port is not None and time.monotonic() < deadline:
            link.recv()
            time.sleep(0.01)
        assert link.port is None and link.filenos() == []
        link.send(b"lost")
        assert link.dropped_sends >= 1
    finally:
        link.close()


def test_a_session_over_a_serial_line(pty_pair):
    """The ground station's session (gcs/vehicle_link/session.py) over serial:DEVICE:BAUD, with a
    tiny MAVLink vehicle on the other end of the pty: heartbeat, then a refused command whose
    STATUSTEXT reason is kept."""
    from common.wire.mavlink import MAV, encoder, pack, parser
    from gcs.vehicle_link.session import Session

    master, path = pty_pair
    stop = threading.Event()
    heard: list[str] = []

    def vehicle() -> None:
        mav, rx = encoder(1, 1), parser()
        next_hb = 0.0
        while not stop.is_set():
            if time.monotonic() >= next_hb:
                os.write(master, pack(mav, MAV.MAVLink_heartbeat_message(
                    MAV.MAV_TYPE_HEXAROTOR, MAV.MAV_AUTOPILOT_GENERIC, 0, 0,
                    MAV.MAV_STATE_STANDBY, 3)))
                next_hb = time.monotonic() + 0.2
            if not select.select([master], [], [], 0.02)[0]:
                continue
            try:
                data = os.read(master, 4096)
            except OSError:  # EIO while no one has the device open yet
                time.sleep(0.01)
                continue
            for msg in rx.parse_buffer(data) or []:
                heard.append(msg.get_type())
                if msg.get_type() == "COMMAND_LONG":
                    os.write(master, pack(mav, MAV.MAVLink_command_ack_message(
                        msg.command, MAV.MAV_RESULT_DENIED, 0, 0, 255, 190)))
                    os.write(master, pack(mav, MAV.MAVLink_statustext_message(
                        MAV.MAV_SEVERITY_WARNING, b"arming refused: no state input", 0, 0)))

    thread = threading.Thread(target=vehicle, daemon=True)
    thread.start()
    session = Session(f"serial://{path}:57600")
    try:
        session.wait_vehicle(timeout=5.0)
        assert session.target_system == 1
        result = session.command(MAV.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        assert result == MAV.MAV_RESULT_DENIED
        assert session.describe(result) == \
            "MAV_RESULT_DENIED: arming refused: no state input"
        assert "HEARTBEAT" in heard and "COMMAND_LONG" in heard  # ours reached it
    finally:
        session.close()
        stop.set()
        thread.join(timeout=2)
