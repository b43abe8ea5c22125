"""ULog, PX4's log format: an append-only writer and a reader.

The writer follows the ULog specification (PX4 docs, "ULog File Format"): the 16-byte
header, the flag bits, then the definitions (information, parameters, formats), then the
data (subscriptions, data, logged strings, changed parameters). Records are assembled in
memory and handed to the kernel with one `write` per `flush` (the processes flush once per
control period): after SIGKILL of the writer every flushed record is in the file, and a
reader stops at the last complete record. pyulog 1.3's own writer writes a whole log at
once, which a log that must survive its writer cannot use; every file is read back with
pyulog (`read_topic`), so the format is proven by the reference reader.

Topics are declared as `Topic(name, fields)` with ULog's C type names; the first field is
always `uint64_t timestamp` (microseconds).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

MAGIC = b"ULog\x01\x12\x35"
VERSION = 1
_HEADER = struct.Struct("<HB")  # msg_size, msg_type
_CODES = {"uint64_t": "Q", "int64_t": "q", "uint32_t": "I", "int32_t": "i",
          "uint16_t": "H", "int16_t": "h", "uint8_t": "B", "int8_t": "b",
          "float": "f", "double": "d", "bool": "?", "char": "c"}
MAX_PAYLOAD = 0xFFFF


class ULogError(ValueError):
    """A ULog file that cannot be read, or a topic it does not hold."""


@dataclass(frozen=True)
class Topic:
    """A ULog message format: name and (type, field) pairs, `timestamp` first.

    Array fields are written `("float", "q", 4)`; pyulog names their columns `q[0]`...
    """

    name: str
    fields: tuple[tuple[str, str] | tuple[str, str, int], ...]
    _struct: struct.Struct = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.fields or self.fields[0][:2] != ("uint64_t", "timestamp"):
            raise ValueError(f"topic {self.name}: the first field must be uint64_t timestamp")
        codes = []
        for f in self.fields:
            if f[0] not in _CODES:
                raise ValueError(f"topic {self.name}: unknown type {f[0]}")
            count = f[2] if len(f) == 3 else 1  # type: ignore[misc]
            codes.append(f"{count}{_CODES[f[0]]}" if count != 1 else _CODES[f[0]])
        object.__setattr__(self, "_struct", struct.Struct("<" + "".join(codes)))

    @property
    def format(self) -> str:
        """The format message's text: `name:type field;type[n] field;...`."""
        parts = []
        for f in self.fields:
            kind = f"{f[0]}[{f[2]}]" if len(f) == 3 else f[0]  # type: ignore[misc]
            parts.append(f"{kind} {f[1]}")
        return f"{self.name}:" + ";".join(parts) + ";"

    @property
    def size(self) -> int:
        return self._struct.size

    @property
    def width(self) -> int:
        """Number of values a record takes (arrays flattened)."""
        return sum(f[2] if len(f) == 3 else 1 for f in self.fields)  # type: ignore[misc]


def _message(kind: bytes, payload: bytes) -> bytes:
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"ULog message of {len(payload)} bytes")
    return _HEADER.pack(len(payload), kind[0]) + payload


def _key_value(type_name: str, key: str, value: bytes) -> bytes:
    k = f"{type_name} {key}".encode()
    return bytes([len(k)]) + k + value


def info_message(key: str, value: str | int | float) -> bytes:
    """'I': information (sys_name, ver_hw, ...): char[n], int32_t or float."""
    if isinstance(value, str):
        raw = value.encode()
        return _message(b"I", _key_value(f"char[{len(raw)}]", key, raw))
    if isinstance(value, int) and not isinstance(value, bool):
        return _message(b"I", _key_value("int32_t", key, struct.pack("<i", value)))
    return _message(b"I", _key_value("float", key, struct.pack("<f", float(value))))


def parameter_message(name: str, value: int | float) -> bytes:
    """'P': a parameter, int32_t or float as PX4 stores them."""
    if isinstance(value, int) and not isinstance(value, bool):
        return _message(b"P", _key_value("int32_t", name, struct.pack("<i", value)))
    return _message(b"P", _key_value("float", name, struct.pack("<f", float(value))))


