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
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from common.logs.errors import ULogError as ULogError  # raised here, named by the callers

MAGIC = b"ULog\x01\x12\x35"
VERSION = 1
_HEADER = struct.Struct("<HB")  # msg_size, msg_type
_CODES = {"uint64_t": "Q", "int64_t": "q", "uint32_t": "I", "int32_t": "i",
          "uint16_t": "H", "int16_t": "h", "uint8_t": "B", "int8_t": "b",
          "float": "f", "double": "d", "bool": "?", "char": "c"}
MAX_PAYLOAD = 0xFFFF


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
            count = f[2] if len(f) == 3 else 1
            codes.append(_code(f[0], count))
        object.__setattr__(self, "_struct", struct.Struct("<" + "".join(codes)))

    @property
    def format(self) -> str:
        """The format message's text: `name:type field;type[n] field;...`."""
        parts = []
        for f in self.fields:
            kind = f"{f[0]}[{f[2]}]" if len(f) == 3 else f[0]
            parts.append(f"{kind} {f[1]}")
        return f"{self.name}:" + ";".join(parts) + ";"

    @property
    def size(self) -> int:
        return self._struct.size

    @property
    def width(self) -> int:
        """Number of values a record takes (arrays flattened; a char[n] is one bytes)."""
        return sum(f[2] if len(f) == 3 and f[0] != "char" else 1
                   for f in self.fields)


def _code(type_name: str, count: int) -> str:
    """struct code of a field: char[n] is one bytes value, other arrays n values."""
    if type_name == "char":
        return f"{count}s"
    return f"{count}{_CODES[type_name]}" if count != 1 else _CODES[type_name]


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


class _FileSink:
    """A log file written with os.write: what the kernel took survives the process."""

    def __init__(self, path: Path) -> None:
        try:
            self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as exc:
            raise ULogError(f"{path}: {exc.strerror}") from None
        self.size = 0  # bytes of complete records

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self.fd, view):]
        except OSError:
            # Cut a torn record off, so the file stays readable to its last complete one.
            try:
                os.ftruncate(self.fd, self.size)
            except OSError:
                pass
            raise
        self.size += len(data)

    def close(self, beside: bool = False) -> None:
        """Synced to the disk, then closed; `beside`: in a thread of its own (the fsync
        takes tens of milliseconds; a control loop rotating its log must not wait for it;
        the interpreter waits for the thread before it exits)."""
        if beside:
            threading.Thread(target=self.close, name="ulog-close").start()
            return
        try:
            os.fsync(self.fd)
        except OSError:
            pass
        os.close(self.fd)


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
            self._close_beside: Callable[[], None] = self._close
            self.path: Path | None = None
        else:
            self.path = Path(sink)
            file = _FileSink(self.path)
            self._write, self._close = file.write, file.close
            self._close_beside = lambda: file.close(beside=True)
        self.failed = ""  # why writing stopped (a full disk, an I/O error); "" while it works
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
        try:
            self._write(b"".join(parts))
        except OSError as exc:
            self._close()
            raise ULogError(f"{self.path}: {exc.strerror}") from None
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
        """Hand the queued records to the kernel in one write. A write that fails (a full
        disk, an I/O error) stops the log where its last complete record ends and sets
        `failed`; the caller keeps flying and says so."""
        if not self._pending:
            return
        data = b"".join(self._pending)
        self._pending.clear()
        if self.failed:
            return
        try:
            self._write(data)
        except OSError as exc:
            self.failed = exc.strerror or type(exc).__name__

    def close(self, beside: bool = False) -> None:
        """The queued records written, the file synced and closed (`beside`: synced and
        closed in a thread of its own, `_FileSink.close`)."""
        if self._closed:
            return
        self.flush()
        (self._close_beside if beside else self._close)()
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
    except ULogError:
        raise
    except Exception as exc:  # pyulog raises its own and builtin exceptions on bad files
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


