"""The mission executor: a fixed timeline of planned segments and its events."""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from typing import NamedTuple, cast

from common.wire.mission_items import MissionItem
from fcu.control.dualquat import Quat, Vec3
from fcu.envelope.feasibility import Envelope, envelope
from fcu.mission.codes import MAV_MISSION_ACCEPTED
from fcu.mission.limits import MissionLimits
from fcu.mission.planning import plan_item, speed_timed, stretched, with_speed
from fcu.mission.segments import Move, Segment
from fcu.mission.stretch import stretch_many
from fcu.mission.validation import check_items, refusal
from fcu.mission.verdicts import batched, first_refusal
from fcu.stages import Reference, pose_ref

# Item ends are sums of float seconds; the flight clock is integer microseconds. An item
# that ends at a step's instant ends at that step whatever the rounding of the sum.
TIME_EPS_S = 1e-9


class MissionEvent(NamedTuple):
    kind: str  # "current" | "reached" | "completed"
    seq: int



def plan(items: Sequence[MissionItem], seq: int, t_s: float, p: Vec3, q: Quat,
         limits: MissionLimits) -> list[Segment]:
    """The segments of items seq.. from (t_s, p, q), as `plan_item` makes them one after
    another (item k from the end of item k - 1), speed-timed moves stretched: the poses
    first (they do not depend on how long a move takes), the moves that the envelope can
    stretch at once stretched then (`stretch_many`), each segment then moved to its start."""
    planned = limits  # with the speeds of the DO_CHANGE_SPEED items before seq
    for item in items[:seq]:
        planned = with_speed(item, planned, limits)
    segments: list[Segment] = []
    to_stretch: dict[int, tuple[Envelope, list[int]]] = {}
    for item in items[seq:]:
        planned = with_speed(item, planned, limits)
        seg = plan_item(item, t_s, p, q, planned, stretch=False, scaled=False)
        if isinstance(seg, Move) and planned.vehicle is not None and seg.moves and \
                speed_timed(item):
            env = envelope(planned.vehicle)
            if batched(env, seg):
                to_stretch.setdefault(id(env), (env, []))[1].append(len(segments))
            else:
                seg = stretched(seg, planned.vehicle)
        segments.append(seg)
        p, q = seg.p_end, seg.q_end
    for env, ks in to_stretch.values():
        moves = stretch_many(env, [cast(Move, segments[k]) for k in ks])
        for k, seg in zip(ks, moves, strict=True):
            segments[k] = seg
    t = t_s
    for seg in segments:
        seg.starting(t)
        t = seg.t1
    return segments


