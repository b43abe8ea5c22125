"""OFFBOARD's shaper and HOLD's brake (both `fcu.modes.offboard`'s approach): their state,
how they step, and the plans they make beside the loop; pure, no I/O.

OFFBOARD flies the streamed targets through the shaper from the reference flown when it
began; HOLD brakes with the same shaper to where the reference comes to rest. Where the work
runs beside the loop (`fcu.work`) a new sample's anchor and a brake are planned there, ahead
of their time (`PlansAhead`), and a reference that was moving coasts until they are in.
"""

from __future__ import annotations

from collections.abc import Callable

from common.wire.mav_enums import MAV_SEVERITY
from fcu.envelope.feasibility import Envelope
from fcu.modes import offboard
from fcu.modes.manual import StickSettings
from fcu.modes.voice import Voice
from fcu.stages import Reference
from fcu.work import Outcome, Work

ANCHOR_LEAD_US = 10_000  # beside the loop: a plan is made this far ahead, at least
LEAD_MAX_US = 100_000  # and at most this far, after plans that came late (`on_time`)
COAST_MAX_US = 250_000  # a coast whose plan is not in by then is planned in the loop (late work)

Planned = Outcome[tuple[offboard.Shaped, Reference]]


class Job:
    """A plan under way beside the loop, asked at `t_us` (flight clock)."""

    __slots__ = ("t_us",)

    def __init__(self, t_us: int) -> None:
        self.t_us = t_us


class PlansAhead:
    """How far ahead plans made beside the loop are made (`lead_us`), and how many came
    after their time (`late_anchors`) or were made in the loop instead (`inline_plans`)."""

    def __init__(self, voice: Voice) -> None:
        self.voice = voice
        self.lead_us = ANCHOR_LEAD_US
        self.late_anchors = 0  # anchors and brakes that came after their time (planned again)
        self.inline_plans = 0  # coasts planned in the loop: their work came too late

    def on_time(self, job: Job, planned_for_us: int) -> bool:
        """Whether a plan made beside for `planned_for_us` came before that time (a late one
        would jump: it is counted and planned again). The lead adapts to the work: after a
        late plan it is twice what that one took (up to LEAD_MAX_US); each plan on time
        brings it a quarter of the way back to ANCHOR_LEAD_US."""
        clock_us = self.voice.clock_us
        if planned_for_us > clock_us:
            self.lead_us -= (self.lead_us - ANCHOR_LEAD_US) // 4
            return True
        self.late_anchors += 1
        self.lead_us = min(LEAD_MAX_US, max(self.lead_us, 2 * (clock_us - job.t_us)))
        return False

    def coasted_too_long(self, sp: offboard.Shaped, t_us: int) -> bool:
        """A coast whose plan has not come within COAST_MAX_US (the work is late or failed):
        it is planned in the loop, counted in `inline_plans` and said."""
        if sp.seq != offboard.COAST or t_us - sp.anchor_us < COAST_MAX_US:
            return False
        self.inline_plans += 1
        self.voice.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, "work late: planned in the loop")
        return True


class OffboardShaper:
    """OFFBOARD's shaper state: the shaped set-point (`sp`; None: it starts afresh from the
    reference flown), a new sample's anchor under way beside the loop or taken in, the last
    refusal said. `in_force` tells whether OFFBOARD still flies when an anchor comes in."""

    def __init__(self, ahead: PlansAhead, in_force: Callable[[], bool]) -> None:
        self.ahead = ahead
        self.in_force = in_force
        self.sp: offboard.Shaped | None = None
        self._anchoring: Job | None = None  # a new sample's anchor under way beside
        self._anchored: offboard.Shaped | None = None  # taken in, flown from its time
        self._refused = ""  # the last refusal said

    def restart(self) -> None:
        """The approach starts again from the reference flown (OFFBOARD entered)."""
        self.sp = None

    def step(self, t_us: int, start: Reference | None, target: offboard.Target,
             lim: StickSettings, env: Envelope | None, work: Work) -> Reference:
        """The streamed target approached within POSCTL's limits and the vehicle's envelope,
        from `start` (the reference flown, its velocity, acceleration and body rate too;
        given when `sp` is None). Where the work runs beside the loop a new sample is
        anchored there (`_beside`), not in this step."""
        sp = self.sp
        if sp is None:
            assert start is not None
            self._anchoring = self._anchored = None
            if work.immediate or not offboard.moving(start):
                sp = offboard.start(t_us, start, lim, env)
            else:  # planned beside (`_beside`): the reference coasts meanwhile
                sp = offboard.coast(t_us, start)
        if work.immediate:
            self.sp, ref = offboard.advance(sp, t_us, target, lim, env)
        else:
            self.sp, ref = self._beside(sp, t_us, target, lim, env, work)
        refused = self.sp.refused
        if refused and refused != self._refused:
            self.ahead.voice.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, refused)
        self._refused = refused
        return ref

    def _beside(self, sp: offboard.Shaped, t_us: int, target: offboard.Target,
                lim: StickSettings, env: Envelope | None,
                work: Work) -> tuple[offboard.Shaped, Reference]:
        """The plan in force flown on; a new sample anchored by `work` at the lead ahead,
        from the reference this plan gives there (`offboard.advance` to that time:
        continuous), and flown from then on; with no new sample, a coast (OFFBOARD entered
        moving) is given its start there (`offboard.start_ahead`). An anchor that came too
        late is planned again further ahead; one at a time (the newest sample when the last
        is in); a coast still unplanned after COAST_MAX_US is planned in this step."""
        anchored = self._anchored
        if anchored is not None and t_us >= anchored.t_us:
            sp, self._anchored = anchored, None
        if self.ahead.coasted_too_long(sp, t_us):
            self._anchoring = self._anchored = None
            return offboard.start_ahead(sp, t_us, lim, env)
        sp, ref = offboard.advance(sp, t_us, None, lim)
        if self._anchoring is not None or self._anchored is not None:
            return sp, ref
        job = Job(t_us)
        ahead_us = t_us + self.ahead.lead_us
        if target.seq != sp.seq:
            self._anchoring = job
            work.submit(offboard.advance, (sp, ahead_us, target, lim, env),
                        lambda outcome: self._anchored_in(job, outcome))
        elif sp.seq == offboard.COAST:
            self._anchoring = job
            work.submit(offboard.start_ahead, (sp, ahead_us, lim, env),
                        lambda outcome: self._anchored_in(job, outcome))
        return sp, ref

    def _anchored_in(self, job: Job, outcome: Planned) -> None:
        if job is not self._anchoring or not self.in_force():
            return  # OFFBOARD left (or entered again) meanwhile
        self._anchoring = None
        if outcome.value is None:
            self.ahead.voice.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, f"offboard: {outcome.error}")
            return
        shaped = outcome.value[0]
        if self.ahead.on_time(job, shaped.t_us):  # else planned again from the next step
            self._anchored = shaped


