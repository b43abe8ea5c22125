"""The moves of a mission judged at once (`fcu.mission.verdicts`) and stretched at once
(`fcu.mission.stretch`): numpy's own product in compiled code (`common.gemm.gemm_nt`) is
numpy's `@` to the bit, every move's verdict is its scaling's (`TimeScaling.fits`), a
mission's first refusal is still the first item that fails, whether the envelope or a
parameter refuses it, and the executor's plan is the one made item by item, however the
moves are shared out between threads (`fcu.mission.batches`); the plan a worker hands the
loop carries no scalings."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from benchmarks.mission_envelope import mixed, waypoints
from common.config.scenario import load_vehicle
from common.frames import q_ned_frd_to_enu_flu
from common.gemm import AVAILABLE, gemm_nt
from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import MissionItem, local_xy
from fcu.control.dualquat import Q_IDENTITY, norm3, q_conj, q_exp, q_log, q_mul
from fcu.edge.work_process import SideBySide
from fcu.envelope.feasibility import clear_caches, envelope
from fcu.mission import batches
from fcu.mission.codes import MAV_MISSION_DENIED, MAV_MISSION_INVALID_PARAM1
from fcu.mission.executor import MissionExecutor, plan
from fcu.mission.limits import MissionLimits
from fcu.mission.planning import plan_item, with_speed
from fcu.mission.segments import ZERO, Move, Segment, keyframe_turn
from fcu.mission.start import plan_from
from fcu.mission.validation import check_mission
from fcu.mission.verdicts import batched, fits_many

ROOT = Path(__file__).resolve().parents[2]
VEHICLES = {name: load_vehicle(ROOT / f"config/vehicles/{name}.toml")
            for name in ("hexa_tilted", "hexa_planar")}
LOCAL = int(MAV_FRAME.MAV_FRAME_LOCAL_NED)
KEYFRAME = int(MAV_CMD.MAV_CMD_WAYPOINT_USER_1)


@pytest.mark.skipif(not AVAILABLE, reason="numpy's BLAS not found under its wheel's name")
def test_the_compiled_product_is_numpys_to_the_bit() -> None:
    rng = np.random.default_rng(3)
    for rows in (2, 3, 67, 201, 921, 5538):
        a = rng.standard_normal((rows, 6)) * rng.uniform(0.1, 100.0)
        b = rng.standard_normal((12, 6))
        out = np.empty((rows, 12))
        gemm_nt(a, b, out)
        assert np.array_equal((a @ b.T).view(np.int64), out.view(np.int64))


def _moves(limits: MissionLimits, scale: float) -> list[Move]:
    """The moves of a mixed mission planned from the origin, their durations scaled."""
    t, p, q = 0.0, ZERO, Q_IDENTITY
    planned, out = limits, []
    for item in mixed(60):
        planned = with_speed(item, planned, limits)
        seg = plan_item(item, t, p, q, planned, stretch=False, scaled=False)
        t, p, q = seg.t1, seg.p_end, seg.q_end
        if isinstance(seg, Move) and seg.moves and seg.duration > 0.0:
            seg.travel = seg.duration = seg.duration * scale
            out.append(seg)
    return out


@pytest.mark.parametrize("name", sorted(VEHICLES))
def test_each_moves_verdict_is_its_scalings(name: str) -> None:
    env = envelope(VEHICLES[name])
    verdicts: list[bool] = []
    for scale in (0.1, 0.3, 1.0, 3.0):
        moves = _moves(MissionLimits(vehicle=VEHICLES[name]), scale)
        assert all(batched(env, m) for m in moves)
        got = fits_many(env, moves)
        clear_caches()
        assert got == [env.scaling(m).fits(m.duration) for m in moves]
        verdicts += got
    assert any(verdicts) and not all(verdicts)


def _keyframe(seq: int, seconds: float, north_m: float = 2.0) -> MissionItem:
    return MissionItem(seq, LOCAL, KEYFRAME, 0, 1, seconds, 0.0, 0.0, 0.0, local_xy(north_m),
                       0, -3.0)


def test_the_first_failing_item_is_reported_whatever_refuses_it() -> None:
    limits = MissionLimits(vehicle=VEHICLES["hexa_tilted"])
    slow, fast, bad = _keyframe(1, 20.0), _keyframe(2, 0.05, 20.0), _keyframe(3, -1.0)
    takeoff = MissionItem(0, LOCAL, int(MAV_CMD.MAV_CMD_NAV_TAKEOFF), 1, 1, 0.0, 0.0, 0.0,
                          math.nan, 0, 0, -3.0)
    assert check_mission([takeoff, slow], limits).result == 0
    envelope_first = check_mission([takeoff, slow, fast, bad], limits)
    assert (envelope_first.result, envelope_first.seq) == (MAV_MISSION_DENIED, 2)
    bad, fast = bad._replace(seq=2), fast._replace(seq=3)
    params_first = check_mission([takeoff, slow, bad, fast], limits)
    assert (params_first.result, params_first.seq) == (MAV_MISSION_INVALID_PARAM1, 2)


def _one_by_one(items: list[MissionItem], limits: MissionLimits) -> list[Segment]:
    """The executor's plan made item by item, each move stretched as it is planned."""
    t, p, q = 1.0, (0.03, -0.02, 0.0), (0.99, 0.01, -0.02, 0.1)
    planned, out = limits, []
    for item in items:
        planned = with_speed(item, planned, limits)
        seg = plan_item(item, t, p, q, planned)
        out.append(seg)
        t, p, q = seg.t1, seg.p_end, seg.q_end
    return out