# Logged-message levels are the syslog levels as ASCII digits, the same scale as
# MAV_SEVERITY (0 emergency .. 7 debug).
def logging_message(t_us: int, severity: int, text: str) -> bytes:
    level = ord("0") + min(max(int(severity), 0), 7)
    raw = text.encode(errors="replace")[:MAX_PAYLOAD - 9]
    return _message(b"L", struct.pack("<BQ", level, t_us) + raw)


def _file_sink(path: Path) -> tuple[Callable[[bytes], None], Callable[[], None]]:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)

    def write(data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]

    def close() -> None:
        os.fsync(fd)
        os.close(fd)

    return write, close


class ULogWriter:
    """An append-only ULog: definitions at open, then records; `flush` hands them to the
    kernel in one write.

    `sink` is a path (the file is created or truncated) or a bytearray (in-process runs).
    """

    def __init__(self, sink: str | Path | bytearray, topics: Sequence[Topic], *,
                 start_us: int = 0, info: Mapping[str, str | int | float] | None = None,
                 params: Mapping[str, int | float] | None = None) -> None:
        if isinstance(sink, bytearray):
            buffer = sink
            self._write: Callable[[bytes], None] = buffer.extend
            self._close: Callable[[], None] = lambda: None
            self.path: Path | None = None
        else:
            self.path = Path(sink)
            self._write, self._close = _file_sink(self.path)
        self._pending: list[bytes] = []
        self._ids: dict[str, tuple[int, struct.Struct]] = {}
        header = MAGIC + bytes([VERSION]) + struct.pack("<Q", start_us)
        flags = _message(b"B", bytes(8) + bytes(8) + bytes(24))
        parts = [header, flags]
        parts += [info_message(k, v) for k, v in (info or {}).items()]
        parts += [parameter_message(k, v) for k, v in (params or {}).items()]
        parts += [_message(b"F", t.format.encode()) for t in topics]
        for msg_id, t in enumerate(topics):
            if t.name in self._ids:
                raise ValueError(f"topic {t.name} declared twice")
            parts.append(_message(b"A", struct.pack("<BH", 0, msg_id) + t.name.encode()))
            payload = 2 + t.size
            self._ids[t.name] = (msg_id, struct.Struct(
                f"<HBH{t._struct.format[1:]}"))
            if payload > MAX_PAYLOAD:
                raise ValueError(f"topic {t.name}: records of {payload} bytes")
        self._write(b"".join(parts))
        self._closed = False

    def add(self, topic: str, values: Iterable[Any]) -> None:
        """Queue one record of `topic` (values in field order, arrays flattened)."""
        msg_id, s = self._ids[topic]
        self._pending.append(s.pack(s.size - 3, 68, msg_id, *values))  # 68 = 'D'

    def log(self, t_us: int, severity: int, text: str) -> None:
        """Queue a logged string (a STATUSTEXT, an event) at flight time t_us."""
        self._pending.append(logging_message(t_us, severity, text))

    def param(self, name: str, value: int | float) -> None:
        """Queue a parameter change (in the data section: it applies from here on)."""
        self._pending.append(parameter_message(name, value))

    def flush(self) -> None:
        if self._pending:
            data = b"".join(self._pending)
            self._pending.clear()
            self._write(data)

    def close(self) -> None:
        if self._closed:
            return
        self.flush()
        self._close()
        self._closed = True


# ---------------------------------------------------------------------------------------------
# Reading (pyulog, the reference reader)
# ---------------------------------------------------------------------------------------------

def open_ulog(path: str | Path, topics: Sequence[str] | None = None) -> Any:
    """The pyulog.ULog of a file, also of one whose writer was killed; only `topics` parsed
    (all if None)."""
    from pyulog import ULog

    path = Path(path)
    try:
        with path.open("rb") as fh:
            if fh.read(len(MAGIC)) != MAGIC:
                raise ULogError(f"{path}: not a ULog file")
        return ULog(str(path), list(topics) if topics is not None else None)
    except OSError as exc:
        raise ULogError(f"{path}: {exc.strerror}") from None
    except (struct.error, ValueError, IndexError, KeyError) as exc:
        if isinstance(exc, ULogError):
            raise
        raise ULogError(f"{path}: unreadable ULog ({type(exc).__name__}: {exc})") from None


