"""The vehicle side of the MAVLink mission protocol (https://mavlink.io/en/services/mission.html),
without I/O: pymavlink messages and the time in, messages to send out.

Upload (GCS -> vehicle): MISSION_COUNT, then MISSION_REQUEST_INT for each item in turn,
re-requested every `item_timeout_s` up to `retries` times (then MISSION_ACK
OPERATION_CANCELLED); an out-of-sequence or duplicate item re-requests the expected one; after
the last item the whole mission is validated (`fcu.mission.check_mission`) and only
MAV_MISSION_ACCEPTED replaces the stored mission, so a failed upload keeps the old one. Every
refusal of a mission (`check_mission`: the item and what is wrong with it; a MISSION_COUNT
above the limit: the count and the limit) sends its reason as STATUSTEXT
(MAV_SEVERITY_WARNING) just before the MISSION_ACK, in chunks when longer than 50
characters (MAVLink 2's `id` and `chunk_seq`; every chunk but the last padded with spaces to
50 at a word boundary, so each also reads on its own). A final item sent again (the GCS lost
our MISSION_ACK) gets the same answer again, STATUSTEXT included.
The check runs where the server's `work` runs it (`fcu.work`: at once, or beside the control
loop): until it is done nothing is answered (MISSION_ACK goes out when it is, through
`outbox`), a final item sent again meanwhile is no new upload and gets no answer of its
own, a MISSION_COUNT from the same GCS starts a new upload (the pending check's result is
dropped), one from another GCS is DENIED as during an upload, a MISSION_CLEAR_ALL is done
(and answered) right after the check, and downloads return the mission in force. A check
that fails (its worker stopped) is MAV_MISSION_ERROR with why. `outbox` names the GCS each
of its answers goes to.
Download: MISSION_REQUEST_LIST -> MISSION_COUNT, then MISSION_ITEM_INT for each
MISSION_REQUEST_INT (or legacy MISSION_REQUEST). MISSION_CLEAR_ALL clears. Only
MAV_MISSION_TYPE_MISSION is supported; the other plan types get MAV_MISSION_UNSUPPORTED.

Frames: with a `home` (the FCU's, as HOME_POSITION publishes it), items in a global frame
with an altitude (GLOBAL / GLOBAL_INT: AMSL, GLOBAL_RELATIVE_ALT / _INT: above home) are
accepted and flown as their local NED equivalents (`fcu.mission.localize`); the server keeps
every item as it was uploaded, frame and coordinates, so a download returns the upload and
`on_mission_changed` gets the local items. A local item beyond the geofence is refused with
a STATUSTEXT that names MAVProxy's 1e7 scaling of local WPL files.

`version` changes on every accepted change and travels as `opaque_id` in MISSION_COUNT and
MISSION_ACK when the pymavlink dialect has that field (pymavlink 2.4.50 has not).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from common.wire.mavlink import MAV
from common.wire.mavlink_types import as_message
from common.wire.mavlink_types.protocol import (
    MissionCount,
    MissionItemInt,
    MissionRequest,
    MissionRequestInt,
    MissionSetCurrent,
)
from common.wire.mavlink_types.protocol import MissionItem as LegacyMissionItem
from common.wire.mission_items import HomePosition, MissionItem, item_from_message
from common.wire.mission_messages import item_message
from fcu.mission.limits import MissionLimits
from fcu.mission.validation import check_mission, localize, too_many
from fcu.work import InlineWork, Outcome, Work

M = MAV
MISSION = M.MAV_MISSION_TYPE_MISSION
Partner = tuple[int, int]  # (system id, component id)
STATUSTEXT_LEN = 50
__all__ = ["MissionServer", "item_from_message", "item_message", "statustext_chunks"]


@dataclass
class _Upload:
    partner: Partner
    count: int
    items: list[MissionItem] = field(default_factory=list)
    requested_s: float = 0.0
    retries_used: int = 0

    @property
    def expected(self) -> int:
        return len(self.items)


@dataclass(frozen=True)
class _Finished:
    """The last upload's outcome, to answer items the GCS sends again after our ACK."""

    partner: Partner
    count: int
    result: int
    notes: tuple[MAV.MAVLink_message, ...] = ()  # STATUSTEXT sent before the ACK