@pytest.mark.parametrize("name", sorted(VEHICLES))
def test_the_executors_plan_is_the_one_made_item_by_item(name: str) -> None:
    """The moves stretched at once (`fcu.mission.stretch`): the same timeline to the bit, the
    same scalings (their parts, their shortest durations, their verdicts)."""
    for cruise in (1.0, 5.0, 20.0):
        limits = MissionLimits(vehicle=VEHICLES[name], cruise_speed_m_s=cruise)
        items = mixed(40)
        clear_caches()
        expected = _one_by_one(items, limits)
        clear_caches()
        got = plan(items, 0, 1.0, (0.03, -0.02, 0.0), (0.99, 0.01, -0.02, 0.1), limits)
        assert [(s.seq, s.t0, s.t1, s.duration, s.p_end, s.q_end) for s in got] == \
            [(s.seq, s.t0, s.t1, s.duration, s.p_end, s.q_end) for s in expected]
        for a, b in zip(got, expected, strict=True):
            assert (a.scaling is None) == (b.scaling is None)
            if a.scaling is not None and b.scaling is not None:
                assert a.scaling.parts.tobytes() == b.scaling.parts.tobytes()
                assert a.scaling.shortest() == b.scaling.shortest()
                assert a.scaling.fits(a.duration) == b.scaling.fits(b.duration)


@pytest.mark.parametrize("name", sorted(VEHICLES))
def test_without_numpys_blas_function_the_old_path_gives_the_same(name: str,
                                                                monkeypatch) -> None:
    """Where numpy's build does not export the BLAS function (`AVAILABLE` False), every move
    is judged and stretched by its own scaling: the same verdicts, refusals and plan."""
    import fcu.mission.verdicts as verdicts

    results = []
    for available in (True, False):
        monkeypatch.setattr(verdicts, "AVAILABLE", available)
        assert batched(envelope(VEHICLES[name]), _moves(MissionLimits(
            vehicle=VEHICLES[name]), 1.0)[0]) is available
        limits = MissionLimits(vehicle=VEHICLES[name], cruise_speed_m_s=5.0)
        clear_caches()
        items = mixed(40)
        fast = _keyframe(len(items), 0.05, 20.0)  # a refused keyframe after the mixed ones
        checked = [check_mission(items, limits), check_mission([*items, fast], limits)]
        clear_caches()
        got = plan(items, 0, 1.0, (0.03, -0.02, 0.0), (0.99, 0.01, -0.02, 0.1), limits)
        results.append(([(c.result, c.seq, c.reason) for c in checked],
                        [(s.seq, s.t0, s.t1, s.duration, s.p_end, s.q_end) for s in got]))
    assert results[0] == results[1]
    assert results[0][0][0][0] == 0 and results[0][0][1][0] == MAV_MISSION_DENIED


def test_shares_cover_the_order_in_contiguous_pieces_of_about_equal_work() -> None:
    order = np.arange(100)[::-1].copy()
    work = np.r_[np.full(50, 3.0), np.full(50, 1.0)]
    try:
        assert [len(p) for p in batches.shares(order, work)] == [100]  # one way installed
        batches.install(batches.in_turn, 2)
        pieces = batches.shares(order, work)
        assert np.array_equal(np.concatenate(pieces), order)
        assert [len(p) for p in pieces] == [33, 67]  # work 99 and 101 of 200
        assert [len(p) for p in batches.shares(order[:31], work[:31])] == [31]  # too few
        batches.install(batches.in_turn, 3)
        assert len(batches.shares(order, work)) == 3
        with pytest.raises(ValueError):
            batches.install(batches.in_turn, 0)
    finally:
        batches.install(batches.in_turn, 1)


def _check_and_plan(limits: MissionLimits) -> tuple[object, ...]:
    items = mixed(150)
    fast = _keyframe(len(items), 0.05, 20.0)  # a refused keyframe after the mixed ones
    clear_caches()
    checked = [check_mission(items, limits), check_mission([*items, fast], limits)]
    clear_caches()
    got = plan(items, 0, 1.0, (0.03, -0.02, 0.0), (0.99, 0.01, -0.02, 0.1), limits)
    return ([(c.result, c.seq, c.reason) for c in checked],
            [(s.seq, s.t0, s.t1, s.duration, s.p_end, s.q_end) for s in got],
            [(s.scaling.parts.tobytes(), s.scaling.shortest()) for s in got
             if s.scaling is not None])


