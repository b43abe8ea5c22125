"""The one place that imports pymavlink: MAVLink 2, `common` dialect, pinned here.

pymavlink picks MAVLink 1 or 2 from the environment at import time; setting MAVLINK20 before
the first import and importing the v2.0 dialect module directly makes the choice explicit.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import types
from typing import Any

os.environ["MAVLINK20"] = "1"

from pymavlink.dialects.v20 import common as mavlink

MAV = mavlink
MAV_COMP_ID_AUTOPILOT1 = mavlink.MAV_COMP_ID_AUTOPILOT1
MAV_COMP_ID_MISSIONPLANNER = mavlink.MAV_COMP_ID_MISSIONPLANNER
GCS_SYSID = 255
MAV_CMD_POSE_KEYFRAME = mavlink.MAV_CMD_WAYPOINT_USER_1  # 31000 (docs/autopilot.md#missions)
MAV_CMD_FIGURE_EIGHT = mavlink.MAV_CMD_WAYPOINT_USER_2  # 31001


class _Sink:
    """A file-like that keeps nothing: encoders here return bytes, links send them."""

    def write(self, _data: bytes) -> None:
        return None


def encoder(system_id: int, component_id: int) -> mavlink.MAVLink:
    """A MAVLink 2 encoder/decoder with its own sequence counter (one per sender)."""
    mav = mavlink.MAVLink(_Sink(), srcSystem=system_id, srcComponent=component_id,
                          use_native=False)
    mav.robust_parsing = True
    return mav


def parser() -> mavlink.MAVLink:
    """A decoder for one incoming byte stream (one per link and peer)."""
    return encoder(0, 0)


SignatureStream = tuple[int, int, int]  # (link id, system id, component id) of a signed stream


def _check_signature(mav: Any, msgbuf: bytearray, srcSystem: int, srcComponent: int) -> bool:
    """MAVLink.check_signature that refuses unsigned and wrongly signed frames, and records
    a stream's timestamp only once the signature is right: pymavlink records it before
    comparing, so one forged frame with a far timestamp would lock the real sender out of
    its stream. (`mav` is a pymavlink MAVLink, untyped.)"""
    signing = mav.signing
    key = signing.secret_key
    if key is None or len(msgbuf) < 13:
        return False
    digest = hashlib.sha256(bytes(key) + bytes(msgbuf[:-6])).digest()[:6]
    if not hmac.compare_digest(digest, bytes(msgbuf[-6:])):
        return False
    tlow, thigh = mav.mav_sign_unpacker.unpack(msgbuf[-12:-6])
    timestamp = tlow + (thigh << 32)
    stream = (msgbuf[-13], srcSystem, srcComponent)
    last = signing.stream_timestamps.get(stream)
    if last is not None and timestamp <= last:
        return False  # replayed or old
    if last is None and timestamp + 6000 * 1000 < signing.timestamp:
        return False  # a new stream more than a minute behind our clock
    signing.stream_timestamps[stream] = timestamp
    signing.timestamp = max(signing.timestamp, timestamp)
    return True


def signed_parser(key: bytes,
                  stream_timestamps: dict[SignatureStream, int] | None = None) -> mavlink.MAVLink:
    """A decoder that accepts only frames signed with `key` (MAVLink 2 signing), sharing
    replay protection through `stream_timestamps` with other parsers of the same links.
    Its check_signature is `_check_signature`, bound to this parser alone."""
    p = mavlink.MAVLink(_Sink(), srcSystem=0, srcComponent=0, use_native=False)
    p.check_signature = types.MethodType(_check_signature, p)
    p.robust_parsing = True
    p.signing.secret_key = key
    p.signing.timestamp = signing_timestamp()
    if stream_timestamps is not None:
        p.signing.stream_timestamps = stream_timestamps
    return p


def pack(mav: mavlink.MAVLink, msg: mavlink.MAVLink_message) -> bytes:
    """Encode a message with `mav`'s identity and next sequence number (as MAVLink.send)."""
    data: bytes = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return data


class SigningKeyError(ValueError):
    """A signing key file that is missing, unreadable or not 32 bytes."""


def read_signing_key(path: str) -> bytes:
    """A MAVLink 2 signing key: a file holding 64 hexadecimal characters (`gcs keygen`) or
    exactly 32 raw bytes."""
    try:
        raw = open(path, "rb").read()
    except OSError as exc:
        raise SigningKeyError(f"signing key {path}: {exc.strerror}") from None
    text = raw.strip()
    if len(text) == 64:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    if len(raw) == 32:
        return raw
    raise SigningKeyError(f"signing key {path}: expected 64 hex characters or 32 bytes")


def signing_timestamp() -> int:
    """Now in the signing clock: 10 us units since 2015-01-01 (MAVLink signing spec)."""
    import time

    return int((max(time.time(), 1420070400) - 1420070400) * 100_000)