@dataclass(frozen=True, eq=False)
class _Checking:
    """An upload received whole, its check under way (`work`)."""

    partner: Partner
    count: int
    items: tuple[MissionItem, ...]
    # MISSION_CLEAR_ALLs that came meanwhile (partner, mission type): done right after it,
    # as they would have been had the check been done when the last item came
    clears: list[tuple[Partner, int]] = field(default_factory=list)


def _msg(cls: type[MAV.MAVLink_message], *args: object,
         opaque_id: int | None = None) -> MAV.MAVLink_message:
    """Build a message, adding opaque_id where this dialect version has the field."""
    if opaque_id is not None and "opaque_id" in cls.fieldnames:
        return cls(*args, opaque_id=opaque_id)
    return cls(*args)


def statustext_chunks(text: str, width: int = STATUSTEXT_LEN) -> list[str]:
    """`text` in STATUSTEXT chunks: split at word boundaries into pieces of at most
    width - 1 characters, all but the last padded with spaces to `width` (MAVLink 2: a
    chunk shorter than 50 characters ends the message)."""
    pieces: list[str] = []
    line = ""
    for word in text.split():
        while len(word) > width - 1:  # a word longer than a chunk: cut it
            if line:
                pieces.append(line)
                line = ""
            pieces.append(word[:width - 1])
            word = word[width - 1:]
        if not line:
            line = word
        elif len(line) + 1 + len(word) <= width - 1:
            line += " " + word
        else:
            pieces.append(line)
            line = word
    if line or not pieces:
        pieces.append(line)
    return [p.ljust(width) for p in pieces[:-1]] + [pieces[-1]]


