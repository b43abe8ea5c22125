"""Append-only binary logs of float64 rows (the plant's truth log, the FCU's onboard log).

Layout: one header line `DQLOG1 {"columns": [...]}\\n`, then rows of little-endian float64.
Rows are written whole and flushed in batches, so a reader after a crash sees every complete
row before the last flush; a trailing partial row is ignored. The first column is time_usec.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np

MAGIC = b"DQLOG1 "


class LogWriter:
    def __init__(self, path: str | Path, columns: tuple[str, ...], flush_rows: int = 256,
                 ) -> None:
        self.path = Path(path)
        self.columns = columns
        self._row = struct.Struct(f"<{len(columns)}d")
        self._fh = self.path.open("wb")
        self._fh.write(MAGIC + json.dumps({"columns": list(columns)}).encode() + b"\n")
        self._fh.flush()
        self._pending: list[bytes] = []
        self._flush_rows = flush_rows

    def write(self, row: tuple[float, ...] | list[float]) -> None:
        self._pending.append(self._row.pack(*row))
        if len(self._pending) >= self._flush_rows:
            self.flush()

    def flush(self) -> None:
        if self._pending:
            self._fh.write(b"".join(self._pending))
            self._pending.clear()
        self._fh.flush()

    def close(self) -> None:
        if not self._fh.closed:
            self.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()


def read_log(path: str | Path) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, rows) of a log; a partial last row (crash mid-write) is dropped."""
    raw = Path(path).read_bytes()
    if not raw.startswith(MAGIC):
        raise ValueError(f"{path}: not a DQLOG1 file")
    end = raw.index(b"\n")
    columns = tuple(json.loads(raw[len(MAGIC):end])["columns"])
    body = raw[end + 1:]
    width = 8 * len(columns)
    body = body[: len(body) - len(body) % width]
    return columns, np.frombuffer(body, dtype="<f8").reshape(-1, len(columns)).copy()


def write_log(path: str | Path, columns: tuple[str, ...], rows: np.ndarray) -> None:
    writer = LogWriter(path, columns)
    for row in np.asarray(rows, dtype=float):
        writer.write(tuple(row))
    writer.close()
