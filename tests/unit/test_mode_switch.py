"""What entering a mode resets, written once (`fcu.modes.mode_state.ModeState.switch`): every
pair of modes against the table, each path that changes modes (commands, plans taken in,
failsafes, arming) through it, and the failsafe changes as enums (`fcu.safety.failsafe`)."""

from __future__ import annotations

import math
from itertools import product

import pytest

from common.outcome import FAILSAFE
from common.wire.mav_enums import MAV_CMD, MAV_FRAME, MAV_RESULT
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.start import MissionPlan
from fcu.modes.commander import Commander
from fcu.modes.landing import Touchdown
from fcu.safety.failsafe import (
    Failsafe,
    FailsafeSettings,
    GcsLinkMonitor,
    LinkChange,
    PoseLoss,
    SaturationChange,
    SaturationMonitor,
    pose_loss_level,
)
from fcu.stages import VehicleState, pose_ref
from fcu.work import Outcome

MODES = list(Mode)  # LOITER is HOLD
HERE = (1.0, 2.0, 3.0)
Q = (1.0, 0.0, 0.0, 0.0)
ITEMS = (MissionItem(0, MAV_FRAME.MAV_FRAME_LOCAL_NED, MAV_CMD.MAV_CMD_NAV_WAYPOINT, 1, 1, 0.0,
                     0.0, 0.0, math.nan, 0, 0, -1.0),)


def _commander(armed: bool = True) -> Commander:
    c = Commander(MissionLimits())
    c.on_state(VehicleState(HERE, Q, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), 0)
    if armed:
        assert c.arm().result == MAV_RESULT.MAV_RESULT_ACCEPTED
    return c


class _Dirty:
    """Every mode's state set to something of its own, to see what a change resets (only
    identities are compared: the stand-ins are never flown)."""

    def __init__(self, c: Commander, mode: Mode) -> None:
        m = c.modes
        m.mode = mode
        self.plan = m.descent.plan = object()
        self.touchdown = m.descent.touchdown = Touchdown(0, (0.0, 0.0, 9.0), Q)
        self.auto = m.auto = object()
        m.mission_run.running = True
        self.shaped = m.shaper.sp = object()
        self.sp = m.posctl.sp = object()
        self.hold = m.brake.hold = pose_ref((9.0, 9.0, 9.0), Q)


def _kept(mode: Mode, previous: Mode) -> dict[str, bool]:
    """The table (fcu/modes/mode_state.py's docstring): what entering `mode` from `previous`
    leaves as it was."""
    again = mode is previous
    return {
        "landing": mode is Mode.LAND or (again and mode is Mode.RTL),
        "auto": mode in (Mode.TAKEOFF, Mode.RTL),
        "run": mode is Mode.LAND or (again and mode is Mode.MISSION),
        "shaper": mode is not Mode.OFFBOARD or again,
        "posctl": mode is not Mode.POSCTL or again,
        "hold": mode is not Mode.HOLD,
    }


def _check(c: Commander, d: _Dirty, kept: dict[str, bool], landing_started: bool) -> None:
    m = c.modes
    if landing_started:
        assert isinstance(m.descent.plan, MissionExecutor) and m.descent.touchdown is None
    elif kept["landing"]:
        assert m.descent.plan is d.plan and m.descent.touchdown is d.touchdown
    else:
        assert m.descent.plan is None and m.descent.touchdown is None
    assert m.auto is (d.auto if kept["auto"] else None)
    assert m.mission_run.running is kept["run"]
    assert m.shaper.sp is (d.shaped if kept["shaper"] else None)
    assert m.posctl.sp is (d.sp if kept["posctl"] else None)
    if kept["hold"]:
        assert m.brake.hold is d.hold
    else:
        assert m.brake.hold is not d.hold and m.brake.hold == pose_ref(HERE, Q)


@pytest.mark.parametrize(("mode", "previous"), list(product(MODES, MODES)),
                         ids=lambda m: m.name)
