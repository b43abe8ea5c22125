"""Work beside the control loop (`fcu.work`, `fcu.edge.work_process`) and the protocol around it:
the mission upload's MISSION_ACK, a mission's start and its COMMAND_ACK, answered when the
work is done, and the vehicle flying the mode in force meanwhile."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from common.config.scenario import load_gains, load_vehicle
from common.wire.mav_enums import MAV_CMD, MAV_RESULT
from common.wire.mavlink import MAV
from common.wire.mission_items import MissionItem
from common.wire.mission_messages import item_message
from common.wire.modes import Mode
from fcu.edge.mission_protocol import MissionServer
from fcu.edge.work_process import ProcessWork, make_work
from fcu.mission.limits import MissionLimits
from fcu.modes.commander import IN_PROGRESS
from fcu.pipeline import Pipeline
from fcu.stages import VehicleState
from fcu.work import Done, InlineWork, Outcome, Work
from tests.unit.test_mission_protocol import waypoints

ROOT = Path(__file__).resolve().parents[2]

VEHICLE = (1, 1)
GCS, OTHER = (255, 190), (254, 190)
M = MAV


class HeldWork(Work):
    """Jobs computed at once but called back only when `release` says: work beside the loop
    that takes as long as the test wants."""

    kind = "held"

    def __init__(self) -> None:
        super().__init__()
        self.held: list[tuple[Done, Outcome[Any]]] = []

    @property
    def pending(self) -> int:
        return len(self.held) + len(self._finished)

    def _submit(self, fn: Callable[..., Any], args: tuple[Any, ...], done: Done,
                warm_up: bool) -> None:
        self.held.append((done, Outcome(fn(*args))))

    def release(self) -> int:
        self._finished += self.held
        self.held = []
        return self.take()


def _items(n: int) -> list[MissionItem]:
    """Waypoints 3 m up, 0.5 m apart."""
    return waypoints(n)


def _msg(m: MAV.MAVLink_message, src: tuple[int, int]) -> MAV.MAVLink_message:
    m._header = MAV.MAVLink_header(m.get_msgId(), srcSystem=src[0], srcComponent=src[1])
    return m


def _count(n: int, src: tuple[int, int] = GCS) -> MAV.MAVLink_message:
    return _msg(M.MAVLink_mission_count_message(*VEHICLE, n, 0), src)


def _item(it: MissionItem, src: tuple[int, int] = GCS) -> MAV.MAVLink_message:
    return _msg(item_message(it, *VEHICLE), src)


def _upload(server: MissionServer, items: list[MissionItem],
            src: tuple[int, int] = GCS) -> list[MAV.MAVLink_message]:
    out = server.handle(_count(len(items), src), 0.0)
    for it in items:
        out = server.handle(_item(it, src), 0.0)
    return out


def _acks(msgs: list[MAV.MAVLink_message]) -> list[int]:
    return [m.type for m in msgs if m.get_type() == "MISSION_ACK"]


def _kinds(msgs: list[MAV.MAVLink_message]) -> list[str]:
    return [m.get_type() for m in msgs]


def _out(server: MissionServer, partner: tuple[int, int] | None = None
         ) -> list[MAV.MAVLink_message]:
    """The server's queued answers (`take_outbox`), each checked to go to `partner`
    (default: GCS, the uploader)."""
    out = server.take_outbox()
    assert all(p == (partner or GCS) for p, _ in out), out
    return [m for _, m in out]


# ---------------------------------------------------------------------- the workers


def test_make_work_names_the_two_kinds():
    assert isinstance(make_work("inline", lockstep=False), InlineWork)
    beside = make_work("beside", lockstep=True)
    assert isinstance(beside, ProcessWork) and beside.wait
    assert not make_work("beside", lockstep=False).wait  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="expected one of inline, beside"):
        make_work("thread", lockstep=False)


# ---------------------------------------------------------------------- the mission upload


def test_the_answer_to_an_upload_waits_for_its_check():
    """Given the last item received while the check runs beside the loop, then nothing is
    answered and the old mission stays (a download returns it); the last item sent again
    meanwhile is no new upload and gets no answer; when the check is done, one
    MISSION_ACK ACCEPTED goes out and the new mission is in force."""
    work = HeldWork()
    server = MissionServer(*VEHICLE, MissionLimits(), work=work)
    changed: list[tuple[MissionItem, ...]] = []
    server.on_mission_changed = changed.append
    old = _items(2)
    _upload(server, old)
    work.release()
    assert _acks(_out(server)) == [M.MAV_MISSION_ACCEPTED]
    new = _items(5)
    assert _upload(server, new) == [] and server.checking
    assert server.handle(_item(new[-1]), 0.0) == []  # the last item again: no answer
    assert server.handle(_msg(M.MAVLink_mission_request_list_message(*VEHICLE, 0), GCS),
                         0.0)[0].count == 2  # a download meanwhile: the mission in force
    assert _out(server) == [] and len(changed) == 1
    assert work.release() == 1
    acks = _out(server)
    assert _kinds(acks) == ["MISSION_ACK"] and acks[0].type == M.MAV_MISSION_ACCEPTED
    assert len(server.mission) == 5 and len(changed) == 2 and not server.checking
    again = server.handle(_item(new[-1]), 0.0)  # after the ACK: the same answer again
    assert _kinds(again) == ["MISSION_ACK"] and again[0].type == M.MAV_MISSION_ACCEPTED


def test_a_new_upload_drops_the_pending_check_and_another_gcs_is_denied():
    """Given a check under way, then a MISSION_COUNT from another GCS is DENIED (busy); one
    from the same GCS starts a new upload, and the old check's answer is dropped."""
    work = HeldWork()
    server = MissionServer(*VEHICLE, MissionLimits(), work=work)
    _upload(server, _items(4))
    busy = server.handle(_count(2, OTHER), 0.0)
    assert _kinds(busy) == ["MISSION_ACK"] and busy[0].type == M.MAV_MISSION_DENIED
    assert _kinds(server.handle(_count(2), 0.0)) == ["MISSION_REQUEST_INT"]
    work.release()
    assert _out(server) == [] and server.mission == ()  # dropped
    _upload(server, _items(2))
    work.release()
    assert _acks(_out(server)) == [M.MAV_MISSION_ACCEPTED]
    assert len(server.mission) == 2


