"""MAVLink 2 frames over Zenoh (docs/fleets.md): `zenoh:PREFIX[@ENDPOINT,...]`.

Keys: a vehicle publishes on `PREFIX/<sysid>/out`, listens on `PREFIX/<sysid>/in` and holds
the liveliness token `PREFIX/<sysid>/alive`; ground stations listen on `PREFIX/*/out` (or one
vehicle's) and publish to the chosen vehicle's `in`. The simulator link uses
`PREFIX/<sysid>/sim/state` (plant to FCU) and `PREFIX/<sysid>/sim/actuators` (FCU to plant).

Sessions run in client mode and connect to routers (default `tcp/127.0.0.1:7447`); multicast
scouting is off and nothing listens, so nothing leaves 127.0.0.1 unless an endpoint says so.
Zenoh's callbacks only append to a deque and poke a pipe: they never block Zenoh's threads
(beyond a lock held for a few list operations), and the pipe's read end lets the same
`select` loop serve Zenoh and sockets. Bounds, so that a flood can neither grow memory nor
starve the caller's loop:

- the deque holds at most `max_queue` samples (MAX_QUEUE, 1024, by default); beyond that the
  OLDEST are dropped (the newest state is worth more than a stale one) and counted in
  `dropped_samples`;
- `recv()` returns at most RECV_BATCH (common/links/base.py) samples per call, oldest first, and
  leaves the rest for the next call;
- the pipe is readable exactly when samples are waiting (or a liveliness change is to be
  reported): a callback writes one byte only when the pipe is empty (so a flood costs no
  system call per sample and the pipe never fills), and `recv()` empties the pipe only when
  it has emptied the deque, so the caller's `select` wakes again for what a batch left.
"""

from __future__ import annotations

import collections
import json
import os
import socket
import threading
from collections.abc import Callable
from typing import Protocol

import zenoh

from common.links.base import RECV_BATCH, Link
from common.links.errors import LinkError, LinkUnavailable
from common.links.url import DEFAULT_ROUTER, LinkUrl, parse_zenoh

ROLES = ("vehicle", "gcs", "sim_server", "sim_client")
MAX_QUEUE = 1024  # samples waiting for recv(); the oldest are dropped beyond it


def client_config(endpoints: list[str], mode: str = "client") -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("connect/endpoints", json.dumps(endpoints))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def router_config(listen: list[str]) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps(listen))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def router_running(endpoint: str = DEFAULT_ROUTER, timeout: float = 0.5) -> bool:
    """Something accepts TCP connections at a tcp/HOST:PORT endpoint."""
    proto, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    if proto != "tcp" or not port.isdigit():
        return False
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            return True
    except OSError:
        return False


class _Declared(Protocol):
    """A Zenoh entity as this module uses it (zenoh's stubs leave `undeclare` untyped)."""

    def undeclare(self) -> None: ...


class _Closable(Protocol):
    """A Zenoh session as this module closes it (zenoh's stubs leave `close` untyped)."""

    def close(self) -> None: ...


def _undeclare(entity: _Declared) -> None:
    entity.undeclare()


def _close(session: _Closable) -> None:
    session.close()


