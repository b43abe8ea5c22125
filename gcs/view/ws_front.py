"""The view's WebSocket front on 127.0.0.1: it accepts both names of the Foxglove WebSocket
protocol and relays every connection, byte for byte, to the foxglove-sdk server bound on
another loopback port.

The published spec (and the clients written to it: Lichtblick releases, others) asks for
the subprotocol `foxglove.websocket.v1`; foxglove-sdk's server accepts only its own names
(`foxglove.sdk.v1`, ...) and answers anything else with HTTP 400. The two are the same
protocol under two names, so the front rewrites only the opening handshake: a request that
offers `foxglove.websocket.v1` and none of the SDK's names is passed on offering
`foxglove.sdk.v1`, and the server's 101 answer goes back naming `foxglove.websocket.v1`.
Any other request (the SDK's own names, or anything else) passes unchanged. After the
handshake the bytes are relayed untouched both ways (the frames do not depend on the
subprotocol's name; the Sec-WebSocket-Accept key depends on the client's key alone).

Guards: at most `MAX_CLIENTS` connections at a time, a handshake of at most
`MAX_HANDSHAKE_BYTES` within `HANDSHAKE_TIMEOUT_S`; anything else is closed.
"""

from __future__ import annotations

import socket
import threading

from gcs.view.settings import HOST

SPEC_SUBPROTOCOL = "foxglove.websocket.v1"  # the published spec's name
SDK_SUBPROTOCOL = "foxglove.sdk.v1"  # foxglove-sdk's name for the same protocol
SDK_PREFIX = "foxglove.sdk."  # every name the SDK's server accepts starts so
MAX_CLIENTS = 16
MAX_HANDSHAKE_BYTES = 16384
HANDSHAKE_TIMEOUT_S = 10.0


def _split_head(data: bytes) -> tuple[list[bytes], bytes] | None:
    """(header lines, bytes after the head) once the blank line has come, else None."""
    end = data.find(b"\r\n\r\n")
    if end < 0:
        return None
    return data[:end].split(b"\r\n"), data[end + 4:]


def _offered(lines: list[bytes]) -> list[str]:
    """The subprotocols a request offers (every Sec-WebSocket-Protocol header, in order)."""
    names: list[str] = []
    for line in lines[1:]:
        key, _, value = line.partition(b":")
        if key.strip().lower() == b"sec-websocket-protocol":
            names += [n.strip() for n in value.decode("latin-1").split(",") if n.strip()]
    return names


def rewrite_request(lines: list[bytes]) -> tuple[list[bytes], bool]:
    """The request's header lines as passed to the SDK, and whether the answer must be
    renamed: offering the spec's name and none of the SDK's, it offers the SDK's instead."""
    offered = _offered(lines)
    if SPEC_SUBPROTOCOL not in offered or any(n.startswith(SDK_PREFIX) for n in offered):
        return lines, False
    kept = [line for line in lines
            if line.partition(b":")[0].strip().lower() != b"sec-websocket-protocol"]
    return [*kept, b"Sec-WebSocket-Protocol: " + SDK_SUBPROTOCOL.encode()], True


def rewrite_response(lines: list[bytes]) -> list[bytes]:
    """The SDK's answer with its subprotocol header naming the spec's protocol."""
    out = []
    for line in lines:
        key, _, value = line.partition(b":")
        if key.strip().lower() == b"sec-websocket-protocol" and value.strip():
            line = key + b": " + SPEC_SUBPROTOCOL.encode()
        out.append(line)
    return out


def _read_head(sock: socket.socket) -> tuple[list[bytes], bytes] | None:
    """Read an HTTP head (request or response) within the handshake's bounds."""
    data = b""
    while (head := _split_head(data)) is None:
        if len(data) > MAX_HANDSHAKE_BYTES:
            return None
        chunk = sock.recv(4096)
        if not chunk:
            return None
        data += chunk
    return head


def _pump(src: socket.socket, dst: socket.socket) -> None:
    """Copy src to dst until src ends, then end dst's sending side (a half close, so that
    the other direction's closing handshake still goes through)."""
    try:
        while chunk := src.recv(65536):
            dst.sendall(chunk)
    except OSError:
        pass
    try:
        dst.shutdown(socket.SHUT_WR)
    except OSError:
        pass


class WebSocketFront:
    """Listens on 127.0.0.1:`port` (0: any free port, then `port` tells) and relays each
    client to the SDK's server on 127.0.0.1:`back_port`."""

    def __init__(self, port: int, back_port: int) -> None:
        self.back_port = back_port
        self._listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        # As the SDK's own listener: a restarted view takes its port back from connections
        # in TIME_WAIT; on Linux this never shares a port another socket listens on.
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listener.bind((HOST, port))
            self._listener.listen(8)
        except OSError:
            self._listener.close()
            raise
        self._listener.settimeout(0.2)  # the accept loop looks at `_stop` this often
        self.port: int = int(self._listener.getsockname()[1])
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._clients: set[socket.socket] = set()
        self._backs: set[socket.socket] = set()
        self._thread = threading.Thread(target=self._serve, name="view-front", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                continue  # e.g. out of descriptors: the client waits in the backlog
            with self._lock:
                if len(self._clients) >= MAX_CLIENTS:
                    client.close()  # a flood of connections must not take every thread
                    continue
                self._clients.add(client)
            threading.Thread(target=self._relay, args=(client,), name="view-relay",
                             daemon=True).start()

    def _relay(self, client: socket.socket) -> None:
        back: socket.socket | None = None
        try:
            client.settimeout(HANDSHAKE_TIMEOUT_S)
            request = _read_head(client)
            if request is None:
                return
            lines, rest = request
            lines, rename = rewrite_request(lines)
            back = socket.create_connection((HOST, self.back_port), timeout=HANDSHAKE_TIMEOUT_S)
            with self._lock:
                if self._stop.is_set():
                    return
                self._backs.add(back)
            back.sendall(b"\r\n".join(lines) + b"\r\n\r\n" + rest)
            response = _read_head(back)
            if response is None:
                return
            head, rest = response
            if rename and head[0].split(b" ")[1:2] == [b"101"]:
                head = rewrite_response(head)
            client.sendall(b"\r\n".join(head) + b"\r\n\r\n" + rest)
            client.settimeout(None)
            back.settimeout(None)
            upstream = threading.Thread(target=_pump, args=(client, back), daemon=True)
            upstream.start()
            _pump(back, client)
            upstream.join()
        except OSError:
            pass
        finally:
            with self._lock:
                self._clients.discard(client)
                if back is not None:
                    self._backs.discard(back)
            client.close()
            if back is not None:
                back.close()

    def stop(self) -> None:
        """Stop accepting and end every relayed connection."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._listener.close()
        with self._lock:
            for sock in (*self._clients, *self._backs):
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