class MissionServer:
    """One vehicle's mission store and protocol state (one upload at a time)."""

    def __init__(self, system_id: int, component_id: int, limits: MissionLimits,
                 item_timeout_s: float = 0.25, retries: int = 5,
                 home: HomePosition | None = None, work: Work | None = None) -> None:
        self.system_id = system_id
        self.work = work if work is not None else InlineWork()
        # answers that came after their message, each with the GCS it goes to
        self.outbox: list[tuple[Partner, MAV.MAVLink_message]] = []
        self.component_id = component_id
        self.limits = limits
        self.home = home  # converts global-frame items; None: only local ones are accepted
        self.item_timeout_s = item_timeout_s
        self.retries = retries
        self.mission: tuple[MissionItem, ...] = ()  # as uploaded (downloads return these)
        self.local_mission: tuple[MissionItem, ...] = ()  # as flown: local NED
        self.version = 0
        self._current_seq = 0
        # The current item lives with whoever flies the mission (the FCU's commander): it is
        # asked through `current` when set; a server on its own keeps its own.
        self.current: Callable[[], int] | None = None
        self.on_mission_changed: Callable[[tuple[MissionItem, ...]], None] | None = None
        self.on_set_current: Callable[[int], bool] | None = None
        self._upload: _Upload | None = None
        self._finished: _Finished | None = None
        self._checking: _Checking | None = None
        self._text_id = 0  # STATUSTEXT id of the last chunked text (1..65535)

    @property
    def uploading(self) -> bool:
        return self._upload is not None

    @property
    def checking(self) -> bool:
        """An upload received whole whose check has not answered yet."""
        return self._checking is not None

    # ------------------------------------------------------------------ replies

    def _ack(self, to: Partner, result: int, mission_type: int = MISSION,
             opaque: bool = False) -> MAV.MAVLink_message:
        return _msg(M.MAVLink_mission_ack_message, to[0], to[1], result, mission_type,
                    opaque_id=self.version if opaque else None)

    def _request(self, up: _Upload, now_s: float) -> MAV.MAVLink_message:
        up.requested_s = now_s
        return M.MAVLink_mission_request_int_message(up.partner[0], up.partner[1], up.expected,
                                                     MISSION)

    def _statustexts(self, text: str) -> tuple[MAV.MAVLink_message, ...]:
        """STATUSTEXT (MAV_SEVERITY_WARNING) carrying `text`, chunked when longer than 50."""
        chunks = statustext_chunks(text)
        text_id = 0
        if len(chunks) > 1:
            self._text_id = self._text_id % 0xFFFF + 1
            text_id = self._text_id
        return tuple(M.MAVLink_statustext_message(M.MAV_SEVERITY_WARNING, chunk.encode(),
                                                  text_id, i)
                     for i, chunk in enumerate(chunks))

    @property
    def current_seq(self) -> int:
        """The current item, sent as current = 1 on download."""
        return self.current() if self.current is not None else self._current_seq

    def _replace(self, items: tuple[MissionItem, ...]) -> None:
        self.mission = items
        self.local_mission = localize(items, self.home)
        self.version = (self.version + 1) & 0xFFFFFFFF or 1
        self._current_seq = 0
        if self.on_mission_changed is not None:
            self.on_mission_changed(self.local_mission)

    # ------------------------------------------------------------------ input

    def _for_us(self, msg: MAV.MAVLink_message) -> bool:
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, self.system_id) and tc in (0, self.component_id)

    def handle(self, msg: MAV.MAVLink_message, now_s: float) -> list[MAV.MAVLink_message]:
        """Messages to send in answer to `msg` received at `now_s` (any clock, seconds)."""
        kind = msg.get_type()
        if not kind.startswith("MISSION_") or not self._for_us(msg):
            return []
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        mission_type = getattr(msg, "mission_type", MISSION)
        if kind == "MISSION_SET_CURRENT":
            self._set_current(as_message(msg, MissionSetCurrent).seq)
            return []
        if kind == "MISSION_ACK":
            if self._upload is not None and self._upload.partner == partner:
                self._upload = None  # the GCS cancelled its upload: the old mission stays
            return []
        if kind in ("MISSION_WRITE_PARTIAL_LIST", "MISSION_REQUEST_PARTIAL_LIST"):
            return [self._ack(partner, M.MAV_MISSION_UNSUPPORTED, mission_type)]
        if kind == "MISSION_CLEAR_ALL":
            return self._clear_all(partner, mission_type)
        if kind not in ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM",
                        "MISSION_REQUEST_LIST", "MISSION_REQUEST_INT", "MISSION_REQUEST"):
            return []
        if mission_type != MISSION:
            return [self._ack(partner, M.MAV_MISSION_UNSUPPORTED, mission_type)]
        return self._transfer(kind, msg, partner, now_s)

    def _clear_all(self, partner: Partner, mission_type: int) -> list[MAV.MAVLink_message]:
        """MISSION_CLEAR_ALL of the mission (or of all types): the mission emptied."""
        if mission_type not in (MISSION, M.MAV_MISSION_TYPE_ALL):
            return [self._ack(partner, M.MAV_MISSION_UNSUPPORTED, mission_type)]
        if self._checking is not None:  # done after the upload being checked (`_clears`)
            self._checking.clears.append((partner, mission_type))
            return []
        self._replace(())
        return [self._ack(partner, M.MAV_MISSION_ACCEPTED, mission_type, opaque=True)]

    def _clears(self, checking: _Checking) -> None:
        """The MISSION_CLEAR_ALLs that came while `checking` was checked, done now: the
        mission emptied, each answered through `outbox`."""
        if checking.clears:
            self._replace(())
        for partner, mission_type in checking.clears:
            self.outbox.append((partner, self._ack(partner, M.MAV_MISSION_ACCEPTED,
                                                   mission_type, opaque=True)))
        checking.clears.clear()

    def _transfer(self, kind: str, msg: MAV.MAVLink_message, partner: Partner,
                  now_s: float) -> list[MAV.MAVLink_message]:
        """An upload's count and items, a download's list and item requests (the mission
        type's own, checked by `handle`)."""
        if kind == "MISSION_COUNT":
            return self._on_count(partner, as_message(msg, MissionCount).count, now_s)
        if kind == "MISSION_ITEM_INT":
            return self._on_item(partner, item_from_message(as_message(msg, MissionItemInt)),
                                 now_s)
        if kind == "MISSION_ITEM":
            return self._on_item(partner, item_from_message(as_message(msg, LegacyMissionItem)),
                                 now_s)
        if kind == "MISSION_REQUEST_LIST":
            return [_msg(M.MAVLink_mission_count_message, partner[0], partner[1],
                         len(self.mission), MISSION, opaque_id=self.version)]
        # MISSION_REQUEST_INT or MISSION_REQUEST: answered with MISSION_ITEM_INT either way.
        seq = as_message(msg, MissionRequestInt if kind == "MISSION_REQUEST_INT"
                         else MissionRequest).seq
        if not 0 <= seq < len(self.mission):
            return [self._ack(partner, M.MAV_MISSION_INVALID_SEQUENCE)]
        return [item_message(self.mission[seq], partner[0], partner[1],
                             current=int(seq == self.current_seq))]

    def _set_current(self, seq: int) -> None:
        if not 0 <= seq < len(self.mission):
            return
        ok = self.on_set_current(seq) if self.on_set_current is not None else True
        if ok:
            self._current_seq = seq

    def _on_count(self, partner: Partner, count: int,
                  now_s: float) -> list[MAV.MAVLink_message]:
        up, checking = self._upload, self._checking
        if (up is not None and up.partner != partner) or \
                (checking is not None and checking.partner != partner):
            return [self._ack(partner, M.MAV_MISSION_DENIED)]  # busy with another GCS
        self._upload = None
        if checking is not None:  # a new upload: the old one's check answers nothing,
            self._checking = None  # the clears that waited for it are done now
            self._clears(checking)
        self._finished = None
        if count > self.limits.max_items:
            return [*self._statustexts(too_many(count, self.limits)),
                    self._ack(partner, M.MAV_MISSION_NO_SPACE)]
        if count == 0:  # the same as clearing
            self._replace(())
            self._finished = _Finished(partner, 0, M.MAV_MISSION_ACCEPTED)
            return [self._ack(partner, M.MAV_MISSION_ACCEPTED, opaque=True)]
        self._upload = _Upload(partner, count)
        return [self._request(self._upload, now_s)]

    def _on_item(self, partner: Partner, item: MissionItem,
                 now_s: float) -> list[MAV.MAVLink_message]:
        up = self._upload
        checking = self._checking
        if up is None and checking is not None and checking.partner == partner:
            return []  # the last item again while it is checked: answered when it is
        if up is None or up.partner != partner:
            done = self._finished
            if up is None and done is not None and done.partner == partner \
                    and 0 <= item.seq < done.count:
                # Our final ACK was lost (or this is a late duplicate): the same answer again.
                return [*done.notes, self._ack(partner, done.result,
                                               opaque=done.result == M.MAV_MISSION_ACCEPTED)]
            return []
        if item.seq != up.expected:
            return [self._request(up, now_s)]  # out of sequence or duplicate: not an error
        up.items.append(item._replace(mission_type=MISSION))
        up.retries_used = 0
        if up.expected < up.count:
            return [self._request(up, now_s)]
        self._upload = None
        checking = self._checking = _Checking(partner, up.count, tuple(up.items))
        self.work.submit(check_mission, (checking.items, self.limits, self.home),
                         lambda outcome: self._checked(checking, outcome))
        return self._take_for(partner)  # done at once (inline): the answer now

    def _checked(self, checking: _Checking,
                 outcome: Outcome[tuple[int, int | None, str]]) -> None:
        """The check's answer: the mission replaced if it was accepted, the ACK queued."""
        if self._checking is not checking:
            return  # superseded by a new upload or a clear
        self._checking = None
        if outcome.value is None:
            result, reason = M.MAV_MISSION_ERROR, f"mission check failed: {outcome.error}"
        else:
            result, _seq, reason = outcome.value
        if result == M.MAV_MISSION_ACCEPTED:
            self._replace(checking.items)
        notes = self._statustexts(reason) if reason else ()
        self._finished = _Finished(checking.partner, checking.count, result, notes)
        self.outbox += [(checking.partner, m) for m in (
            *notes, self._ack(checking.partner, result, opaque=result == M.MAV_MISSION_ACCEPTED))]
        self._clears(checking)

    def take_outbox(self) -> list[tuple[Partner, MAV.MAVLink_message]]:
        """The answers queued since the last call, each with the GCS (system, component)
        it goes to: the uploader's, and those of clears that waited for its check."""
        out, self.outbox = self.outbox, []
        return out

    def _take_for(self, partner: Partner) -> list[MAV.MAVLink_message]:
        """The queued answers to `partner`, taken out of `outbox` (others stay)."""
        mine = [m for p, m in self.outbox if p == partner]
        self.outbox = [(p, m) for p, m in self.outbox if p != partner]
        return mine

    # ------------------------------------------------------------------ time

    def tick(self, now_s: float) -> list[MAV.MAVLink_message]:
        """Re-requests, or the cancellation of an upload whose items stopped coming."""
        up = self._upload
        if up is None or now_s - up.requested_s < self.item_timeout_s:
            return []
        if up.retries_used < self.retries:
            up.retries_used += 1
            return [self._request(up, now_s)]
        self._upload = None
        self._finished = _Finished(up.partner, up.count, M.MAV_MISSION_OPERATION_CANCELLED)
        return [self._ack(up.partner, M.MAV_MISSION_OPERATION_CANCELLED)]
