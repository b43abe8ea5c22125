"""Where the plant waits for PX4's lockstep answers (pure: sample times in, decisions out).

PX4 answers only when its outputs update, not at every HIL_SENSOR (SimulatorMavlink.cpp's
sender thread polls actuator_outputs), and stamps each answer with its clock, the latest
HIL_SENSOR time it processed. Its outputs follow its angular velocity, whose publication
is rate-limited (IMU_GYRO_RATEMAX, 400 Hz by default, in VehicleAngularVelocity): with an
IMU faster than that, the answers do not fall at a fixed period in samples (measured
with PX4 at a 1 kHz IMU: every 1 to 7 samples, mostly 4), and while PX4 starts it answers
every sample.

The rule, in samples between the stamps of accepted answers (`intervals`, a histogram):

- learning: the schedule waits for 2 x LEARN_WINDOW intervals whose two halves have the
  same longest interval (a cadence that has settled, PX4's start-up gaps past), and takes
  that longest interval as `period` and `longest`;
- then the plant steps on its own sensor clock without waiting up to the sample `longest`
  samples after the latest answer (`due_us`) and waits there. An answer stamped at the
  sample it waits at applies from the physics step that starts there; one that comes
  earlier (a shorter interval) applies from the step after it arrives. With a fixed
  cadence the longest interval is the period, every answer lands where it is due and a
  deterministic firmware gives the same run every time;
- an answer due that does not come soon (`step_past`: the caller's GRACE_S of wall
  time) lets the plant step one sample on and wait at the next: a firmware whose
  cadence has grown (PX4 answers every sample while it starts, then settles on its
  rate-limited cadence) needs that sample before it answers, and its answer, stamped
  where it came, lengthens `longest`. A firmware that was only slow answers with the
  earlier stamp, which applies from the next step and leaves `longest` as it was; it
  also doubles the grace (`grace_scale`, up to MAX_GRACE_SCALE and half the timeout):
  on a busy machine the firmware's own latency sets how long the plant waits, and
  stepping past a slow answer happens a few times per run at most;
- an answer that does not come at all (`skip`: the caller's 1 s of wall time since the
  wait began, as Gazebo's poll timeout) drops what was learned: the plant paces by the
  wall clock, as while PX4 starts, and learns the cadence again from the answers that
  follow. A firmware that stops answering (no outputs to publish) keeps running on the
  wall clock until it answers again.
  Within a learned cadence the longest interval only grows.

Each give-up is recorded (`give_ups`, the latest MAX_GIVE_UPS_KEPT): the sample the plant
waited at, the latest answer accepted when the wait began (the answer owed is the next one)
and the wall times the wait began and ended, so that a run can be judged on which answer
was missing and for how long. Each step past is recorded so too (`step_pasts`, the latest
MAX_STEP_PASTS_KEPT): the sample it left and the wall times its grace began and ended.
"""

from __future__ import annotations

from collections import deque
from enum import Enum
from typing import NamedTuple

LEARN_WINDOW = 8  # intervals in each half of the learning window
MAX_GRACE_SCALE = 8  # the grace grows to at most this many times the caller's
MAX_GIVE_UPS_KEPT = 100  # the latest give-ups kept in `give_ups` (all are counted)
MAX_STEP_PASTS_KEPT = 100  # the latest steps past kept in `step_pasts` (all are counted)


class Answer(Enum):
    STALE = "stale"  # stamped before the latest accepted answer
    EXTRA = "extra"  # a second answer with the latest accepted stamp
    ON_TIME = "on_time"  # stamped at the latest sample sent: applies from its own step
    LATE = "late"  # stamped before the latest sample sent: applies from the next step


class Wait(Enum):
    """What the plant does at a sample (`AnswerSchedule.wait_at`)."""

    STEP = "step"  # no answer due: step on
    WAIT = "wait"  # wait for what arrives, until the time given
    STEP_PAST = "step_past"  # the grace has passed: one sample on, wait there (`step_past`)
    GIVE_UP = "give_up"  # the timeout has passed: learn again (`skip`)