def test_a_check_that_failed_is_a_mission_error_with_why():
    class Broken(Work):
        def _submit(self, fn, args, done, warm_up):
            done(Outcome(None, "the worker stopped (exit code -9)"))

    server = MissionServer(*VEHICLE, MissionLimits(), work=Broken())
    out = _upload(server, _items(2))
    assert _kinds(out)[-1] == "MISSION_ACK" and set(_kinds(out)[:-1]) == {"STATUSTEXT"}
    assert _acks(out) == [M.MAV_MISSION_ERROR] and server.mission == ()
    text = "".join(m.text for m in out[:-1])
    assert "mission check failed: the worker stopped" in " ".join(text.split())


# ---------------------------------------------------------------------- a mission's start


def airborne_pipeline() -> Pipeline:
    """Hovering armed 2 m up in HOLD (the tilted vehicle's envelope in the limits)."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(vehicle=vehicle))
    pipe.on_state(0, VehicleState((0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    assert pipe.arm()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    return pipe


def airborne_commander() -> Any:
    """`airborne_pipeline`'s commander."""
    return airborne_pipeline().commander


def _planned_commander() -> tuple[Any, HeldWork]:
    c = airborne_commander()
    work = HeldWork()
    c.work = work
    c.set_mission(tuple(_items(3)))
    return c, work


def test_a_mission_start_is_answered_and_shown_when_its_plan_is_taken_in():
    """Given MISSION_START in flight with the plan made beside the loop, then the answer is
    IN_PROGRESS, the mode in force (HOLD) flies on and is shown, and no event is said;
    when the plan is taken in, the mode is MISSION, 'mission started' is said, the reply
    gets ACCEPTED, and the mission's timeline starts at that step."""
    c, work = _planned_commander()
    replies: list[tuple[int, str]] = []
    c.step_at(2_000_000)
    result = c.mission_start(0)
    assert result == (IN_PROGRESS, "") and c.modes.mission_run.plan is not None
    c.modes.mission_run.plan.on_end(lambda r, t: replies.append((r, t)))
    said = len(c.events)
    for k in range(5):
        c.reference(2_000_000 + 2000 * k)
    assert c.mode == Mode.HOLD and not c.modes.mission_run.running and len(c.events) == said
    work.release()
    assert replies == [(MAV_RESULT.MAV_RESULT_ACCEPTED, "mission started")]
    assert c.mode == Mode.MISSION and c.modes.mission_run.running
    assert c.modes.mission_run.offset_s == pytest.approx(0.008)
    assert c.events[-1].text == "mission started"


