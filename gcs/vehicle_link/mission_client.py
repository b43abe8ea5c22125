"""The ground-station side of the MAVLink mission protocol over a pymavlink `mavutil`
connection: upload, download and clear (https://mavlink.io/en/services/mission.html).

How long each answer is waited for is the station's policy (`gcs.vehicle_link.patience`): the last
message is re-sent at the specification's timeouts (1500 ms for the whole-transaction steps
MISSION_COUNT, MISSION_REQUEST_LIST, MISSION_CLEAR_ALL; 250 ms per mission item) for as long
as the vehicle is heard (any message of its system: a vehicle checking a mission still sends
its HEARTBEAT), and the transaction fails only when the vehicle falls silent (SILENCE_S) or
an answer has not come within its ceiling (30 s), the error saying which. Messages from
other systems, for other systems or about other plan types are skipped. Wall-clock time is
fine here: the GCS faces links.

Lossy links duplicate and delay answers, and MAVLink 2 as pymavlink knows it has no
transaction id (no `opaque_id`), so answers of an earlier transaction can arrive during the
next one. Each transaction therefore starts by dropping the input already waiting, and what
keeps coming until no mission answer has come for `settle_s` (50 ms: a link's reordering
time); an upload takes MAV_MISSION_ACCEPTED only once the vehicle has asked for the last item
and an item's error only once it has had an item (earlier ones answer an earlier
transaction); a download that hears a second MISSION_COUNT with another count fails (the
mission changed, or the first count was stale), never returning a mission of the wrong
length.
Pass `send=` (e.g. `Session.send`) when another thread sends on the same connection, so
that sends stay serialised; by default `conn.mav.send` is used.

An upload also collects the STATUSTEXT that the vehicle sends while it runs: a vehicle that
refuses a mission says why just before its MISSION_ACK (e.g. "item 3: needs 1903 rad/s >
1445 (85% of 1700): lengthen p1 to 0.87 s"). `upload_detailed` returns them with the result;
chunked texts (MAVLink 2 `id`, `chunk_seq`) are put back together.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple, Protocol

import common.wire.mavlink  # noqa: F401  (pins MAVLink 2 before anything imports mavutil)
from common.wire.mavlink import MAV
from common.wire.mission_items import HomePosition, MissionItem, item_from_message
from common.wire.mission_messages import item_message
from gcs.vehicle_link.patience import (
    MISSION_ITEM,
    MISSION_STEP,
    SILENCE_S,
    Budget,
    Wait,
    from_target,
)
from gcs.vehicle_link.status_texts import StatusTexts

M = MAV
MISSION = M.MAV_MISSION_TYPE_MISSION
TIMEOUT_S = MISSION_STEP.resend_s  # the spec's whole-transaction timeout: re-send after it
ITEM_TIMEOUT_S = MISSION_ITEM.resend_s  # the spec's per-item timeout
CEILING_S = MISSION_ITEM.ceiling_s  # an answer not come by then is given up, heard or not
# After the last item a vehicle may check the whole mission before its MISSION_ACK (this
# FCU's envelope check, ArduPilot's and PX4's storage): like every answer it is waited for
# while the vehicle is heard, up to CEILING_S.
SETTLE_S = 0.05  # a transaction starts after this long without a stale mission answer
_ANSWERS = {"MISSION_ACK", "MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_COUNT",
            "MISSION_ITEM", "MISSION_ITEM_INT"}
# Results that refer to items: a vehicle cannot send them before it has had an item.
_ITEM_RESULTS = {M.MAV_MISSION_UNSUPPORTED_FRAME, M.MAV_MISSION_UNSUPPORTED,
                 M.MAV_MISSION_INVALID_PARAM1, M.MAV_MISSION_INVALID_PARAM2,
                 M.MAV_MISSION_INVALID_PARAM3, M.MAV_MISSION_INVALID_PARAM4,
                 M.MAV_MISSION_INVALID_PARAM5_X, M.MAV_MISSION_INVALID_PARAM6_Y,
                 M.MAV_MISSION_INVALID_PARAM7, M.MAV_MISSION_INVALID_SEQUENCE}

Progress = Callable[[int, int], None]


class Connection(Protocol):
    """What the mission client uses of a pymavlink connection (`mavutil.mavfile`, or
    `gcs.vehicle_link.session.LinkFile`): its encoder (`mav`: srcSystem, send) and `recv_match`."""

    mav: Any

    def recv_match(self, condition: str | None = None, type: str | list[str] | None = None,
                   blocking: bool = False, timeout: float | None = None) -> Any: ...


class MissionError(RuntimeError):
    """A mission transaction that could not be completed (no answer, protocol error)."""


def result_name(result: int) -> str:
    entry = M.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry is not None else f"MAV_MISSION_RESULT {result}"


Send = Callable[[MAV.MAVLink_message], None]


def _sender(conn: Connection, send: Send | None) -> Send:
    """`send` if given (e.g. a session's locked send), else the connection's own."""
    return send if send is not None else conn.mav.send


def _drain(conn: Connection, target_system: int, quiet_s: float, limit_s: float = 0.5) -> None:
    """Drop the input waiting on `conn`, then keep dropping until no mission answer from
    `target_system` to us has come for `quiet_s` (at most `limit_s`): late duplicates of an
    earlier transaction's answers, within the link's reordering time, must not be taken for
    this one's."""
    me = conn.mav.srcSystem
    start = time.monotonic()
    quiet_until = start + quiet_s
    while (now := time.monotonic()) < quiet_until and now - start < limit_s:
        msg = conn.recv_match(blocking=quiet_s > 0, timeout=max(0.001, quiet_until - now))
        if msg is None:
            if quiet_s <= 0:
                return
            continue
        if msg.get_type() in _ANSWERS and msg.get_srcSystem() == target_system and \
                getattr(msg, "target_system", 0) in (0, me):
            quiet_until = time.monotonic() + quiet_s


def _recv(conn: Connection, types: list[str], target_system: int, target_component: int,
          timeout_s: float, wait: Wait | None = None) -> Any:
    """The next message of `types` from the target about missions, or None on timeout;
    every message of the target (its component, when given) heard meanwhile is noted in
    `wait`."""
    deadline = time.monotonic() + timeout_s
    me = conn.mav.srcSystem
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            return None
        msg = conn.recv_match(blocking=True, timeout=remaining)
        if not from_target(msg, target_system, target_component):
            continue  # none, bad data, or another component of its system: not heard
        if wait is not None:
            wait.heard()
        if msg.get_type() not in types:
            continue
        if getattr(msg, "target_system", 0) not in (0, me):
            continue
        if getattr(msg, "mission_type", MISSION) != MISSION:
            continue
        return msg


def _is_item(seq: int) -> Callable[[Any], bool]:
    """Whether a mission item message is item `seq`."""
    return lambda msg: bool(msg.seq == seq)


def _item_from(msg: Any) -> MissionItem:
    item = item_from_message(msg)
    if not item.xy_fit_int32:  # a legacy MISSION_ITEM with a non-finite or huge x or y
        raise MissionError(f"mission download: item {msg.seq} has an x or y that is not "
                           "finite or does not fit MISSION_ITEM_INT")
    return item


class UploadResult(NamedTuple):
    """The vehicle's answer to an upload: MAV_MISSION_RESULT and what it said meanwhile."""

    result: int
    notes: tuple[str, ...] = ()  # STATUSTEXT from the vehicle during the upload
    asked: int = -1  # the highest seq the vehicle asked for (-1: none): a refused item's

    @property
    def accepted(self) -> bool:
        return bool(self.result == M.MAV_MISSION_ACCEPTED)

    @property
    def about_item(self) -> bool:
        """Whether the result names a fault of an item (the last one the vehicle asked
        for, `asked`), rather than of the whole mission."""
        return self.result in _ITEM_RESULTS and self.asked >= 0

    def describe(self) -> str:
        """e.g. "MAV_MISSION_DENIED: item 3: needs 1903 rad/s > 1445 (85% of 1700): ..." """
        return ": ".join([result_name(self.result), *self.notes])


def _budgets(timeout_s: float, item_timeout_s: float, silence_s: float,
             ceiling_s: float) -> tuple[Budget, Budget]:
    """The transaction step's and the item's budgets with the caller's figures."""
    return (MISSION_STEP.but(resend_s=timeout_s, silence_s=silence_s, ceiling_s=ceiling_s),
            MISSION_ITEM.but(resend_s=item_timeout_s, silence_s=silence_s,
                             ceiling_s=ceiling_s))


def upload(conn: Connection, target_system: int, target_component: int,
           items: Sequence[MissionItem],
           progress: Progress | None = None, *, timeout_s: float = TIMEOUT_S,
           item_timeout_s: float = ITEM_TIMEOUT_S, silence_s: float = SILENCE_S,
           ceiling_s: float = CEILING_S, send: Send | None = None,
           settle_s: float = SETTLE_S, notes: list[str] | None = None) -> int:
    """Upload `items` (sent with seq = their index) and return the vehicle's
    MAV_MISSION_RESULT (MAV_MISSION_ACCEPTED when it took the mission); the texts of the
    STATUSTEXT it sent meanwhile are appended to `notes` when given (`upload_detailed`).

    The last message is re-sent each `timeout_s` (MISSION_COUNT) or `item_timeout_s` (an
    item) without an answer. Raises MissionError when the vehicle falls silent for
    `silence_s`, when an answer has not come within `ceiling_s`, or when it asks for an
    item outside the mission.
    """
    answer = upload_detailed(conn, target_system, target_component, items, progress,
                             timeout_s=timeout_s, item_timeout_s=item_timeout_s,
                             silence_s=silence_s, ceiling_s=ceiling_s, send=send,
                             settle_s=settle_s)
    if notes is not None:
        notes.extend(answer.notes)
    return answer.result


def upload_detailed(conn: Connection, target_system: int, target_component: int,
                    items: Sequence[MissionItem], progress: Progress | None = None, *,
                    timeout_s: float = TIMEOUT_S, item_timeout_s: float = ITEM_TIMEOUT_S,
                    silence_s: float = SILENCE_S, ceiling_s: float = CEILING_S,
                    send: Send | None = None, settle_s: float = SETTLE_S) -> UploadResult:
    """`upload`, returning the result with the STATUSTEXT texts that the target system sent
    during the upload (a refusal's reason comes just before the MISSION_ACK).

    Raises MissionError as `upload` does.
    """
    _send = _sender(conn, send)
    step, per_item = _budgets(timeout_s, item_timeout_s, silence_s, ceiling_s)
    texts = StatusTexts()
    items = [item._replace(seq=i, mission_type=MISSION) for i, item in enumerate(items)]
    count = len(items)
    _drain(conn, target_system, settle_s)
    last = M.MAVLink_mission_count_message(target_system, target_component, count, MISSION)
    _send(last)
    wait, done = Wait(step), -1  # done: highest seq requested so far
    sent_items: set[int] = set()
    repeats = 0  # items sent again: each may draw ArduPilot's NACK (`_ack_meaning`)
    types = ["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "STATUSTEXT"]
    while True:
        if wait.due() and not wait.expired():
            _send(last)
            wait.sent()
            repeats += done >= 0  # an item sent again (MISSION_COUNT is not an item)
        msg = _recv(conn, types, target_system, target_component, wait.left(), wait)
        if msg is not None and msg.get_type() == "STATUSTEXT":
            texts.add(msg)
            continue
        if msg is None:
            if why := wait.expired():
                _send(M.MAVLink_mission_ack_message(
                    target_system, target_component, M.MAV_MISSION_OPERATION_CANCELLED,
                    MISSION))
                raise _upload_unanswered(target_system, count, done,
                                         f"{why}{wait.tries_text()}", texts.texts)
            continue
        if msg.get_type() == "MISSION_ACK":
            meaning = _ack_meaning(msg.type, done, count, repeats)
            repeats -= meaning == _REPEATED
            if meaning in (_EARLIER, _REPEATED):
                continue
            if meaning:
                raise _upload_unanswered(target_system, count, done, meaning, texts.texts)
            if msg.type == M.MAV_MISSION_ACCEPTED and progress is not None:
                progress(count, count)
            return UploadResult(msg.type, texts.texts, done)
        seq = msg.seq
        _check_asked(_send, target_system, target_component, seq, count)
        if seq > done:  # progress: the vehicle holds items 0..seq-1; the next answer's wait
            done = seq
            wait = Wait(per_item)
            if progress is not None:
                progress(seq, count)
        else:  # a repeated request (ours or its re-request): the wait goes on
            wait.sent()
        last = item_message(items[seq], target_system, target_component)
        _send(last)
        repeats += seq in sent_items
        sent_items.add(seq)


def _check_asked(send: Send, target_system: int, target_component: int, seq: int,
                 count: int) -> None:
    """A request for item `seq` outside the mission: MAV_MISSION_INVALID_SEQUENCE to the
    vehicle, MissionError raised."""
    if not 0 <= seq < count:
        send(M.MAVLink_mission_ack_message(target_system, target_component,
                                           M.MAV_MISSION_INVALID_SEQUENCE, MISSION))
        raise MissionError(f"mission upload to system {target_system}: vehicle asked for "
                           f"item {seq} of a mission of {count}")


def _upload_unanswered(target_system: int, count: int, done: int, why: str,
                       texts: Sequence[str]) -> MissionError:
    """The error of an upload the vehicle stopped answering: what was awaited (with `done`
    the highest item requested, -1 none), why the wait ended, what the vehicle said."""
    held = ""
    if done < 0:
        what = f"answer to MISSION_COUNT({count})"
    elif done == count - 1:
        what = f"MISSION_ACK after the last item ({done})"
        held = "; the vehicle may hold the new mission"
    else:
        what = f"request for the item after {done}"
    said = "".join(f"; the vehicle said: {t}" for t in texts)
    return MissionError(f"mission upload to system {target_system}: no {what}{why}{held}"
                        f"{said}")


_EARLIER, _REPEATED = "earlier", "repeated"  # MISSION_ACKs that are not the answer


def _ack_meaning(result: int, done: int, count: int, repeats: int) -> str:
    """What a MISSION_ACK during an upload says: '' the answer; _EARLIER an earlier
    transaction's (`_earlier_ack`); _REPEATED ArduPilot's NACK to an item sent again (of
    which `repeats` are not answered so yet): during its upload it answers an item it did
    not ask for with MAV_MISSION_INVALID_SEQUENCE and goes on (wait for its next request);
    else why the outcome is unknown: after its upload it answers any item with
    MAV_MISSION_ERROR, so after the last item sent again its MISSION_ACK to the first was
    lost. PX4 ignores the first and answers the last item again with its MISSION_ACK."""
    if _earlier_ack(result, done, count):
        return _EARLIER
    if repeats <= 0:
        return ""
    if result == M.MAV_MISSION_INVALID_SEQUENCE:
        return _REPEATED
    if result == M.MAV_MISSION_ERROR and done == count - 1:
        return (": the vehicle answered the last item sent again with MAV_MISSION_ERROR, "
                "as ArduPilot answers an item after its upload is over (its MISSION_ACK "
                "was lost)")
    return ""


def _earlier_ack(result: int, done: int, count: int) -> bool:
    """Whether a MISSION_ACK during an upload belongs to an earlier transaction: accepted
    before the vehicle had every item, or about an item before one was sent."""
    if result == M.MAV_MISSION_ACCEPTED and done < count - 1:
        return True  # the vehicle has not had every item: an earlier transaction's ACK
    return result in _ITEM_RESULTS and done < 0  # about an item, before we have sent one


def download(conn: Connection, target_system: int, target_component: int,
             progress: Progress | None = None, *, timeout_s: float = TIMEOUT_S,
             item_timeout_s: float = ITEM_TIMEOUT_S, silence_s: float = SILENCE_S,
             ceiling_s: float = CEILING_S, send: Send | None = None,
             settle_s: float = SETTLE_S) -> list[MissionItem]:
    """The vehicle's mission. Each request is re-sent as `upload`'s are; MissionError when
    the vehicle falls silent, an answer does not come within the ceiling, it refuses, or
    its mission changes during the download."""
    _send = _sender(conn, send)
    step, per_item = _budgets(timeout_s, item_timeout_s, silence_s, ceiling_s)
    _drain(conn, target_system, settle_s)
    counts: list[int] = []

    def exchange(request: Any, types: list[str], budget: Budget,
                 accept: Callable[[Any], bool], what: str) -> Any:
        _send(request)
        wait = Wait(budget)
        while not (why := wait.expired()):
            if wait.due():
                _send(request)
                wait.sent()
            msg = _recv(conn, types, target_system, target_component, wait.left(), wait)
            if msg is None:
                continue
            if msg.get_type() == "MISSION_ACK":
                if msg.type == M.MAV_MISSION_ACCEPTED:
                    continue  # a late ACK of an earlier transaction
                raise MissionError(f"mission download from system {target_system}: "
                                   f"{what} refused: {result_name(msg.type)}")
            if msg.get_type() == "MISSION_COUNT" and counts:
                if msg.count != counts[0]:
                    raise MissionError(
                        f"mission download from system {target_system}: MISSION_COUNT "
                        f"{counts[0]}, then {msg.count}: the mission changed (or an "
                        "answer was stale); try again")
                continue  # a duplicate of the count we have
            if accept(msg):
                return msg
        raise MissionError(f"mission download from system {target_system}: no answer to "
                           f"{what}{why}{wait.tries_text()}")

    count_msg = exchange(
        M.MAVLink_mission_request_list_message(target_system, target_component, MISSION),
        ["MISSION_COUNT", "MISSION_ACK"], step, lambda m: True, "MISSION_REQUEST_LIST")
    count = count_msg.count
    counts.append(count)
    items: list[MissionItem] = []
    for seq in range(count):
        msg = exchange(
            M.MAVLink_mission_request_int_message(target_system, target_component, seq,
                                                  MISSION),
            ["MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_ACK", "MISSION_COUNT"],
            per_item, _is_item(seq), f"the request for item {seq} of {count}")
        items.append(_item_from(msg))
        if progress is not None:
            progress(seq + 1, count)
    _send(M.MAVLink_mission_ack_message(target_system, target_component,
                                              M.MAV_MISSION_ACCEPTED, MISSION))
    return items


def clear(conn: Connection, target_system: int, target_component: int, *,
          timeout_s: float = TIMEOUT_S, silence_s: float = SILENCE_S,
          ceiling_s: float = CEILING_S, send: Send | None = None,
          settle_s: float = SETTLE_S) -> int:
    """Clear the vehicle's mission; its MAV_MISSION_RESULT. MISSION_CLEAR_ALL is re-sent
    each `timeout_s` without an answer; MissionError on silence or at the ceiling."""
    return _one_answer(conn, target_system, target_component,
                       M.MAVLink_mission_clear_all_message(target_system, target_component,
                                                           MISSION),
                       MISSION_STEP.but(resend_s=timeout_s, silence_s=silence_s,
                                        ceiling_s=ceiling_s),
                       send, settle_s, f"mission clear on system {target_system}")


def set_current(conn: Connection, target_system: int, target_component: int, seq: int, *,
                timeout_s: float = TIMEOUT_S, silence_s: float = SILENCE_S,
                ceiling_s: float = CEILING_S, send: Send | None = None) -> int:
    """MISSION_SET_CURRENT (the mission protocol's "set current item"): the `seq` that the
    vehicle's MISSION_CURRENT then shows; re-sent each `timeout_s` until a MISSION_CURRENT
    with `seq` comes, MissionError on silence or at the ceiling (a vehicle that refuses
    keeps showing its own current item)."""
    _send = _sender(conn, send)
    request = M.MAVLink_mission_set_current_message(target_system, target_component, seq)
    _send(request)
    wait = Wait(MISSION_STEP.but(resend_s=timeout_s, silence_s=silence_s,
                                 ceiling_s=ceiling_s))
    while not (why := wait.expired()):
        if wait.due():
            _send(request)
            wait.sent()
        msg = _recv(conn, ["MISSION_CURRENT"], target_system, target_component,
                    wait.left(), wait)
        if msg is not None and msg.seq == seq:
            return int(msg.seq)
    raise MissionError(f"mission set current on system {target_system}: no MISSION_CURRENT "
                       f"showing item {seq}{why}{wait.tries_text()}")


def _one_answer(conn: Connection, target_system: int, target_component: int, request: Any,
                budget: Budget, send: Send | None, settle_s: float, what: str) -> int:
    """Send `request`, re-sent by `budget`, until its MISSION_ACK: its result."""
    _send = _sender(conn, send)
    _drain(conn, target_system, settle_s)
    _send(request)
    wait = Wait(budget)
    while not (why := wait.expired()):
        if wait.due():
            _send(request)
            wait.sent()
        msg = _recv(conn, ["MISSION_ACK"], target_system, target_component, wait.left(),
                    wait)
        if msg is not None:
            return int(msg.type)
    raise MissionError(f"{what}: no MISSION_ACK{why}{wait.tries_text()}")


def home_position(conn: Connection, target_system: int, target_component: int, *,
                  timeout_s: float = 1.0, retries: int = 2,
                  send: Send | None = None) -> HomePosition | None:
    """The vehicle's home (HOME_POSITION: the origin that global mission items are converted
    through): the last one heard, else asked for with MAV_CMD_REQUEST_MESSAGE (and waited
    for `timeout_s` per try, the vehicle's periodic one counting too); None if none came."""
    last = getattr(conn, "messages", {}).get("HOME_POSITION")
    if from_target(last, target_system, target_component):
        return HomePosition.from_message(last)
    _send = _sender(conn, send)
    for confirmation in range(retries + 1):
        _send(M.MAVLink_command_long_message(
            target_system, target_component, M.MAV_CMD_REQUEST_MESSAGE, confirmation,
            M.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0))
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0.0:
            msg = conn.recv_match(type="HOME_POSITION", blocking=True, timeout=remaining)
            if from_target(msg, target_system, target_component):
                return HomePosition.from_message(msg)
    return None
