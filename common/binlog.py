"""Append-only binary logs of float64 rows (the plant's truth log, the FCU's onboard log).

Layout: a 4096-byte header (`DQLOG2 {"columns": [...]}` padded with spaces, then the row
count as a little-endian uint64 in its last 8 bytes), then rows of little-endian float64.
The writer maps the file into memory and updates the row count after each row: the rows live
in the kernel's page cache the moment they are written, so after SIGKILL of the writer every
complete row before the kill is readable, without a system call per row in the control loop.
A clean close truncates the file to its rows. The first column is time_usec.
"""

from __future__ import annotations

import json
import mmap
import os
import struct
from pathlib import Path

import numpy as np

MAGIC = b"DQLOG2 "
HEADER = 4096
_COUNT = struct.Struct("<Q")
_GROW = 1 << 20  # map the file in steps of 1 MiB


def _header(columns: tuple[str, ...]) -> bytes:
    text = MAGIC + json.dumps({"columns": list(columns)}).encode()
    if len(text) > HEADER - _COUNT.size - 1:
        raise ValueError("too many columns for the log header")
    return text + b"\n" + b" " * (HEADER - _COUNT.size - len(text) - 1)


class LogWriter:
    def __init__(self, path: str | Path, columns: tuple[str, ...]) -> None:
        self.path = Path(path)
        self.columns = columns
        self._row = struct.Struct(f"<{len(columns)}d")
        self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        os.write(self._fd, _header(columns) + _COUNT.pack(0))
        self._size = 0
        self._map: mmap.mmap | None = None
        self._rows = 0
        self._grow(HEADER + _GROW)

    def _grow(self, size: int) -> None:
        if self._map is not None:
            self._map.close()
        os.ftruncate(self._fd, size)
        self._map = mmap.mmap(self._fd, size)
        self._size = size

    def write(self, row: tuple[float, ...] | list[float]) -> None:
        offset = HEADER + self._rows * self._row.size
        if offset + self._row.size > self._size:
            self._grow(self._size + _GROW)
        m = self._map
        self._row.pack_into(m, offset, *row)
        self._rows += 1
        _COUNT.pack_into(m, HEADER - _COUNT.size, self._rows)  # the row is complete

    @property
    def rows(self) -> int:
        return self._rows

    def close(self) -> None:
        if self._map is None:
            return
        self._map.flush()
        self._map.close()
        self._map = None
        os.ftruncate(self._fd, HEADER + self._rows * self._row.size)
        os.fsync(self._fd)
        os.close(self._fd)


def read_log(path: str | Path) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, rows) of a log, also of one whose writer was killed mid-run."""
    raw = Path(path).read_bytes()
    if not raw.startswith(MAGIC) or len(raw) < HEADER:
        raise ValueError(f"{path}: not a DQLOG2 file")
    columns = tuple(json.loads(raw[len(MAGIC):raw.index(b"\n")])["columns"])
    (count,) = _COUNT.unpack_from(raw, HEADER - _COUNT.size)
    width = 8 * len(columns)
    count = min(count, (len(raw) - HEADER) // width)
    body = raw[HEADER:HEADER + count * width]
    return columns, np.frombuffer(body, dtype="<f8").reshape(-1, len(columns)).copy()


def write_log(path: str | Path, columns: tuple[str, ...], rows: np.ndarray) -> None:
    """A whole log at once (in-process runs)."""
    rows = np.ascontiguousarray(rows, dtype="<f8")
    with Path(path).open("wb") as fh:
        fh.write(_header(columns) + _COUNT.pack(len(rows)))
        fh.write(rows.tobytes())