class ZenohLink(Link):
    """A Zenoh link in one of the roles of ROLES."""

    spin = False  # data arrives from Zenoh's threads: sleep in select, release the GIL

    def __init__(self, url: LinkUrl, *, role: str, system_id: int = 0,
                 on_liveliness: Callable[[int, bool], None] | None = None,
                 max_queue: int = MAX_QUEUE) -> None:
        if role not in ROLES:
            raise LinkError(f"zenoh link role {role!r}: expected one of {ROLES}")
        self.url = url
        self.prefix, self.endpoints = parse_zenoh(url.device)
        self.role = role
        self.system_id = system_id
        if max_queue < 1:
            raise LinkError(f"zenoh link: max_queue must be at least 1, got {max_queue}")
        self.max_queue = max_queue
        self._queue: collections.deque[tuple[str, bytes]] = collections.deque(maxlen=max_queue)
        self.dropped_samples = 0  # the oldest samples dropped because the queue was full
        self._rfd, self._wfd = os.pipe()
        os.set_blocking(self._rfd, False)
        os.set_blocking(self._wfd, False)
        # Guards the queue, the drop count and `_poked` (True: a byte is in the pipe).
        self._qlock = threading.Lock()
        self._poked = False
        self._lock = threading.Lock()
        self._pub_lock = threading.Lock()  # the publisher: sends against re-target and close
        self.vehicles: set[int] = set()
        self._on_liveliness = on_liveliness
        try:
            self.session = zenoh.open(client_config(self.endpoints))
        except zenoh.ZError as exc:
            self.close_fds()
            why = (str(exc).splitlines() or ["?"])[0].split("  at ")[0].rstrip()
            raise LinkUnavailable(f"link '{url}': cannot open a Zenoh session: {why}") from None
        p, n = self.prefix, system_id
        self._token = None
        self._pub = None
        self._live = None
        if role == "vehicle":
            self._pub = self.session.declare_publisher(f"{p}/{n}/out", express=True)
            self._sub = self.session.declare_subscriber(f"{p}/{n}/in", self._on_sample)
            self._token = self.session.liveliness().declare_token(f"{p}/{n}/alive")
        elif role == "gcs":
            self._sub = self.session.declare_subscriber(f"{p}/{n or '*'}/out", self._on_sample)
            self._live = self.session.liveliness().declare_subscriber(
                f"{p}/*/alive", self._on_alive, history=True)
            if n:
                self.set_target(n)
        elif role == "sim_server":
            self._pub = self.session.declare_publisher(f"{p}/{n}/sim/state", express=True)
            self._sub = self.session.declare_subscriber(f"{p}/{n}/sim/actuators",
                                                        self._on_sample)
        else:
            self._pub = self.session.declare_publisher(f"{p}/{n}/sim/actuators", express=True)
            self._sub = self.session.declare_subscriber(f"{p}/{n}/sim/state", self._on_sample)

    # Zenoh threads: append and poke, never block.
    def _on_sample(self, sample: zenoh.Sample) -> None:
        item = (str(sample.key_expr), sample.payload.to_bytes())
        with self._qlock:
            q = self._queue
            if len(q) == q.maxlen:
                self.dropped_samples += 1  # append() drops the oldest
            q.append(item)
            if not self._poked:
                self._poke()

    def _poke(self) -> None:
        """Make the pipe readable (with `_qlock` held). One byte at most is ever in it, so
        the write cannot find it full; a closed pipe (after close()) has no reader left."""
        try:
            os.write(self._wfd, b"\0")
        except BlockingIOError:
            pass  # full, hence readable: the wakeup is there
        except OSError:
            return
        self._poked = True

    def _on_alive(self, sample: zenoh.Sample) -> None:
        chunk = str(sample.key_expr).split("/")[-2]
        if not chunk.isdigit():
            return
        sysid = int(chunk)
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            (self.vehicles.add if alive else self.vehicles.discard)(sysid)
        if self._on_liveliness is not None:
            self._on_liveliness(sysid, alive)
        self._on_sample_wakeup()

    def _on_sample_wakeup(self) -> None:
        with self._qlock:
            if not self._poked:
                self._poke()

    def set_target(self, system_id: int) -> None:
        """GCS: send to this vehicle's `in` key from now on."""
        with self._pub_lock:
            if self._pub is not None:
                _undeclare(self._pub)
            self._pub = self.session.declare_publisher(f"{self.prefix}/{system_id}/in",
                                                       express=True)

    def fileno(self) -> int:
        return self._rfd

    @property
    def queued(self) -> int:
        """Samples waiting for recv()."""
        return len(self._queue)

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
        """At most `limit` (by default RECV_BATCH) samples, oldest first. While samples
        remain the pipe stays readable, so the caller's `select` wakes again for them."""
        with self._qlock:
            q = self._queue
            n = min(len(q), limit)
            out: list[tuple[object, bytes]] = [q.popleft() for _ in range(n)]
            if q:
                if not self._poked:
                    self._poke()
            elif self._poked:
                try:
                    while os.read(self._rfd, 64):
                        pass
                except OSError:
                    pass  # empty (BlockingIOError) or closed
                self._poked = False
        return out

    def send(self, data: bytes) -> None:
        # Under the lock: another thread may be re-targeting (set_target) or closing, and a
        # put on the publisher it undeclares raises "Undeclared publisher".
        with self._pub_lock:
            pub = self._pub
            if pub is not None:
                pub.put(data)

    def close_fds(self) -> None:
        with self._qlock:  # a late callback then writes to -1, never to a reused number
            fds, self._rfd, self._wfd = (self._rfd, self._wfd), -1, -1
            self._poked = False
        for fd in fds:
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass

    def close(self) -> None:
        with self._pub_lock:
            pub, self._pub = self._pub, None  # later sends are dropped, as on a closed socket
        for entity in (self._token, self._live, getattr(self, "_sub", None), pub):
            if entity is not None:
                try:
                    entity.undeclare()
                except zenoh.ZError:
                    pass
        _close(self.session)
        self.close_fds()


def run_router(listen: list[str], stop: threading.Event) -> None:
    """A Zenoh router for the machine's sessions (and other routers' connections)."""
    session = zenoh.open(router_config(listen))
    try:
        stop.wait()
    finally:
        _close(session)