def test_a_plan_under_way_gives_way_to_a_newer_command():
    """Given a mission's plan under way, then LAND drops it, its command answered FAILED
    (superseded): taken in later, it changes nothing and answers nothing more."""
    c, work = _planned_commander()
    replies: list[tuple[int, str]] = []
    assert c.set_mode(Mode.MISSION, 0.0)[0] == IN_PROGRESS
    c.modes.mission_run.plan.on_end(lambda r, t: replies.append((r, t)))
    assert c.set_mode(Mode.LAND, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    assert replies == [(MAV_RESULT.MAV_RESULT_FAILED, "superseded by a newer command")]
    work.release()
    assert c.mode == Mode.LAND and len(replies) == 1 and c.modes.mission_run.plan is None


def test_inline_work_answers_a_mission_start_at_once():
    c = airborne_commander()
    c.set_mission(tuple(_items(3)))
    assert c.mission_start(0) == (MAV_RESULT.MAV_RESULT_ACCEPTED, "mission started")
    assert c.mode == Mode.MISSION and c.modes.mission_run.offset_s == 0.0


def _flown_until_moving(c: Any, t_us: int) -> int:
    """Steps of 2 ms from `t_us` until the reference moves at 0.2 m/s or more; the next
    step's time."""
    while math.dist(c.fly(t_us).v_enu_m_s, (0.0, 0.0, 0.0)) < 0.2:
        t_us += 2000
        assert t_us < 20_000_000, "the reference never moved"
    return t_us + 2000


def _path_after(c: Any, t_us: int, steps: int) -> list[tuple[float, float, float]]:
    return [c.fly(t_us + 2000 * k).p_enu_m for k in range(steps)]


def _braked_to_rest(c: Any, work: HeldWork, t_us: int) -> list[Any]:
    """The references from `t_us` on, 2 ms apart, while HOLD's brake flies for a start
    under way (its plan released beside the loop as soon as it is asked), until it is at
    rest and the start's own plan has been asked for (held)."""
    refs = []
    for k in range(5000):
        refs.append(c.fly(t_us + 2000 * k))
        if c.modes.plan_lead_in is None:
            assert work.pending == 1  # the mission's plan, asked from where it rests
            return refs
        work.release()  # the brake's plan
    raise AssertionError("the brake never came to rest")


def _continuous(refs: list[Any]) -> None:
    """No step in position (5 m/s at most) or velocity (30 m/s^2 at most) between steps."""
    for r0, r1 in itertools.pairwise(refs):
        assert math.dist(r0.p_enu_m, r1.p_enu_m) < 0.01
        assert math.dist(r0.v_enu_m_s, r1.v_enu_m_s) < 0.06


def test_a_start_under_way_brakes_to_rest_and_its_plan_flies_on_from_there():
    """Given a mission in flight, moving, and a new current item, planned beside the loop,
    then HOLD's brake takes the reference to rest from its speed (no step in velocity),
    the plan is made from where it rests (the reference resting there meanwhile), and when
    it is taken in it flies from there: no step. (The reference used to stop dead where it
    was asked, its velocity stepping to zero, or, earlier, to step back to that pose once
    the plan came in.)"""
    c = airborne_commander()
    c.set_mission(tuple(_items(3)))
    c.fly(2_000_000)
    assert c.mission_start(0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED  # inline work
    t = _flown_until_moving(c, 2_002_000)
    asked = c.last_ref
    work = HeldWork()
    c.work = work
    assert c.set_mission_current(2) == (IN_PROGRESS, "")
    braking = _braked_to_rest(c, work, t)
    rest = braking[-1]
    assert rest.v_enu_m_s == (0.0, 0.0, 0.0) and len(braking) > 10
    assert c.mode == Mode.MISSION and c.mission_current != 2  # not shown before it flies
    t += 2000 * len(braking)
    held = [c.fly(t + 2000 * k) for k in range(10)]
    assert all(r.p_enu_m == rest.p_enu_m and r.v_enu_m_s == (0.0, 0.0, 0.0) for r in held)
    assert work.release() == 1 and c.mode == Mode.MISSION and c.mission_current == 2
    after = [c.fly(t + 20_000 + 2000 * k) for k in range(2000)]
    _continuous([asked, *braking, *held, *after])
    assert 0.0 < math.dist(rest.p_enu_m, after[0].p_enu_m) < 1e-6  # from where it rested
    assert math.dist(after[-1].p_enu_m, after[-2].p_enu_m) > 0.0 or c.mission_done


def test_a_running_missions_dropped_new_start_holds_where_its_brake_stops():
    """Given a mission in flight, moving, a new current item asked (HOLD's brake flying for
    it), when POSCTL is asked (the new start dropped, POSCTL's fit beside the loop: MISSION
    still in force), then the mission does not jump back to where it paused: it holds,
    braking on from where the reference is, with no step, and POSCTL is entered from
    there when fitted."""
    from fcu.modes import manual
    c = airborne_commander()
    c.set_mission(tuple(_items(3)))
    c.manual_input(0.0, manual.CENTRED)
    c.fly(2_000_000)
    assert c.mission_start(0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED  # inline work
    t = _flown_until_moving(c, 2_002_000)
    work = HeldWork()
    c.work = work
    assert c.set_mission_current(2) == (IN_PROGRESS, "")
    braking = [c.fly(t + 2000 * k) for k in range(20)]
    work.release()  # the brake's plan
    braking += [c.fly(t + 40_000 + 2000 * k) for k in range(5)]
    assert math.dist(braking[-1].v_enu_m_s, (0.0, 0.0, 0.0)) > 0.05  # still braking
    assert c.set_mode(Mode.POSCTL, 0.0) == (IN_PROGRESS, "")  # the re-aim dropped
    held = [c.fly(t + 50_000 + 2000 * k) for k in range(1000)]
    assert c.mode == Mode.HOLD and not c.modes.mission_run.running
    _continuous([*braking, *held])
    assert held[-1].v_enu_m_s == (0.0, 0.0, 0.0)
    c.on_state(VehicleState(held[-1].p_enu_m, held[-1].q_enu_flu, (0.0, 0.0, 0.0),
                            (0.0, 0.0, 0.0)), t + 2_050_000)  # the vehicle followed
    work.release()  # the fit
    assert c.mode == Mode.POSCTL
    assert math.dist(c.fly(t + 2_052_000).p_enu_m, held[-1].p_enu_m) < 0.01


@pytest.mark.parametrize("mode", [Mode.TAKEOFF, Mode.LAND, Mode.POSCTL])
def test_a_dropped_start_lets_the_mode_in_force_fly_on_from_the_brake(mode):
    """Given TAKEOFF climbing, LAND descending or POSCTL moving up on its stick, and
    MISSION asked (HOLD's brake flying for it, then its plan made beside the loop), when a
    new mission upload drops that start (the mode in force stays), then the mode flies on
    from where the reference is, with no step and no jump to where its plan or set-point
    would have been by then, and reaches what it was going to: TAKEOFF its altitude, LAND
    the touchdown."""
    from fcu.modes import manual
    c = airborne_commander()
    c.set_mission(tuple(_items(3)))
    c.manual_input(0.0, manual.Sticks(up=0.5))
    c.fly(2_000_000)
    answer = c.takeoff() if mode == Mode.TAKEOFF else c.set_mode(mode, 0.0)
    assert answer[0] == MAV_RESULT.MAV_RESULT_ACCEPTED and c.mode == mode
    t = _flown_until_moving(c, 2_002_000)
    work = HeldWork()
    c.work = work
    assert c.set_mode(Mode.MISSION, 0.0) == (IN_PROGRESS, "")
    braking = [c.fly(t + 2000 * k) for k in range(10)]
    work.release()  # the brake's plan
    braking += [c.fly(t + 20_000 + 2000 * k) for k in range(40)]
    c.set_mission(tuple(_items(2)))
    assert c.under_way is None and c.mode == mode
    path = braking[-1:]
    for k in range(5000 if mode != Mode.POSCTL else 500):  # to the touchdown, whose
        path.append(c.fly(t + 100_000 + 2000 * k))           # set-point follows the state
        work.release()                                        # (held here)
        if c.modes.descent.touchdown is not None:
            break
    _continuous([*braking, *path])
    z = path[-1].p_enu_m[2]
    if mode == Mode.TAKEOFF:
        assert z == pytest.approx(2.0 + c.flight.takeoff_alt_m, abs=1e-6)
    elif mode == Mode.LAND:
        assert c.modes.descent.touchdown is not None and z < 0.5
    else:
        assert z > braking[-1].p_enu_m[2] + 0.5  # climbing on its stick for 1 s


def test_posctl_is_entered_when_its_limits_are_fitted():
    """Given POSCTL asked with its envelope fit made beside the loop, then the answer is
    IN_PROGRESS and HOLD flies on (shown), the reference still; when the fit is taken in,
    POSCTL is in force with the fitted limits and the reply gets ACCEPTED."""
    from fcu.modes import manual
    c = airborne_commander()
    work = HeldWork()
    c.work = work
    c.manual_input(0.0, manual.CENTRED)
    assert c.set_mode(Mode.POSCTL, 0.0) == (IN_PROGRESS, "")
    replies: list[tuple[int, str]] = []
    c.under_way.on_end(lambda r, t: replies.append((r, t)))
    refs = [c.reference(2000 * k) for k in range(1, 4)]
    assert c.mode == Mode.HOLD and c.modes.posctl.sp is None
    assert all(r.p_enu_m == refs[0].p_enu_m for r in refs)
    work.release()
    assert replies == [(MAV_RESULT.MAV_RESULT_ACCEPTED, "mode POSCTL")]
    assert c.mode == Mode.POSCTL and c.under_way is None
    assert c.modes.posctl.limits == manual.fit_envelope(c.flight.sticks, c.limits.vehicle,
                                                  (1.0, 0.0, 0.0, 0.0))


def _offboard_commander(work: Work) -> Any:
    from fcu.edge.setpoint_wire import position_target
    c = airborne_commander()
    c.work = work
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (0.0, 0.0, -2.0),
                                                    (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    return c


def test_a_mission_asked_from_offboard_at_speed_outlives_the_stream_it_left():
    """Given OFFBOARD flying to a set-point 20 m north and MISSION asked at speed (HOLD's
    brake flies first, seconds), when the set-points stop with the request, as a station's
    do, then the OFFBOARD stream's loss is no failsafe (the change under way has left
    OFFBOARD, as it would have in the loop): the start goes on and MISSION is entered
    where the brake stopped. (The loss's HOLD dropped the start: MISSION answered FAILED.)"""
    from fcu.edge.setpoint_wire import position_target
    pipe = airborne_pipeline()
    c = pipe.commander
    c.set_mission(tuple(_items(3)))
    pipe.check_links(0.0, 0.0)
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (20.0, 0.0, -2.0),
                                                    (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    t = 0
    while math.dist(c.fly(t).v_enu_m_s, (0.0, 0.0, 0.0)) < 2.0:
        t += 2000
    answers: list[int] = []
    assert c.set_mode(Mode.MISSION, 0.5)[0] == IN_PROGRESS
    assert c.under_way is not None
    c.under_way.on_end(lambda r, _: answers.append(r))
    for k in range(1, 5000):
        c.fly(t + 2000 * k)
        pipe.check_links(0.5 + 0.002 * k, 0.5 + 0.002 * k)  # no set-point since 0 s
        if answers:
            break
    assert answers == [MAV_RESULT.MAV_RESULT_ACCEPTED] and c.mode == Mode.MISSION
    assert k * 0.002 > 1.0  # the brake outlasted COM_OF_LOSS_T


def test_a_new_offboard_sample_is_anchored_beside_the_loop_ahead_and_flown_continuously():
    """Given OFFBOARD with the planner beside the loop, when a sample 2 m north comes, then
    the step only submits its anchor (the plan in force flies on, still), the anchor is
    planned ANCHOR_LEAD_US ahead from where that plan is then, the reference leaves from
    there without a jump and reaches the sample, as it does with the planner inline."""
    import itertools
    import math

    from fcu.edge.setpoint_wire import position_target
    from fcu.modes.shaping import ANCHOR_LEAD_US
    work = HeldWork()
    c = _offboard_commander(work)
    t = 2000
    c.reference(t)
    assert work.release() == 1  # the first sample's anchor
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (2.0, 0.0, -2.0),
                                                    (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    path = []
    for k in range(1, 6):  # the sample's anchor under way: the hover flies on
        path.append(c.reference(t + 2000 * k).p_enu_m)
    assert len(work.held) == 1 and all(p == path[0] for p in path)
    assert work.release() == 1
    asked_at = t + 2000 * 5
    for k in range(6, 3000):
        ref = c.reference(t + 2000 * k)
        if t + 2000 * k < asked_at + ANCHOR_LEAD_US:
            assert ref.p_enu_m == path[0]  # not before its time
        path.append(ref.p_enu_m)
    jumps = [math.dist(a, b) / 0.002 for a, b in itertools.pairwise(path)]
    assert max(jumps) <= 5.0 + 1e-6  # MPC_VEL_MANUAL: a continuous approach
    assert math.dist(path[-1], (0.0, 2.0, 2.0)) < 1e-6 and c.modes.ahead.late_anchors == 0


def test_an_anchor_that_comes_after_its_time_is_planned_again():
    """Given the anchor of a sample taken in after its time had passed, then it is not
    flown (it would jump), it is counted, and the next step asks for it again."""
    from fcu.modes.shaping import ANCHOR_LEAD_US
    work = HeldWork()
    c = _offboard_commander(work)
    c.reference(2000)
    for k in range(2, 2 + ANCHOR_LEAD_US // 2000 + 1):
        c.reference(2000 * k)
    assert work.release() == 1 and c.modes.ahead.late_anchors == 1
    c.reference(2000 * 20)
    assert len(work.held) == 1  # asked again
    work.release()
    assert c.modes.ahead.late_anchors == 1


def _command(server: Any, command: int, confirmation: int, *params: float,
             src: tuple[int, int] = GCS) -> None:
    p = [*params, *([0.0] * (7 - len(params)))]
    server.handle(0, _msg(M.MAVLink_command_long_message(1, 1, command, confirmation, *p), src),
                  1.0)


def _command_acks(link: Any) -> list[tuple[int, int]]:
    from tests.unit.test_gcs_dispatch import parsed
    return [(m.command, m.result) for m in parsed(link) if m.get_type() == "COMMAND_ACK"]


def _airborne_server(n_links: int) -> tuple[Any, list[Any]]:
    """The FCU's ground-station server (`make_server`) with its vehicle armed 2 m up."""
    from tests.unit.test_gcs_dispatch import make_server
    server, links = make_server(n_links)
    server.pipeline.on_state(0, VehicleState((0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.0),
                                             (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), 0)
    assert server.pipeline.arm()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    return server, links


def _server_with_a_mission() -> tuple[Any, list[Any], Any, HeldWork]:
    """The airborne server (one link), its commander, a 3-item mission and work held."""
    server, links = _airborne_server(1)
    c = server.pipeline.commander
    work = HeldWork()
    c.work = work
    c.set_mission(tuple(_items(3)))
    return server, links, c, work


def test_a_command_under_way_is_in_progress_then_final_and_a_retry_is_not_run_again():
    """Given MISSION_START in flight with the plan made beside the loop (through the FCU's
    ground-station server), then nothing is said before IN_PROGRESS_FIRST_S; a retry
    (confirmation 1) meanwhile is answered IN_PROGRESS and plans nothing more; when the plan
    is taken in, the final ACCEPTED; a second MISSION_START under way that a LAND
    supersedes ends FAILED, and LAND is ACCEPTED."""
    server, links, c, work = _server_with_a_mission()
    start = MAV_CMD.MAV_CMD_MISSION_START
    _command(server, start, 0)
    assert _command_acks(links[0]) == []
    _command(server, start, 1)
    assert _command_acks(links[0]) == [(start, MAV_RESULT.MAV_RESULT_IN_PROGRESS)]
    assert len(work.held) == 1 and c.mode == Mode.HOLD
    work.release()
    assert _command_acks(links[0]) == [(start, MAV_RESULT.MAV_RESULT_ACCEPTED)]
    assert c.mode == Mode.MISSION
    _command(server, MAV_CMD.MAV_CMD_DO_SET_MODE, 0, 1.0, 4.0, 3.0)  # AUTO.LOITER: HOLD
    _command(server, start, 0)
    _command(server, MAV_CMD.MAV_CMD_NAV_LAND, 0)
    work.release()
    assert _command_acks(links[0]) == [
        (MAV_CMD.MAV_CMD_DO_SET_MODE, MAV_RESULT.MAV_RESULT_ACCEPTED),
        (start, MAV_RESULT.MAV_RESULT_FAILED),
        (MAV_CMD.MAV_CMD_NAV_LAND, MAV_RESULT.MAV_RESULT_ACCEPTED)]
    assert c.mode == Mode.LAND


def test_a_command_under_way_is_told_in_progress_again_until_its_end():
    """Given MISSION_START whose plan is made beside the loop (through the FCU's
    ground-station server) and lasts, then the sender is told IN_PROGRESS after
    IN_PROGRESS_FIRST_S (0.25 s), then again every IN_PROGRESS_REPEAT_S (0.5 s) while it
    lasts, as the command protocol allows (MAVSDK gives a command up when nothing follows
    IN_PROGRESS within 1.5 s at its defaults: a start from 14 m/s brakes for about 7 s),
    and nothing more once its final answer is given."""
    server, links, _c, work = _server_with_a_mission()
    start = MAV_CMD.MAV_CMD_MISSION_START
    _command(server, start, 0)  # at 1.0 s
    told = [(start, MAV_RESULT.MAV_RESULT_IN_PROGRESS)]
    assert _command_acks(links[0]) == []
    for now_s, again in ((1.2, False), (1.25, True), (1.7, False), (1.75, True), (2.3, True),
                         (2.5, False)):
        server.tick(now_s)
        assert _command_acks(links[0]) == (told if again else []), now_s
    work.release()
    assert _command_acks(links[0]) == [(start, MAV_RESULT.MAV_RESULT_ACCEPTED)]
    server.tick(5.0)
    assert _command_acks(links[0]) == [] and server.commands.under_way == {}


def test_work_done_within_a_quarter_second_is_answered_once_with_its_result():
    """Given MISSION_START whose plan beside the loop is taken in within
    IN_PROGRESS_FIRST_S, then its one COMMAND_ACK is the final ACCEPTED, as PX4 and
    ArduPilot answer a mode change (MAVSDK's mission plugins report a first IN_PROGRESS as
    their result, Busy), and nothing follows."""
    server, links, c, work = _server_with_a_mission()
    start = MAV_CMD.MAV_CMD_MISSION_START
    _command(server, start, 0)  # at 1.0 s
    server.tick(1.2)
    assert _command_acks(links[0]) == []
    work.release()
    assert _command_acks(links[0]) == [(start, MAV_RESULT.MAV_RESULT_ACCEPTED)]
    server.tick(3.0)
    assert _command_acks(links[0]) == [] and c.mode == Mode.MISSION


def test_the_same_mode_asked_by_two_stations_under_way_is_one_change_both_answered():
    """Given POSCTL asked by two stations (on two links) while its fit runs beside the loop,
    then both are answered IN_PROGRESS, one fit runs (the second joins, it does not drop the
    first), and when it is taken in both get ACCEPTED; a MISSION asked twice likewise.
    (A second request that dropped the first answered it FAILED while the mode it asked
    for was entered.)"""
    from fcu.modes import manual
    server, links = _airborne_server(2)
    c = server.pipeline.commander
    work = HeldWork()
    c.work = work
    c.manual_input(1.0, manual.CENTRED)
    set_mode = MAV_CMD.MAV_CMD_DO_SET_MODE
    for index, src in ((0, GCS), (1, OTHER)):
        server.handle(index, _msg(M.MAVLink_command_long_message(
            1, 1, set_mode, 0, 1.0, 3.0, 0.0, 0, 0, 0, 0), src), 1.0)  # POSCTL
    server.tick(1.3)  # the fit lasts: each is told IN_PROGRESS
    in_progress = [(set_mode, MAV_RESULT.MAV_RESULT_IN_PROGRESS)]
    assert _command_acks(links[0]) == in_progress and _command_acks(links[1]) == in_progress
    assert len(work.held) == 1 and c.mode == Mode.HOLD
    work.release()
    accepted = [(set_mode, MAV_RESULT.MAV_RESULT_ACCEPTED)]
    assert _command_acks(links[0]) == accepted and _command_acks(links[1]) == accepted
    assert c.mode == Mode.POSCTL
    c.set_mission(tuple(_items(3)))
    for index, src in ((0, GCS), (1, OTHER)):
        server.handle(index, _msg(M.MAVLink_command_long_message(
            1, 1, set_mode, 0, 1.0, 4.0, 4.0, 0, 0, 0, 0), src), 1.0)  # AUTO.MISSION
    assert len(work.held) == 1
    work.release()
    assert _command_acks(links[0]) == accepted and _command_acks(links[1]) == accepted
    assert c.mode == Mode.MISSION and c.modes.mission_run.running


def test_a_new_current_item_in_flight_is_confirmed_by_mission_current_and_its_ack():
    """Given DO_SET_MISSION_CURRENT in a flying mission, planned again beside the loop, then
    it is told IN_PROGRESS when the plan lasts, and when it is taken in both the spec's confirmation
    (MISSION_CURRENT with the new item) and the final COMMAND_ACK ACCEPTED go out (the
    ACK's reply used to replace the confirmation's)."""
    from tests.unit.test_gcs_dispatch import parsed
    server, links = _airborne_server(1)
    c = server.pipeline.commander
    c.set_mission(tuple(_items(3)))
    assert c.mission_start(0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED  # inline work
    work = HeldWork()
    c.work = work
    parsed(links[0])
    current = MAV_CMD.MAV_CMD_DO_SET_MISSION_CURRENT
    _command(server, current, 0, 2.0)
    server.tick(1.3)
    assert _command_acks(links[0]) == [(current, MAV_RESULT.MAV_RESULT_IN_PROGRESS)]
    work.release()
    sent = parsed(links[0])
    assert [(m.command, m.result) for m in sent if m.get_type() == "COMMAND_ACK"] == [
        (current, MAV_RESULT.MAV_RESULT_ACCEPTED)]
    assert [m.seq for m in sent if m.get_type() == "MISSION_CURRENT"] == [2]


# ---------------------------------------------------------------------- what supersedes what


def _posctl_or_mission_under_way(mode: Mode) -> tuple[Any, HeldWork, list[tuple[int, str]]]:
    """Airborne in HOLD with a mission stored and MANUAL_CONTROL heard; `mode` asked, its
    work held beside the loop; the replies its command gets."""
    from fcu.modes import manual
    c, work = _planned_commander()
    c.manual_input(0.0, manual.CENTRED)
    assert c.set_mode(mode, 0.0) == (IN_PROGRESS, "")
    replies: list[tuple[int, str]] = []
    c.under_way.on_end(lambda r, t: replies.append((r, t)))
    return c, work, replies


@pytest.mark.parametrize("mode", [Mode.MISSION, Mode.POSCTL])
def test_a_takeoff_supersedes_a_change_under_way(mode):
    """Given MISSION's plan or POSCTL's fit under way, when NAV_TAKEOFF is accepted, then
    the change is dropped (its command FAILED, superseded) and TAKEOFF stays in force when
    the work comes back. (The change used to be taken in over the accepted take-off: the
    climb abandoned for a mission or POSCTL.)"""
    c, work, replies = _posctl_or_mission_under_way(mode)
    answer = c.takeoff()
    assert answer[0] == MAV_RESULT.MAV_RESULT_ACCEPTED and c.mode == Mode.TAKEOFF
    assert replies == [(MAV_RESULT.MAV_RESULT_FAILED, "superseded by a newer command")]
    work.release()
    assert c.mode == Mode.TAKEOFF and c.under_way is None and len(replies) == 1
    assert not c.modes.mission_run.running


def _landing_pipeline(work: Work) -> Any:
    """Armed 2 m up, landing (LAND), a mission stored, the GCS link watched (COM_DL_LOSS_T
    5 s, COM_DL_LAND_T 10 s) and rotor saturation aborting missions (COM_SAT_ACT 1)."""
    from fcu.safety.failsafe import FailsafeSettings
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(vehicle=vehicle),
                    failsafes=FailsafeSettings(gcs_loss_s=5.0, gcs_loss_land_s=10.0,
                                               saturation_hold=True))
    pipe.on_state(0, VehicleState((0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    assert pipe.arm()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    pipe.commander.work = work
    pipe.commander.set_mission(tuple(_items(3)))
    pipe.check_links(0.0, 0.0)  # the GCS heard at 0 s
    assert pipe.commander.set_mode(Mode.LAND, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    return pipe


def _gcs_loss_in_landing(held: bool) -> tuple[Mode, Mode, list[int]]:
    """MISSION asked while landing, the GCS link lost before its plan is taken in: (the
    mode after the plan came back, the mode after COM_DL_LAND_T, the command's answers)."""
    work = HeldWork() if held else InlineWork()
    pipe = _landing_pipeline(work)
    c = pipe.commander
    answers: list[int] = []
    answer = c.set_mode(Mode.MISSION, 4.9)
    if c.under_way is not None:
        c.under_way.on_end(lambda r, t: answers.append(r))
    else:
        answers.append(answer[0])
    pipe.check_links(5.5, 0.0)  # lost
    if isinstance(work, HeldWork):
        work.release()
    after_loss = c.mode
    pipe.check_links(16.0, 0.0)  # COM_DL_LAND_T after the loss
    return after_loss, c.mode, answers


def test_a_failsafe_in_a_landing_judges_the_change_under_way_as_made():
    """Given MISSION asked while landing, when the GCS link is lost before its plan is taken
    in, then the vehicle does what it does when the plan is made in the loop: the loss's
    HOLD (the change dropped, its command FAILED, where inline it was ACCEPTED first), then
    LAND after COM_DL_LAND_T. (The landing used to make the loss's reaction needless, and
    the mission was then entered and flown with the link lost and no reaction at all.)"""
    assert _gcs_loss_in_landing(held=False) == (
        Mode.HOLD, Mode.LAND, [MAV_RESULT.MAV_RESULT_ACCEPTED])
    assert _gcs_loss_in_landing(held=True) == (
        Mode.HOLD, Mode.LAND, [MAV_RESULT.MAV_RESULT_FAILED])


def test_rotor_saturation_aborts_a_mission_whose_start_is_under_way():
    """Given COM_SAT_ACT 1 and a mission's start under way from HOLD, when the rotors have
    been saturated for COM_SAT_T, then the start is dropped and the vehicle holds, as the
    mission flown would have been aborted; a POSCTL fit under way is not (POSCTL is not
    aborted by saturation)."""
    for mode, expected in ((Mode.MISSION, Mode.HOLD), (Mode.POSCTL, Mode.POSCTL)):
        from fcu.modes import manual
        work = HeldWork()
        pipe = _landing_pipeline(work)
        c = pipe.commander
        c.set_mode(Mode.HOLD, 0.0)
        c.manual_input(0.0, manual.CENTRED)
        assert c.set_mode(mode, 0.0)[0] == IN_PROGRESS
        omega_sq = (1e9,) * 6
        pipe._check_saturation(0, True, omega_sq)
        pipe._check_saturation(2_100_000, True, omega_sq)  # COM_SAT_T (2 s) later
        work.release()
        assert c.mode == expected, mode
        aborted = any("mission aborted" in e.text for e in c.events)
        assert aborted == (mode == Mode.MISSION), mode


def test_a_new_current_item_re_aims_a_start_under_way():
    """Given MISSION_START under way, when a new current item is set before its plan is
    taken in, then the start flies from that item: one plan taken in, the MISSION_START's
    command ACCEPTED once, the current item the new one. (It used to be ACCEPTED and then
    silently undone: the start flew from item 0.)"""
    c, work = _planned_commander()
    c.set_mission(tuple(_items(4)))
    assert c.mission_start(0) == (IN_PROGRESS, "")
    replies: list[tuple[int, str]] = []
    c.under_way.on_end(lambda r, t: replies.append((r, t)))
    assert c.set_mission_current(3) == (IN_PROGRESS, "")
    assert replies == [] and len(work.held) == 2
    assert c.set_mission_current(3) == (IN_PROGRESS, "")  # sent again: the same plan
    assert len(work.held) == 2
    work.release()
    assert replies == [(MAV_RESULT.MAV_RESULT_ACCEPTED, "mission started")]
    assert c.mode == Mode.MISSION and c.modes.mission_run.running and c.mission_current == 3


def test_a_new_mission_leaves_posctl_under_way():
    """Given POSCTL's fit under way, when a mission upload is accepted (or the mission
    cleared), then POSCTL is still entered when fitted: the new mission drops only a
    mission's plan."""
    c, work, replies = _posctl_or_mission_under_way(Mode.POSCTL)
    c.set_mission(())
    assert replies == []
    work.release()
    assert replies == [(MAV_RESULT.MAV_RESULT_ACCEPTED, "mode POSCTL")]
    assert c.mode == Mode.POSCTL


def test_arming_in_mission_with_posctl_under_way_enters_posctl_alone():
    """Given MISSION_START on the ground (MISSION, flown when armed) and then POSCTL asked,
    its fit under way, when the vehicle arms, then no mission plan starts beside it: POSCTL
    is entered when fitted and stays. (Both used to be taken in: POSCTL ACCEPTED, then the
    mission's plan switched to MISSION.)"""
    from fcu.modes import manual
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(vehicle=vehicle))
    pipe.on_state(0, VehicleState((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    c = pipe.commander
    work = HeldWork()
    c.work = work
    c.set_mission(tuple(_items(3)))
    assert c.mission_start(0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED and c.mode == Mode.MISSION
    c.manual_input(0.0, manual.CENTRED)
    assert c.set_mode(Mode.POSCTL, 0.0) == (IN_PROGRESS, "")
    assert pipe.arm()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    assert len(work.held) == 1 and c.modes.mission_run.plan is None
    work.release()
    assert c.mode == Mode.POSCTL and not c.modes.mission_run.running


def test_a_clear_during_a_check_is_done_after_it_and_both_stations_are_answered():
    """Given GCS's upload being checked, when another station sends MISSION_CLEAR_ALL, then
    it is done right after the check, as in the loop: GCS gets its MISSION_ACK (and again
    for its last item re-sent), the other station ACCEPTED, and the mission is empty. (The
    clear used to drop the check: GCS never got a MISSION_ACK.) A new upload from GCS
    meanwhile drops the check and the clear is done then."""
    work = HeldWork()
    server = MissionServer(*VEHICLE, MissionLimits(), work=work)
    items = _items(4)
    assert _upload(server, items) == []
    clear = _msg(M.MAVLink_mission_clear_all_message(*VEHICLE, 0), OTHER)
    assert server.handle(clear, 0.0) == []
    assert server.mission == ()
    work.release()
    out = server.take_outbox()
    assert [(p, m.get_type(), m.type) for p, m in out] == [
        (GCS, "MISSION_ACK", M.MAV_MISSION_ACCEPTED), (OTHER, "MISSION_ACK",
                                                     M.MAV_MISSION_ACCEPTED)]
    assert server.mission == () and server.version == 2
    again = server.handle(_item(items[-1]), 1.0)
    assert _acks(again) == [M.MAV_MISSION_ACCEPTED]

    assert _upload(server, items) == []
    assert server.handle(clear, 0.0) == []
    assert _kinds(server.handle(_count(2), 0.0)) == ["MISSION_REQUEST_INT"]  # a new upload
    assert _acks(_out(server, OTHER)) == [M.MAV_MISSION_ACCEPTED]
    work.release()
    assert server.take_outbox() == [] and server.mission == ()


def test_an_answer_that_comes_later_goes_to_its_stations_link():
    """Given GCS's upload on link 0 checked, when another station starts an upload on link
    1 before the answer went out, then GCS's MISSION_ACK still goes out on link 0 (it went
    to the link of the latest upload)."""
    from tests.unit.test_gcs_dispatch import make_server, parsed
    server, links = make_server(2)
    work = HeldWork()
    server.missions.work = work
    items = _items(3)
    server.handle(0, _count(len(items)), 1.0)
    for it in items:
        server.handle(0, _item(it), 1.0)
    work.release()  # the check done, its answer queued
    server.handle(1, _count(2, OTHER), 1.0)
    server.tick(1.0)
    acks0 = [m for m in parsed(links[0]) if m.get_type() == "MISSION_ACK"]
    acks1 = [m for m in parsed(links[1]) if m.get_type() == "MISSION_ACK"]
    assert [(m.target_system, m.type) for m in acks0] == [(GCS[0], M.MAV_MISSION_ACCEPTED)]
    assert acks1 == []


def test_in_progress_says_progress_unknown_and_a_final_answer_keeps_a_newer_record():
    """Given MISSION_START under way, then its IN_PROGRESS carries progress 255 (the spec's
    unknown) and its final answer 0; a command the same station sent meanwhile is still
    answered from its record when retried (confirmation 1) after that final answer, not
    run again (the final answer used to overwrite the station's record)."""
    from tests.unit.test_gcs_dispatch import parsed
    server, links = _airborne_server(1)
    c = server.pipeline.commander
    work = HeldWork()
    c.work = work
    c.set_mission(tuple(_items(3)))
    start, interval = MAV_CMD.MAV_CMD_MISSION_START, MAV_CMD.MAV_CMD_SET_MESSAGE_INTERVAL
    _command(server, start, 0)
    _command(server, interval, 0, float(M.MAVLINK_MSG_ID_HEARTBEAT), 1e6)
    server.tick(1.3)  # the plan lasts: told IN_PROGRESS
    work.release()
    _command(server, interval, 1, float(M.MAVLINK_MSG_ID_HEARTBEAT), 1e6)
    acks = [(m.command, m.result, m.progress) for m in parsed(links[0])
            if m.get_type() == "COMMAND_ACK"]
    ok = MAV_RESULT.MAV_RESULT_ACCEPTED
    assert acks == [(interval, ok, 0), (start, IN_PROGRESS, 255), (start, ok, 0),
                    (interval, ok, 0)]
    assert server.commands.repeated_commands == 1
    assert c.mode == Mode.MISSION
