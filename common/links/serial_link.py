"""serial: links through pyserial, imported only where a serial link is used."""

from __future__ import annotations

import errno
import importlib
import os
import stat
import time
from types import ModuleType
from typing import Protocol

from common.links.base import RECV_BATCH, Link, first_line
from common.links.errors import LinkError
from common.links.url import LinkUrl


class SerialPort(Protocol):
    """What this link uses of a `serial.Serial` (pyserial ships no type hints)."""

    def read(self, size: int) -> bytes: ...
    def write(self, data: bytes) -> int | None: ...
    def fileno(self) -> int: ...
    def close(self) -> None: ...


class SerialLink(Link):
    """serial:DEVICE:BAUD through pyserial: raw, 8N1, no flow control, never waiting.

    The device is opened exclusively (a second process is told it is in use, not given half
    the bytes). A device that goes away (a USB adapter pulled, the other end of a pty
    closed) is closed and reopened at most once per `retry_s`; meanwhile nothing is read and
    writes are dropped (counted in `dropped_sends`). A write the driver takes only in part
    keeps its unsent tail, sent before anything new, so that no frame is cut."""

    def __init__(self, url: LinkUrl, retry_s: float = 1.0) -> None:
        self.url = url
        self.retry_s = retry_s
        self._next_try = 0.0
        self._tail = b""
        self.dropped_sends = 0
        self.reopens = 0
        self.port: SerialPort | None = self._open()

    def _open(self) -> SerialPort:
        serial = _pyserial()
        url, device = self.url, self.url.device
        try:
            mode = os.stat(device).st_mode
        except FileNotFoundError:
            raise LinkError(f"link '{url}': no such device {device}") from None
        except OSError as exc:
            raise LinkError(f"link '{url}': {device}: {exc.strerror}") from None
        if not stat.S_ISCHR(mode):
            raise LinkError(f"link '{url}': {device} is not a serial device")
        try:
            port: SerialPort = serial.Serial(device, url.baud, timeout=0, write_timeout=0,
                                             exclusive=True)
        except (serial.SerialException, OSError) as exc:
            code = getattr(exc, "errno", None)
            if code in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EBUSY):
                why = f"{device} is in use by another process"
            elif code == errno.EACCES:
                why = f"no permission to open {device} (on Linux: the dialout group)"
            elif code == errno.ENOENT:
                why = f"no such device {device}"
            else:
                why = f"cannot open {device}: {first_line(exc)}"
            raise LinkError(f"link '{url}': {why}") from None
        except ValueError as exc:  # a baud rate the driver refuses
            raise LinkError(f"link '{url}': {exc}") from None
        return port

    def _lost(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            except (OSError, ValueError):
                pass
        self.port = None
        self._tail = b""
        self._next_try = time.monotonic() + self.retry_s

    def _reopen(self) -> None:
        if self.port is None and time.monotonic() >= self._next_try:
            self._next_try = time.monotonic() + self.retry_s
            try:
                self.port = self._open()
                self.reopens += 1
            except LinkError:
                pass

    def fileno(self) -> int:
        self._reopen()
        return self.port.fileno() if self.port is not None else -1

    def recv(self, limit: int = RECV_BATCH) -> list[tuple[object, bytes]]:
        serial = _pyserial()
        self._reopen()
        out: list[tuple[object, bytes]] = []
        if self.port is None:
            return out
        for _ in range(limit):
            try:
                data = self.port.read(4096)
            except (serial.SerialException, OSError):
                self._lost()  # readable without data: the device has gone
                return out
            if not data:
                return out
            out.append((self.url.device, data))
        return out

    def send(self, data: bytes) -> None:
        serial = _pyserial()
        self._reopen()
        if self.port is None:
            self.dropped_sends += 1
            return
        try:
            if self._tail:
                self._tail = self._tail[self.port.write(self._tail) or 0:]
                if self._tail:
                    self.dropped_sends += 1
                    return
            self._tail = data[self.port.write(data) or 0:]
        except serial.SerialTimeoutException:
            self.dropped_sends += 1
        except (serial.SerialException, OSError):
            self.dropped_sends += 1
            self._lost()

    def close(self) -> None:
        if self.port is not None:
            self.port.close()
            self.port = None
        self._next_try = float("inf")


def _pyserial() -> ModuleType:
    """pyserial, imported where a serial link is used (by name: it ships no type hints, and
    what this module uses of it is typed by `SerialPort`)."""
    return importlib.import_module("serial")