@pytest.mark.parametrize("name", sorted(VEHICLES))
def test_however_the_moves_are_shared_out_and_run_the_results_are_the_same(name: str) -> None:
    """Given the batch kernels' moves cut two or three ways, the shares run in reverse order
    or side by side on threads, then the verdicts, refusals, plan and scalings are the ones
    made in one call, to the bit."""
    limits = MissionLimits(vehicle=VEHICLES[name], cruise_speed_m_s=5.0)
    expected = _check_and_plan(limits)
    assert expected[0][0][0] == 0 and expected[0][1][0] == MAV_MISSION_DENIED
    side_by_side = SideBySide(2)
    shared: list[int] = []

    def backwards(calls):
        shared.append(len(calls))
        batches.in_turn(list(calls)[::-1])

    def threads(calls):
        shared.append(len(calls))
        side_by_side(calls)

    try:
        for runner, ways in ((backwards, 3), (threads, 2)):
            shared.clear()
            batches.install(runner, ways)
            assert _check_and_plan(limits) == expected, ways
            assert max(shared) == ways  # the moves were shared out
    finally:
        batches.install(batches.in_turn, 1)


def test_the_plan_handed_to_the_loop_flies_the_same_and_carries_no_scalings() -> None:
    """Given a 500-waypoint mission planned at its start (`plan_from`, a worker's job), then
    its executor samples the same references as one that kept its scalings, holds none, and
    pickles to less than a megabyte (with them, 16 MB, unpickled in the loop's thread)."""
    limits = MissionLimits(vehicle=VEHICLES["hexa_tilted"])
    items = waypoints(500)
    start = (1.0, (0.03, -0.02, 3.0), (0.99, 0.01, -0.02, 0.1))
    handed, why = plan_from(items, limits, 0, *start)
    assert handed is not None and why == ""
    kept = MissionExecutor(items, limits)
    kept.set_current(0, *start)
    assert sum(seg.scaling is not None for seg in kept._segments) == 500
    assert all(seg.scaling is None for seg in handed._segments)
    assert handed.schedule == kept.schedule
    for t_s in np.linspace(0.5, kept.end_time_s + 1.0, 997):
        assert handed.sample(float(t_s)) == kept.sample(float(t_s))
    assert len(pickle.dumps(handed, protocol=pickle.HIGHEST_PROTOCOL)) < 1_000_000
    assert len(pickle.dumps(kept, protocol=pickle.HIGHEST_PROTOCOL)) > 10_000_000


def test_the_keyframes_compiled_turn_is_the_frame_conversion_and_quaternion_maths_to_the_bit():
    """`keyframe_turn` writes `common.frames.q_ned_frd_to_enu_flu`'s products out inside its
    kernel; given start attitudes and NED/FRD rotations at random and at the extremes (none,
    a half turn, the axes' half turns, tiny angles), then its turn, whether it turns and its
    end attitude are those of `q_exp`, `q_ned_frd_to_enu_flu`, `q_log` and `q_mul`, to the
    bit: a change of the frame convention in one place and not the other fails here."""
    rng = np.random.default_rng(11)
    rots = [(0.0, 0.0, 0.0), (math.pi, 0.0, 0.0), (0.0, math.pi, 0.0), (0.0, 0.0, math.pi),
            (1e-12, 0.0, -1e-12), (0.3, -0.2, 0.5), (-math.pi, 0.0, 0.0),
            *(tuple(float(v) for v in rng.uniform(-3.2, 3.2, 3)) for _ in range(200))]
    starts = [Q_IDENTITY, q_exp((0.01, -0.02, 0.3)), q_exp((math.pi, 0.0, 0.0)),
              q_ned_frd_to_enu_flu(q_exp((0.3, -0.2, 0.5))),  # already there: no turn
              *(q_exp(tuple(float(v) for v in rng.uniform(-3.2, 3.2, 3))) for _ in range(20))]
    turned = 0
    for q0 in starts:
        for rot in rots:
            q1 = q_ned_frd_to_enu_flu(q_exp(rot))
            phi = q_log(q_mul(q_conj(q0), q1))
            turns = norm3(phi) > 0.0
            expected = (phi, turns, q_mul(q0, q_exp(phi)) if turns else q0)
            got = keyframe_turn(q0, *rot)
            assert np.array_equal(np.array([*got[0], *got[2]]).view(np.int64),
                                  np.array([*expected[0], *expected[2]]).view(np.int64)), \
                (q0, rot)
            assert got[1] == expected[1]
            turned += turns
    assert 0 < turned < len(starts) * len(rots)
