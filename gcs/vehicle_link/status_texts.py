"""A vehicle's STATUSTEXT messages as texts, chunked ones put back together: the reasons a
vehicle gives during a mission upload (`gcs.vehicle_link.mission_client`)."""

from __future__ import annotations

from typing import Any

STATUSTEXT_LEN = 50


class StatusTexts:
    """STATUSTEXT messages as texts, chunked ones (MAVLink 2 `id` != 0) put back together: a
    chunk shorter than 50 characters ends its text. Runs of spaces are collapsed (chunks are
    padded at word boundaries) and a text equal to the previous one is kept once (a vehicle
    repeats its answer when the MISSION_ACK after it was lost)."""

    def __init__(self) -> None:
        self._done: list[str] = []
        self._open: dict[int, dict[int, str]] = {}

    @staticmethod
    def _joined(texts: list[str], text: str) -> list[str]:
        text = " ".join(text.split())
        return [*texts, text] if text and (not texts or texts[-1] != text) else texts

    def add(self, msg: Any) -> None:
        text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
        text = text.split("\0", 1)[0]
        text_id = getattr(msg, "id", 0)
        if not text_id:
            self._done = self._joined(self._done, text)
            return
        chunks = self._open.setdefault(text_id, {})
        chunks[getattr(msg, "chunk_seq", 0)] = text
        if len(text) < STATUSTEXT_LEN:
            del self._open[text_id]
            self._done = self._joined(self._done, "".join(chunks[k] for k in sorted(chunks)))

    @property
    def texts(self) -> tuple[str, ...]:
        """The texts so far, unfinished chunked ones included as far as they came."""
        out = self._done
        for chunks in self._open.values():
            out = self._joined(out, "".join(chunks[k] for k in sorted(chunks)))
        return tuple(out)