def test_entering_a_mode_resets_what_belongs_to_it_and_what_the_others_flew(mode, previous):
    """Given every mode's state set, when `mode` is entered from `previous`, then exactly
    what the table says is reset: the mode's own state (unless re-entered; HOLD's always),
    the landing, TAKEOFF's or RTL's plan and the mission's run (but where they go on)."""
    c = _commander()
    d = _Dirty(c, previous)
    c.modes.switch(mode)
    assert c.mode is mode
    _check(c, d, _kept(mode, previous), mode is Mode.LAND and previous is not Mode.LAND)


def test_a_hold_given_is_held_and_a_replaced_missions_touchdown_goes_on():
    c = _commander()
    d = _Dirty(c, Mode.MISSION)
    at = pose_ref((4.0, 5.0, 6.0), Q)
    c.modes.switch(Mode.HOLD, hold=at)
    assert c.modes.brake.hold is at and c.modes.descent.touchdown is None
    d = _Dirty(c, Mode.MISSION)
    c.set_mission(ITEMS)
    assert c.mode is Mode.HOLD and c.modes.descent.touchdown is d.touchdown
    assert c.modes.auto is None and not c.modes.mission_run.running
    assert c.modes.brake.hold == pose_ref(HERE, Q)


@pytest.mark.parametrize("previous", MODES, ids=lambda m: m.name)
def test_failsafes_enter_hold_and_land_through_the_table(previous):
    c = _commander()
    d = _Dirty(c, previous)
    c.failsafe_hold("failsafe: test: HOLD")
    assert c.mode is Mode.HOLD and c.events[-1].kind == FAILSAFE
    _check(c, d, _kept(Mode.HOLD, previous), False)
    d = _Dirty(c, previous)
    c.failsafe_land("failsafe: test: LAND")
    assert c.mode is Mode.LAND
    if previous is Mode.LAND:  # landing already: nothing changes
        assert c.modes.descent.plan is d.plan and c.modes.auto is d.auto
    else:
        _check(c, d, _kept(Mode.LAND, previous), True)


@pytest.mark.parametrize("previous", MODES, ids=lambda m: m.name)
def test_takeoff_and_a_mode_command_enter_through_the_table(previous):
    c = _commander()
    d = _Dirty(c, previous)
    assert c.takeoff().result == MAV_RESULT.MAV_RESULT_ACCEPTED
    assert c.mode is Mode.TAKEOFF and isinstance(c.modes.auto, MissionExecutor)
    d.auto = c.modes.auto  # planned anew, then kept by the switch
    _check(c, d, _kept(Mode.TAKEOFF, previous), False)
    d = _Dirty(c, previous)
    assert c.set_mode(Mode.HOLD, 0.0).result == MAV_RESULT.MAV_RESULT_ACCEPTED
    _check(c, d, _kept(Mode.HOLD, previous), False)


def test_a_missions_start_and_its_plan_enter_mission_or_hold_through_the_table():
    items = ITEMS
    c = _commander(armed=False)
    c.set_mission(items)
    d = _Dirty(c, Mode.LAND)
    assert c.mission_start().result == MAV_RESULT.MAV_RESULT_ACCEPTED  # disarmed: flown later
    assert c.mode is Mode.MISSION and not c.modes.mission_run.running
    _check(c, d, {**_kept(Mode.MISSION, Mode.LAND), "run": False}, False)
    c = _commander()
    c.set_mission(items)
    start = pose_ref((7.0, 7.0, 7.0), Q)
    for executor, mode in ((None, Mode.HOLD), (MissionExecutor(items, c.limits), Mode.MISSION)):
        d = _Dirty(c, Mode.OFFBOARD)
        plan = c.modes.mission_run.plan = MissionPlan(seq=0, t_s=0.0, start=start, said="",
                                                      text="")
        c._planned(plan, Outcome((executor, "refused")))
        assert c.mode is mode and c.modes.mission_run.running is (executor is not None)
        assert c.modes.descent.touchdown is None and c.modes.auto is None
        assert c.modes.brake.hold is (start if mode is Mode.HOLD else d.hold)
        assert c.modes.shaper.sp is d.shaped and c.modes.posctl.sp is d.sp