class MissionExecutor:
    """Plans a mission on a fixed timeline and samples its reference.

    `start` (or `set_current`) plans every remaining item at once: item k starts at the
    end time of item k - 1, from its desired end pose; with `limits.vehicle`, speed-timed
    items are stretched as in validation (the `fcu.mission` docstring). An item is active on
    [start, end), so at a boundary the sample is the next item's at tau = 0 (the right-hand
    limit); zero-length items are passed through (their events still come). Before the start
    the reference holds the start pose, after the end the final pose.
    """

    def __init__(self, items: Sequence[MissionItem], limits: MissionLimits) -> None:
        self.items = tuple(items)
        self.limits = limits
        if not self.items:
            raise ValueError("empty mission")
        # The geofence and the item count are the uploader's business (the vehicle may have
        # tightened its limits since); what cannot be flown is refused here.
        check = check_items(self.items, limits, geofence=False)
        if check.result != MAV_MISSION_ACCEPTED:
            raise ValueError(f"mission not executable: {refusal(check)}")
        self._segments: list[Segment] = []
        self._ends: list[float] = []
        self._start_ref: Reference | None = None
        self._t_start = 0.0
        self._announced = 0
        self._reached = 0
        self._completed = False
        self.current_seq = 0

    # ------------------------------------------------------------------ planning

    def start(self, t_s: float, p_enu_m: Vec3, q_enu_flu: Quat) -> None:
        """Plan the whole mission from item 0, starting at t_s from the given pose."""
        self.set_current(0, t_s, p_enu_m, q_enu_flu)

    def set_current(self, seq: int, t_s: float, p_enu_m: Vec3, q_enu_flu: Quat) -> None:
        """Re-plan from item seq, starting at t_s from the given pose."""
        if not 0 <= seq < len(self.items):
            raise ValueError(f"no mission item {seq} (mission has {len(self.items)})")
        p: Vec3 = (p_enu_m[0], p_enu_m[1], p_enu_m[2])
        q: Quat = (q_enu_flu[0], q_enu_flu[1], q_enu_flu[2], q_enu_flu[3])
        self._start_ref = pose_ref(p, q)
        self._t_start = t_s
        self._segments = plan(self.items, seq, t_s, p, q, self.limits)
        self._ends = [seg.t1 for seg in self._segments]
        self._announced = 0
        self._reached = 0
        self._completed = False
        self.current_seq = seq

    def refusal(self) -> str:
        """'' when every planned item fits the envelope as planned from the start pose
        given (speed-timed items are stretched already), else why the first that does not
        fails (`fcu.mission.planning.envelope_reason`): a user-timed item that fitted from
        the origin may not from the vehicle's actual pose."""
        items = {item.seq: item for item in self.items}
        return first_refusal([(items[seg.seq], seg, self.limits) for seg in self._segments])[1]

    def drop_scalings(self) -> None:
        """Forget the envelope scalings of the planned segments: they serve the check alone
        (`refusal` makes any it needs again), and a worker's plan of 500 legs carried 16 MB
        of them, unpickled in the loop's thread: `benchmarks/bench_realtime.py` saw the
        loop stop for 48-60 ms at mode MISSION."""
        for seg in self._segments:
            seg.scaling = None

    @property
    def started(self) -> bool:
        return self._start_ref is not None

    @property
    def completed(self) -> bool:
        """True once `update` has seen the last item end."""
        return self._completed

    @property
    def schedule(self) -> tuple[tuple[int, float, float], ...]:
        """(seq, planned start, planned end) of each planned item."""
        return tuple((seg.seq, seg.t0, seg.t1) for seg in self._segments)

    @property
    def end_time_s(self) -> float:
        self._require_started()
        return self._ends[-1]

    def _require_started(self) -> Reference:
        """The start reference; raises if the mission has not been started."""
        if self._start_ref is None:
            raise RuntimeError("mission executor not started")
        return self._start_ref

    # ------------------------------------------------------------------ running

    def update(self, t_s: float) -> list[MissionEvent]:
        """Events since the last update: items that became current, were reached, the end."""
        self._require_started()
        segs = self._segments
        events: list[MissionEvent] = []
        while True:
            if self._reached < self._announced:
                seg = segs[self._reached]
                if seg.t1 <= t_s + TIME_EPS_S:
                    events.append(MissionEvent("reached", seg.seq))
                    self._reached += 1
                    continue
                break
            if self._announced < len(segs) and segs[self._announced].t0 <= t_s + TIME_EPS_S:
                seg = segs[self._announced]
                events.append(MissionEvent("current", seg.seq))
                self.current_seq = seg.seq
                self._announced += 1
                continue
            break
        if self._reached == len(segs) and not self._completed:
            self._completed = True
            events.append(MissionEvent("completed", segs[-1].seq))
        return events

    def sample(self, t_s: float) -> Reference:
        """The reference at t_s (any time: before the start, during, after the end)."""
        start = self._require_started()
        if t_s < self._t_start:
            return start
        k = bisect.bisect_right(self._ends, t_s)
        if k == len(self._segments):
            return self._segments[-1].end_ref
        seg = self._segments[k]
        return seg.sample(t_s - seg.t0)