def topic_rows(ulog: Any, name: str) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, float64 rows) of topic `name` in a pyulog.ULog; `timestamp` is named
    `time_us`. A topic declared but never written gives zero rows."""
    for d in ulog.data_list:
        if d.name == name and d.multi_id == 0:
            names = [f.field_name for f in d.field_data]
            cols = np.column_stack([np.asarray(d.data[n], dtype=np.float64) for n in names])
            return tuple("time_us" if n == "timestamp" else n for n in names), cols
    for fmt in ulog.message_formats.values():
        if fmt.name == name:
            names = []
            for _type, count, fname in fmt.fields:
                names += [f"{fname}[{i}]" for i in range(count)] if count else [fname]
            names = [n for n in names if not n.startswith("_padding")]
            return (tuple("time_us" if n == "timestamp" else n for n in names),
                    np.zeros((0, len(names))))
    raise ULogError(f"no topic {name} in the log")


def read_topic(path: str | Path, name: str) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, float64 rows) of one topic of a ULog file; the first column is time_us."""
    return topic_rows(open_ulog(path, [name]), name)


def _definitions(head: bytes, name: str) -> tuple[int, struct.Struct, tuple[str, ...]] | None:
    """(msg_id, record struct, column names) of topic `name` from a log's first bytes."""
    formats: dict[str, str] = {}
    pos = len(MAGIC) + 1 + 8
    while pos + 3 <= len(head):
        size, kind = _HEADER.unpack_from(head, pos)
        body = head[pos + 3:pos + 3 + size]
        if len(body) < size:
            return None
        if kind == ord("F"):
            text = body.decode(errors="replace")
            fmt_name, _, fields = text.partition(":")
            formats[fmt_name] = fields
        elif kind == ord("A") and body[3:].decode(errors="replace") == name:
            (msg_id,) = struct.unpack_from("<H", body, 1)
            codes, cols = [], []
            for f in filter(None, formats.get(name, "").split(";")):
                kind_name, fname = f.split(" ")
                base, _, count = kind_name.partition("[")
                n = int(count[:-1]) if count else 1
                codes.append(f"{n}{_CODES[base]}")
                cols += [f"{fname}[{i}]" for i in range(n)] if count else [fname]
            return msg_id, struct.Struct("<" + "".join(codes)), tuple(
                "time_us" if c == "timestamp" else c for c in cols)
        pos += 3 + size
    return None


def tail_record(path: str | Path, name: str, window: int = 1 << 16
                ) -> tuple[tuple[str, ...], tuple[float, ...]] | None:
    """(columns, values) of the last complete record of topic `name` in a log that may still
    be being written; None before its first record. Reads the definitions and the file's
    last `window` bytes only (cheap enough to poll)."""
    try:
        with Path(path).open("rb") as fh:
            head = fh.read(1 << 16)
            if not head.startswith(MAGIC):
                return None
            found = _definitions(head, name)
            if found is None:
                return None
            msg_id, record, cols = found
            end = fh.seek(0, os.SEEK_END)
            fh.seek(max(0, end - window))
            data = fh.read()
    except OSError:
        return None
    marker = _HEADER.pack(2 + record.size, ord("D")) + struct.pack("<H", msg_id)
    stop = len(data)
    while True:
        pos = data.rfind(marker, 0, stop)
        if pos < 0:
            return None
        after = pos + 5 + record.size
        # a complete record, followed by the end, a header still being written, or a header
        if after <= len(data) and (after + 3 > len(data) or data[after + 2:after + 3] in
                                   (b"D", b"L", b"P", b"A", b"O", b"S", b"C")):
            return cols, tuple(float(v) for v in record.unpack_from(data, pos + 5))
        stop = pos + len(marker) - 1
