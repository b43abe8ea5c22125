"""`gcs router` and `gcs keygen`: what links between machines need, a Zenoh router and a
MAVLink 2 signing key."""

from __future__ import annotations

import argparse

from common.process.diagnostics import get_logger, say

log = get_logger(__name__)


def cmd_keygen(args: argparse.Namespace) -> int:
    import os
    import secrets

    if args.file.exists():
        log.error(f"gcs keygen: {args.file} exists; not overwriting a key")
        return 2
    try:
        fd = os.open(args.file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        where = "its folder does not exist" if isinstance(exc, FileNotFoundError) \
            else exc.strerror
        log.error(f"gcs keygen: cannot write {args.file}: {where}")
        return 2
    with os.fdopen(fd, "w") as fh:
        fh.write(secrets.token_hex(32) + "\n")
    say(f"wrote a 32-byte signing key to {args.file} (keep it out of version control)")
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    import signal
    import threading

    from common.links.url import DEFAULT_ROUTER
    from common.links.zenoh_link import run_router

    listen = args.listen or [DEFAULT_ROUTER]
    for endpoint in listen:
        problem = _endpoint_problem(endpoint)
        if problem:
            log.error(f"gcs router: {problem}")
            return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    say(f"gcs router: listening on {', '.join(listen)} (multicast scouting off)")
    try:
        run_router(listen, stop)
    except Exception as exc:  # zenoh reports a listener it cannot open as a plain error
        log.error(f"gcs router: cannot listen on {', '.join(listen)}: "
                  f"{(str(exc).splitlines() or [type(exc).__name__])[0]}")
        return 2
    return 0


def _endpoint_problem(endpoint: str) -> str:
    """Why a router cannot listen on a Zenoh endpoint ('' if it can, as far as a test
    bind tells): tcp/HOST:PORT and udp/HOST:PORT are checked, other protocols left to
    Zenoh."""
    import errno
    import socket

    proto, slash, addr = endpoint.partition("/")
    host, colon, port = addr.rpartition(":")
    if not slash or not colon or not port.isdigit() or not host:
        return f"endpoint '{endpoint}': expected PROTO/HOST:PORT, e.g. tcp/127.0.0.1:7447"
    if not 1 <= int(port) <= 65535:
        return f"endpoint '{endpoint}': port {port} out of range (1..65535)"
    kind = {"tcp": socket.SOCK_STREAM, "udp": socket.SOCK_DGRAM}.get(proto)
    if kind is None:
        return ""
    family = socket.AF_INET6 if host.startswith("[") else socket.AF_INET
    with socket.socket(family, kind) as s:
        if kind == socket.SOCK_STREAM:  # ignore connections in TIME_WAIT, as Zenoh does
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host.strip("[]"), int(port)))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return f"{host}:{port} is in use by another process"
            return f"cannot listen on {endpoint}: {exc.strerror or exc}"
    return ""
