"""The mission's state in the commander: its items, the current one, its executor on its
timeline, a start under way, whether it runs or is done, and what the executor said; pure,
no I/O."""

from __future__ import annotations

from common.wire.mav_enums import MAV_CMD
from common.wire.mission_items import MissionItem
from fcu.mission.executor import MissionEvent, MissionExecutor
from fcu.mission.start import MissionPlan
from fcu.stages import Reference


class MissionRun:
    """The mission in force (`items`) and how far it has flown."""

    def __init__(self) -> None:
        self.items: tuple[MissionItem, ...] = ()
        self.current = 0  # the one home of the current mission item
        self.executor: MissionExecutor | None = None
        self.offset_s = 0.0  # the executor's timeline: the flight clock minus this
        self.plan: MissionPlan | None = None  # a start under way
        self.running = False
        self.done = False
        self.events: list[MissionEvent] = []  # the executor's, for the shell to drain

    def replace(self, items: tuple[MissionItem, ...]) -> None:
        """A new mission: not started, from its first item."""
        self.items = tuple(items)
        self.current = 0
        self.done = False
        self.executor = None

    def select(self, seq: int) -> None:
        """Item `seq` the current one, the mission not done."""
        self.current = seq
        self.done = False

    def restart(self, seq: int) -> None:
        """Flown again from item `seq`, once started (`begin`)."""
        self.select(seq)
        self.running = False

    def refuse(self) -> None:
        """Its plan from here refused: nothing to fly."""
        self.executor = None
        self.running = False

    def begin(self, executor: MissionExecutor, offset_s: float) -> None:
        """Flown from now by `executor`, on the flight clock minus `offset_s`."""
        self.executor = executor
        self.running = True
        self.offset_s = offset_s

    def stop(self) -> None:
        """No longer flown (another mode, a disarm)."""
        self.running = False

    def step(self, t_flight_s: float) -> tuple[Reference, bool]:
        """The reference at `t_flight_s` (flight clock), and whether the mission has just
        completed (then it is done, no longer running)."""
        executor = self.executor
        assert executor is not None
        t_s = t_flight_s - self.offset_s  # on the plan's timeline
        events = executor.update(t_s)
        self.events.extend(events)
        for ev in events:
            if ev.kind == "current":
                self.current = ev.seq
        ref = executor.sample(t_s)
        if executor.completed:
            self.running = False
            self.done = True
        return ref, executor.completed

    def _lands(self, item: MissionItem) -> bool:
        return item.command == MAV_CMD.MAV_CMD_NAV_LAND

    @property
    def has_landing(self) -> bool:
        """Some item is a NAV_LAND."""
        return any(self._lands(it) for it in self.items)

    @property
    def ends_landing(self) -> bool:
        """The last item is a NAV_LAND: the mission ends in a touchdown."""
        return bool(self.items) and self._lands(self.items[-1])

    @property
    def flying_landing(self) -> bool:
        """Running, its current item a NAV_LAND."""
        return self.running and 0 <= self.current < len(self.items) and \
            self._lands(self.items[self.current])