class HoldBrake:
    """HOLD's brake state: where it holds (`hold`), the brake shaped to it (`sp`), and a
    brake under way beside the loop or taken in. A moving reference brakes within
    OFFBOARD's limits to where it comes to rest, and `hold` becomes that pose (PX4's and
    ArduPilot's hold); one at rest is held as it is. A new `hold` brakes afresh."""

    def __init__(self, ahead: PlansAhead) -> None:
        self.ahead = ahead
        self.hold: Reference | None = None
        self.sp: offboard.Shaped | None = None
        self._shaped: Reference | None = None  # the hold that sp brakes to
        self._braking: Job | None = None  # a brake under way beside the loop
        self._braked: tuple[offboard.Shaped, Reference] | None = None  # taken in, not flown

    def hold_at(self, pose: Reference) -> None:
        """Hold `pose` from here (HOLD entered, a failsafe, a plan's end): braked afresh."""
        self.hold = pose

    def step(self, t_us: int, flown: Reference | None, lim: StickSettings,
             env: Envelope | None, work: Work) -> Reference:
        """HOLD's reference at `t_us`, braking from `flown` (the reference flown, None: at
        rest at `hold`). Where the work runs beside the loop the brake is planned there
        (`_beside`) and the reference coasts until it is in."""
        assert self.hold is not None
        if self._shaped is not self.hold:
            start = flown if flown is not None else self.hold
            self._braking = self._braked = None
            if work.immediate or not offboard.moving(start):
                self.sp, self.hold = offboard.brake(t_us, start, lim, env)
            else:
                self.sp = offboard.coast(t_us, start)
            self._shaped = self.hold
        assert self.sp is not None
        if self.sp.seq == offboard.COAST:
            self._beside(t_us, lim, env, work)
        if offboard.settled(self.sp):
            return self.hold
        self.sp, ref = offboard.advance(self.sp, t_us, None, lim)
        return ref

    def _beside(self, t_us: int, lim: StickSettings, env: Envelope | None,
                work: Work) -> None:
        """While HOLD coasts: its brake planned by `work` at the lead ahead from where the
        coast is then (`offboard.brake_ahead`), taken in at its time; one that came too late
        is planned again; after COAST_MAX_US it is planned in this step."""
        sp = self.sp
        assert sp is not None
        braked = self._braked
        if braked is not None and t_us >= braked[0].t_us:
            self._braked = None
            self.sp, self.hold = braked
        elif self.ahead.coasted_too_long(sp, t_us):
            self._braking = self._braked = None
            self.sp, self.hold = offboard.brake_ahead(sp, t_us, lim, env)
        elif self._braking is None and braked is None:
            job = self._braking = Job(t_us)
            work.submit(offboard.brake_ahead, (sp, t_us + self.ahead.lead_us, lim, env),
                        lambda outcome: self._braked_in(job, outcome))
            return
        else:
            return
        self._shaped = self.hold

    def _braked_in(self, job: Job, outcome: Planned) -> None:
        if job is not self._braking:
            return  # a newer hold asked meanwhile
        self._braking = None
        if outcome.value is None:
            self.ahead.voice.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, f"hold: {outcome.error}")
        elif self.ahead.on_time(job, outcome.value[0].t_us):  # else planned again
            self._braked = outcome.value