def test_arming_restarts_hold_and_posctl_and_disarming_ends_what_flew():
    c = _commander()
    d = _Dirty(c, Mode.OFFBOARD)
    c.modes.descent.on_ground = True
    assert c.disarm().result == MAV_RESULT.MAV_RESULT_ACCEPTED
    m = c.modes
    assert c.mode is Mode.OFFBOARD and not m.mission_run.running and m.auto is None
    assert m.descent.plan is None and m.descent.touchdown is None
    assert m.shaper.sp is d.shaped and m.posctl.sp is d.sp and m.brake.hold is d.hold
    d = _Dirty(c, Mode.OFFBOARD)
    c.modes.mission_run.running = False
    assert c.arm().result == MAV_RESULT.MAV_RESULT_ACCEPTED
    assert m.brake.hold == pose_ref(HERE, Q) and m.posctl.sp is None
    assert m.descent.plan is None and m.descent.touchdown is None
    assert m.shaper.sp is None and m.auto is d.auto and c.mode is Mode.OFFBOARD


# ---------------------------------------------------------------------- failsafe enums


def test_pose_loss_levels_are_ordered_members():
    s = FailsafeSettings(pose_loss_s=1.0, pose_loss_land_s=2.0)
    assert pose_loss_level(5_000_000, -1, s) is PoseLoss.FRESH
    assert pose_loss_level(1_000_000, 0, s) is PoseLoss.FRESH
    assert pose_loss_level(1_100_000, 0, s) is PoseLoss.HOLD
    assert pose_loss_level(3_100_000, 0, s) is PoseLoss.LAND
    assert PoseLoss.FRESH < PoseLoss.HOLD < PoseLoss.LAND and not PoseLoss.FRESH


def test_saturation_and_link_monitors_say_their_changes_as_members():
    s = FailsafeSettings(saturation_s=0.5, gcs_loss_s=1.0, gcs_loss_land_s=2.0)
    sat = SaturationMonitor()
    seen = [sat.update(t, on, s) for t, on in ((0, True), (400_000, True), (600_000, True),
                                                (700_000, True), (800_000, False),
                                                (900_000, False))]
    N, START, CLEAR = SaturationChange.NONE, SaturationChange.START, SaturationChange.CLEAR
    assert seen == [N, N, START, N, CLEAR, N]
    link = GcsLinkMonitor()
    seen_link = [link.update(now, 10.0, s) for now in (10.5, 11.5, 12.0, 13.6, 14.0)]
    seen_link.append(link.update(15.0, 15.0, s))
    L = LinkChange
    assert seen_link == [L.NONE, L.LOST, L.NONE, L.LAND, L.NONE, L.REGAINED]


def test_the_gcs_link_failsafe_is_set_and_cleared_by_member():
    from pathlib import Path

    from common.config.scenario import load_gains, load_vehicle
    from fcu.pipeline import Pipeline
    root = Path(__file__).resolve().parents[2]
    pipe = Pipeline(load_vehicle(root / "config/vehicles/hexa_tilted.toml"),
                    load_gains(root / "config/gains/pid_eq30.toml"), 500,
                    failsafes=FailsafeSettings(gcs_loss_s=1.0))
    pipe.check_links(10.0, 8.5)
    assert pipe.failsafe is Failsafe.GCS_LOST
    assert pipe.events[-1].text == "failsafe: GCS link lost"
    pipe.check_links(11.0, 11.0)
    assert pipe.failsafe is Failsafe.NONE and pipe.events[-1].text == "GCS link regained"
