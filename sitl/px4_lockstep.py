"""Where the plant waits for PX4's lockstep answers (pure: sample times in, decisions out).

PX4 answers only when its outputs update, at its control rate, not at every HIL_SENSOR
(SimulatorMavlink.cpp's sender thread polls actuator_outputs), and stamps each answer with
its clock, the latest HIL_SENSOR time it processed. So the answers fall every `period`
samples (1 at 250 Hz IMU and control, 4 at a 1 kHz IMU). The schedule learns that period
from the stamps of the accepted answers (two equal intervals in a row, in samples) and then
says where the next answer is due: the plant steps on its own sensor clock without waiting
up to that sample, and there waits for the answer, which it applies from the physics step
that starts at the answer's stamp. For a deterministic firmware every answer then lands
where it is due, and the run repeats exactly.

An answer that does not come (`skip`: the caller's 1 s of wall time, as Gazebo's poll
timeout) moves the due sample one period on, the period unchanged; intervals that change
for good (two equal new ones in a row) are learned again.
"""

from __future__ import annotations

from enum import Enum


class Answer(Enum):
    STALE = "stale"  # stamped before the latest accepted answer
    EXTRA = "extra"  # a second answer with the latest accepted stamp
    ON_TIME = "on_time"  # stamped at the latest sample sent: applies from its own step
    LATE = "late"  # stamped before the latest sample sent: applies from the next step


class AnswerSchedule:
    """The firmware's answer period in samples, learned from its answers' stamps."""

    def __init__(self, imu_us: int) -> None:
        if imu_us <= 0:
            raise ValueError("imu_us must be positive")
        self.imu_us = imu_us
        self.reset()

    def reset(self) -> None:
        """A new connection: nothing learned."""
        self.last_us: int | None = None  # the latest accepted answer's stamp
        self.period: int | None = None  # samples between answers, once learned
        self._interval: int | None = None  # the latest interval seen, in samples
        self.due_us: int | None = None  # the sample the next answer is due at

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
        if last is not None:
            interval = (stamp_us - last) // self.imu_us
            if interval > 0 and interval == self._interval:
                self.period = interval  # two equal intervals in a row
            self._interval = interval
        self.last_us = stamp_us
        if self.period is not None:
            self.due_us = self._next_due(stamp_us, sent_us)
        return Answer.ON_TIME if stamp_us == sent_us else Answer.LATE

    def _next_due(self, stamp_us: int, sent_us: int) -> int:
        """The first sample a period after `stamp_us`, not before the latest sent."""
        assert self.period is not None
        step = self.period * self.imu_us
        due = stamp_us + step
        if due < sent_us:
            due += -(-(sent_us - due) // step) * step
        return due

    def waits_at(self, sent_us: int) -> bool:
        """Whether the plant must wait for an answer before stepping past `sent_us`."""
        return self.due_us is not None and sent_us >= self.due_us

    def skip(self) -> None:
        """The answer due did not come: the next one is due a period later."""
        if self.due_us is not None and self.period is not None:
            self.due_us += self.period * self.imu_us