_KINDS = frozenset(b"ABCDFILMOPQS")


class _Layout(NamedTuple):
    msg_ids: dict[str, int]  # topic -> msg_id
    sizes: dict[int, int]  # msg_id -> payload size of its data messages
    records: dict[str, tuple[struct.Struct, tuple[str, ...]]]  # topic -> struct, columns


def _layout(head: bytes) -> _Layout:
    """Formats and subscriptions declared in a log's first bytes (this writer declares
    every subscription when it opens the log)."""
    formats: dict[str, str] = {}
    layout = _Layout({}, {}, {})
    pos = len(MAGIC) + 1 + 8
    while pos + 3 <= len(head):
        size, kind = _HEADER.unpack_from(head, pos)
        body = head[pos + 3:pos + 3 + size]
        if len(body) < size:
            break
        if kind == ord("F"):
            fmt_name, _, fields = body.decode(errors="replace").partition(":")
            formats[fmt_name] = fields
        elif kind == ord("A"):
            name = body[3:].decode(errors="replace")
            (msg_id,) = struct.unpack_from("<H", body, 1)
            codes, cols = [], []
            for f in filter(None, formats.get(name, "").split(";")):
                kind_name, fname = f.split(" ")
                base, _, count = kind_name.partition("[")
                n = int(count[:-1]) if count else 1
                codes.append(_code(base, n))
                cols += ([f"{fname}[{i}]" for i in range(n)] if count and base != "char"
                         else [fname])
            record = struct.Struct("<" + "".join(codes))
            layout.msg_ids[name] = msg_id
            layout.sizes[msg_id] = 2 + record.size
            layout.records[name] = (record, tuple(
                "time_us" if c == "timestamp" else c for c in cols))
        pos += 3 + size
    return layout


def _chain_to_end(data: bytes, pos: int, sizes: dict[int, int]) -> bool:
    """Whether messages from `pos` follow one another to the end of `data`: known types,
    data messages of a declared topic and of its size (the last one may be torn)."""
    while pos + 3 <= len(data):
        size, kind = _HEADER.unpack_from(data, pos)
        if kind not in _KINDS:
            return False
        if kind == ord("D") and pos + 5 <= len(data):
            (msg_id,) = struct.unpack_from("<H", data, pos + 3)
            if sizes.get(msg_id) != size:
                return False
        pos += 3 + size
    return True


def tail_record(path: str | Path, name: str, window: int = 1 << 16
                ) -> tuple[tuple[str, ...], tuple[float | bytes, ...]] | None:
    """(columns, values) of the last complete record of topic `name` in a log that may still
    be being written; None before its first record. Reads the definitions and the end of
    the file, from `window` bytes back, further back until a record is found (cheap enough
    to poll). A candidate counts only if the messages after it chain to the end of the file,
    so a byte pattern inside another record's payload is not taken for a record."""
    try:
        with Path(path).open("rb") as fh:
            head = fh.read(1 << 16)
            if not head.startswith(MAGIC):
                return None
            layout = _layout(head)
            if name not in layout.msg_ids:
                return None
            msg_id = layout.msg_ids[name]
            record, cols = layout.records[name]
            end = fh.seek(0, os.SEEK_END)
            marker = _HEADER.pack(2 + record.size, ord("D")) + struct.pack("<H", msg_id)
            while True:
                start = max(0, end - window)
                fh.seek(start)
                data = fh.read(end - start)
                stop = len(data)
                while (pos := data.rfind(marker, 0, stop)) >= 0:
                    after = pos + 5 + record.size
                    if after <= len(data) and _chain_to_end(data, after, layout.sizes):
                        return cols, tuple(v if isinstance(v, bytes) else float(v)
                                           for v in record.unpack_from(data, pos + 5))
                    stop = pos + len(marker) - 1
                if start == 0:
                    return None
                window *= 4
    except OSError:
        return None