class GiveUp(NamedTuple):
    """One wait the plant gave up (`AnswerSchedule.wait_at` returned GIVE_UP)."""

    sample_us: int  # the sample the plant waited at
    answered_us: int | None  # the latest accepted answer when the wait began (None: none)
    began_s: float  # wall time (the caller's clock) the wait began
    gave_up_s: float  # and was given up


class StepPast(NamedTuple):
    """One step past an answer due (`AnswerSchedule.wait_at` returned STEP_PAST)."""

    sample_us: int  # the sample stepped past (its answer was due)
    began_s: float  # wall time (the caller's clock) the grace began
    stepped_s: float  # and the plant stepped past


class AnswerSchedule:
    """The longest interval in samples between the firmware's answers, from their stamps."""

    def __init__(self, imu_us: int) -> None:
        if imu_us <= 0:
            raise ValueError("imu_us must be positive")
        self.imu_us = imu_us
        self.intervals: dict[int, int] = {}  # samples between accepted answers -> count
        self.grace_scale = 1  # doubled by each answer that was slow, not longer (the run's)
        self.slow_answers = 0  # answers that came after the plant stepped past them
        self.slow_waits = 0  # waits that ended so (each doubled the grace)
        self.slow_steps = 0  # the steps taken past them (in those waits)
        # answers stamped before the latest sample sent (applied from the next step), from
        # the sample waited at when the cadence was learned (`learned_at_us`) on: a firmware
        # behind the wall-clock pace answers the samples sent on that pace after it
        self.late_answers = 0
        self.give_ups: deque[GiveUp] = deque(maxlen=MAX_GIVE_UPS_KEPT)  # the run's latest
        self.step_pasts: deque[StepPast] = deque(maxlen=MAX_STEP_PASTS_KEPT)  # and these
        self.reset()

    def reset(self) -> None:
        """A new connection: nothing learned (the histogram is kept: it is statistics)."""
        self.last_us: int | None = None  # the latest accepted answer's stamp
        self.period: int | None = None  # the longest interval when learned
        self.longest: int | None = None  # the longest interval since, in samples
        self._recent: list[int] = []  # the latest intervals, while learning
        self.due_us: int | None = None  # the sample the next answer is due at
        self._wait_s: float | None = None  # wall time the wait for the answer due began
        self._wait_from_us: int | None = None  # the latest accepted answer then
        self._grace_s = 0.0  # wall time of the latest `step_past` (or the wait's start)
        self._steps_past = 0  # `step_past` calls since the latest accepted answer
        self._past_us: int | None = None  # the latest sample stepped to past an answer due
        self.learned_at_us = -1  # the latest sample sent when learned (-1: not learned)

    @property
    def learned(self) -> bool:
        return self.period is not None

    def accept(self, stamp_us: int, sent_us: int) -> Answer:
        """An answer stamped `stamp_us` (at most `sent_us`, the latest sample sent)."""
        stamp_us = min(stamp_us, sent_us)
        last = self.last_us
        if last is not None and stamp_us < last:
            return Answer.STALE
        if last is not None and stamp_us == last:
            return Answer.EXTRA
        learned = self.learned
        if last is not None:
            self._interval((stamp_us - last) // self.imu_us)
            if not learned and self.learned:
                self.learned_at_us = sent_us
        self.last_us = stamp_us
        if self.longest is not None:
            self.due_us = self._next_due(stamp_us, sent_us)
        kind = Answer.ON_TIME if stamp_us == sent_us else Answer.LATE
        if kind is Answer.LATE and learned and stamp_us >= self.learned_at_us:
            self.late_answers += 1
        past = self._past_us
        if past is not None and stamp_us < past:  # slow, not longer: the plant stepped past
            self.slow_answers += 1
            if self._steps_past:  # the first of them: wait longer from now on
                self.slow_waits += 1
                self.slow_steps += self._steps_past
                self.grace_scale = min(2 * self.grace_scale, MAX_GRACE_SCALE)
        else:
            self._past_us = None
        self._steps_past = 0
        return kind

    def _interval(self, interval: int) -> None:
        self.intervals[interval] = self.intervals.get(interval, 0) + 1
        if self.longest is not None:
            self.longest = max(self.longest, interval)
            return
        recent = self._recent
        recent.append(interval)
        del recent[:-2 * LEARN_WINDOW]
        if len(recent) == 2 * LEARN_WINDOW and \
                max(recent[:LEARN_WINDOW]) == max(recent[LEARN_WINDOW:]) > 0:
            self.period = self.longest = max(recent)

    def _next_due(self, stamp_us: int, sent_us: int) -> int:
        """The first sample `longest` samples after `stamp_us`, at or after the latest
        sent (a whole number of `longest` steps on)."""
        assert self.longest is not None
        step = self.longest * self.imu_us
        due = stamp_us + step
        if due < sent_us:
            due += -(-(sent_us - due) // step) * step
        return due

    def waits_at(self, sent_us: int) -> bool:
        """Whether the plant must wait for an answer before stepping past `sent_us`."""
        return self.due_us is not None and sent_us >= self.due_us

    def wait_at(self, sent_us: int, now_s: float, grace_s: float,
                timeout_s: float) -> tuple[Wait, float]:
        """At the latest sample sent and the wall time `now_s`: step, wait (until the time
        returned), step past after the grace (`grace_s` times `grace_scale`, at most half of
        `timeout_s`) without the answer due, or give up (`skip`) `timeout_s` after the wait
        began; an answer accepted meanwhile ends the wait."""
        grace_s = min(grace_s * self.grace_scale, 0.5 * timeout_s)
        if self._wait_s is not None and self.last_us != self._wait_from_us:
            self._wait_s = None  # an answer came since the wait began
        if self.last_us == sent_us or not self.waits_at(sent_us):
            return Wait.STEP, now_s
        if self._wait_s is None:
            self._wait_s = self._grace_s = now_s
            self._wait_from_us = self.last_us
        if now_s - self._wait_s >= timeout_s:
            self.give_ups.append(GiveUp(sent_us, self._wait_from_us, self._wait_s, now_s))
            self.skip()
            return Wait.GIVE_UP, now_s
        if now_s - self._grace_s >= grace_s:
            self.step_pasts.append(StepPast(sent_us, self._grace_s, now_s))
            self.step_past()
            self._grace_s = now_s
            return Wait.STEP_PAST, now_s
        return Wait.WAIT, self._grace_s + grace_s

    def stats(self) -> dict[str, object]:
        """The schedule's figures for a stats file: the slow answers, the cadence learned,
        the intervals seen, each give-up kept (the sample waited at, the latest answer
        accepted before it: the one owed is the next, when the wait began on the caller's
        clock and the seconds waited) and each step past kept (the sample left, when its
        grace began and the seconds it lasted)."""
        return {"late_answers": self.late_answers,
                "slow_answers": self.slow_answers, "slow_waits": self.slow_waits,
                "slow_steps": self.slow_steps, "answer_period_samples": self.period,
                "answer_interval_longest": self.longest,
                "answer_intervals": {str(k): n for k, n in sorted(self.intervals.items())},
                "answer_give_ups": [{"sample_us": g.sample_us, "answered_us": g.answered_us,
                                     "began_s": g.began_s,
                                     "waited_s": round(g.gave_up_s - g.began_s, 6)}
                                    for g in self.give_ups],
                "answer_step_pasts": [{"sample_us": p.sample_us, "began_s": p.began_s,
                                       "waited_s": round(p.stepped_s - p.began_s, 6)}
                                      for p in self.step_pasts]}

    def step_past(self) -> None:
        """The answer due has not come yet: wait for it one sample later."""
        assert self.due_us is not None
        self.due_us += self.imu_us
        self._steps_past += 1
        self._past_us = self.due_us

    def skip(self) -> None:
        """The answer due did not come: learn the cadence again (the plant paces by the
        wall clock meanwhile), keeping the latest accepted stamp."""
        last = self.last_us
        self.reset()
        self.last_us = last
