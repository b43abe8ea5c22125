"""The mission check's shortcuts give the full computation's answers, to the bit: the yes/no
kernel and the ratio kernel against `excess_kernel`, the search stopped early
(`TimeScaling.stretches`) and resumed, the parts moves and figures share through
`Envelope.kept`, the upload check's unstretched plan, a figure's compiled allocations and the
yes/no answer from the allocations (`fcu.envelope.verdict`) (fcu/envelope/excess.py,
fcu/envelope/feasibility.py, fcu/envelope/scaling.py, fcu/envelope/verdict.py, fcu/mission/)."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from benchmarks.mission_envelope import mixed
from benchmarks.random_mission_gen import random_cruise_speed, random_mission
from common.config.scenario import load_vehicle
from fcu.control.dualquat import Q_IDENTITY, q_exp
from fcu.envelope import feasibility
from fcu.envelope.excess import excess_kernel, excess_ratio, fits_kernel, parts_into
from fcu.envelope.feasibility import (
    DIFF_STEP,
    TILT_STEP_S,
    Envelope,
    TimeScaling,
    at_rest,
    envelope,
)
from fcu.envelope.instants import time_order
from fcu.envelope.verdict import fits_raw
from fcu.mission.limits import MissionLimits
from fcu.mission.planning import envelope_reason, plan_item, with_speed
from fcu.mission.segments import Figure, Move
from fcu.reference.trajectory import FigureInfinity

ROOT = Path(__file__).resolve().parents[2]
TILTED = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
PLANAR = load_vehicle(ROOT / "config/vehicles/hexa_planar.toml")
Q0 = q_exp((0.3, -0.2, 0.5))
Q0_W = (-Q0[0], Q0[1], Q0[2], Q0[3])  # another attitude, the same vector part
Q0_FLIPPED = ((Q0[0], -Q0[1], Q0[2], Q0[3]), (Q0[0], Q0[1], -Q0[2], Q0[3]),
              (Q0[0], Q0[1], Q0[2], -Q0[3]))  # others, one component of the vector part apart


def _paths() -> list[Move | Figure]:
    """Moves that climb, brake, turn and keep their attitude, and figures (slow to fast)."""
    return [Move(0, 0.0, (0.0, 0.0, 1.0), (0.0, 0.0, 2.0), Q_IDENTITY, None, 1.0, 0.0),
            Move(0, 0.0, (0.0, 0.0, 3.0), (4.0, -3.0, -2.5), Q0, None, 1.0, 0.0),
            Move(0, 0.0, (0.0, 0.0, 3.0), (1.0, 2.0, 0.5), Q0, (0.4, -1.1, 2.0), 1.0, 0.0),
            Move(0, 0.0, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), Q_IDENTITY, (0.0, 0.0, 3.0), 1.0,
                 0.0),
            Figure(0, 0.0, (0.0, 0.0, 3.0), Q0, 2.0, 1.0, (2.0, 1.0, -3.0)),
            Figure(0, 0.0, (0.0, 0.0, 3.0), Q_IDENTITY, 0.5, 1.0, (0.0, 0.3, 0.2))]


def _fresh(env: Envelope, path: Move | Figure) -> TimeScaling:
    """The path's scaling with nothing kept from before."""
    feasibility.clear_caches()
    return env.scaling(path)


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_ratio_and_fits_are_the_excess_kernels(vehicle):
    """Given paths flown from far too fast to slow, then excess_ratio is excess_kernel's
    ratio to the bit, fits_kernel says whether it is at most 1, and a ratio stopped at 1 is
    above 1 exactly where the full one is."""
    env = envelope(vehicle)
    for path in _paths():
        sc = _fresh(env, path)
        o, scratch = sc.order, np.empty(sc.samples)
        args = (env.limit, env.tau_up, env.tau_down, env.tilt_limit,
                env.tilt_rate_max * TILT_STEP_S)
        for duration in np.geomspace(0.05, 300.0, 60):
            full = excess_kernel(sc.om0, sc.om1, sc.dom0, sc.dom1, sc.is_end, duration, *args,
                                 sc.after, sc.gap, env.floor)[0]
            ratio = excess_ratio(sc.parts, o.place_gap, o.place_ends, duration, *args,
                                 env.floor > 0.0, 1e6, scratch)
            stopped = excess_ratio(sc.parts, o.place_gap, o.place_ends, duration, *args,
                                   env.floor > 0.0, 1.0, scratch)
            assert ratio == full or ratio > 1e6, (path, duration)
            assert fits_kernel(sc.parts, o.place_gap, o.place_ends, duration, *args,
                               env.floor > 0.0, scratch) == (full <= 1.0)
            assert (stopped > 1.0) == (full > 1.0)


@pytest.mark.parametrize("probed", [0, 2, 3, 4], ids=["speed", "slowing", "tilt", "step"])
def test_fits_at_each_limit_is_the_excess_kernels(probed):
    """Given one limit binding (rotor speed, slowing, tilt rate and turns, tilt step: the
    others out of reach), set at the need of a path's most demanding actuator and a few
    doubles either side, then fits_kernel says whether excess_kernel's ratio is at most 1
    and excess_ratio is that ratio, to the bit."""
    env = envelope(TILTED)
    for path in _paths():
        sc = _fresh(env, path)
        o, scratch = sc.order, np.empty(sc.samples)
        for duration in (0.3, 1.0, 4.0, 30.0):
            args = [1e300, 0.0, 0.0, 1e300, 1e300]  # limit, tau_up, tau_down, tilt, step
            args[probed] = 1.0
            need = excess_kernel(sc.om0, sc.om1, sc.dom0, sc.dom1, sc.is_end, duration, *args,
                                 sc.after, sc.gap, 0.0)[0]
            if not 0.0 < need < 1e300:
                continue
            at = 1.0 / need if probed == 2 else need  # tau_down divides, the others limit
            for x in (at, *np.nextafter(at, [0.0, np.inf]),
                      *np.nextafter(np.nextafter(at, [0.0, np.inf]), [0.0, np.inf])):
                args[probed] = float(x)
                full = excess_kernel(sc.om0, sc.om1, sc.dom0, sc.dom1, sc.is_end, duration,
                                     *args, sc.after, sc.gap, 0.0)[0]
                assert fits_kernel(sc.parts, o.place_gap, o.place_ends, duration, *args,
                                   False, scratch) == (full <= 1.0), (path, duration, x)
                assert excess_ratio(sc.parts, o.place_gap, o.place_ends, duration, *args,
                                    False, 1e6, scratch) == full


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_stretches_is_the_shortest_duration_compared(vehicle):
    """Given a path and planned durations around its shortest one, then `stretches` answers
    as the full search compared, and the search resumed after it ends where a fresh one
    does, with the same duration found fitting."""
    env = envelope(vehicle)
    for path in _paths():
        shortest = _fresh(env, path).shortest()
        for factor in (0.0, 0.5, 0.9, 0.99, 0.99995, 1.0, 1.00005, 1.01, 1.1, 2.0, 50.0):
            planned = shortest * factor if math.isfinite(shortest) else factor
            sc = _fresh(env, path)
            assert sc.stretches(planned) == (math.isfinite(shortest) and shortest > planned)
            assert sc.shortest() == shortest
            assert sc.fits(shortest) == _fresh(env, path).fits(shortest)


def _parts_kept_and_fresh(env: Envelope, first: Move | Figure,
                          second: Move | Figure) -> tuple[np.ndarray, np.ndarray]:
    feasibility.clear_caches()
    env.scaling(first)
    kept = env.scaling(second).parts
    return kept, _fresh(env, second).parts


def test_paths_share_only_what_they_have_in_common():
    """Given two moves or figures that share what `Envelope.kept` keeps (q0 and phi; the
    amplitude and axis) or differ in one component of it (with as many samples), when the
    second is scaled after the first, then its parts are those of the second scaled alone,
    to the bit."""
    env = envelope(TILTED)
    phi = (0.4, -1.1, 2.0)
    pairs = [
        (Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, phi, 1.0, 0.0),
         Move(0, 0.0, (0.0,) * 3, (-3.0, 0.5, 0.0), Q0, phi, 1.0, 0.0)),  # dp differs
        (Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, phi, 1.0, 0.0),
         Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, (0.4, -1.1, 2.1), 1.0, 0.0)),
        *((Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, phi, 1.0, 0.0),
           Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, other, 1.0, 0.0))
          for other in ((-0.4, -1.1, 2.0), (0.4, 1.1, 2.0), (0.4, -1.1, -2.0))),
        (Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, phi, 1.0, 0.0),
         Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q_IDENTITY, phi, 1.0, 0.0)),
        (Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, phi, 1.0, 0.0),
         Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0_W, phi, 1.0, 0.0)),
        *((Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, phi, 1.0, 0.0),
           Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), other, phi, 1.0, 0.0))
          for other in Q0_FLIPPED),  # q0 differs in its x, y or z component alone
        *((Figure(0, 0.0, (0.0,) * 3, Q0, 2.0, 1.0, (2.0, 1.0, -3.0)),
           Figure(0, 0.0, (0.0,) * 3, other, 2.0, 1.0, (2.0, 1.0, -3.0)))
          for other in Q0_FLIPPED),
        (Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q0, None, 1.0, 0.0),
         Move(0, 0.0, (0.0,) * 3, (1.0, 2.0, 0.5), Q_IDENTITY, None, 1.0, 0.0)),
        (Figure(0, 0.0, (0.0,) * 3, Q0, 2.0, 1.0, (2.0, 1.0, -3.0)),
         Figure(0, 0.0, (1.0, 5.0, 3.0), Q_IDENTITY, 2.0, 1.0, (2.0, 1.0, -3.0))),
        (Figure(0, 0.0, (0.0,) * 3, Q0, 2.0, 1.0, (2.0, 1.0, -3.0)),
         Figure(0, 0.0, (0.0,) * 3, Q0, 1.5, 1.0, (2.0, 1.0, -3.0))),
        *((Figure(0, 0.0, (0.0,) * 3, Q0, 2.0, 1.0, (2.0, 1.0, -3.0)),
           Figure(0, 0.0, (0.0,) * 3, Q0, 2.0, 1.0, other))
          for other in ((2.0, 1.0, -2.9), (-2.0, 1.0, -3.0), (2.0, -1.0, -3.0),
                        (2.0, 1.0, 3.0))),
    ]
    for first, second in pairs:
        kept, fresh = _parts_kept_and_fresh(env, first, second)
        assert kept.tobytes() == fresh.tobytes(), (first, second)


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_the_upload_check_judges_unstretched_moves_as_stretched_ones(vehicle):
    """Given the items of random missions and of a mixed one planned as the executor plans
    them, then each item's envelope reason is the same when its speed-timed moves are left
    unstretched (the upload check) as when they are stretched."""
    missions = [(mixed(40), MissionLimits(vehicle=vehicle))]
    for seed in range(40):
        rng = np.random.default_rng(seed)
        items = random_mission(rng)
        missions.append((items, MissionLimits(vehicle=vehicle,
                                              cruise_speed_m_s=random_cruise_speed(rng))))
    judged = 0
    for items, limits in missions:
        t, p, q = 0.0, (0.0, 0.0, 0.0), Q_IDENTITY
        planned = limits
        for item in items:
            planned = with_speed(item, planned, limits)
            feasibility.clear_caches()
            unstretched = plan_item(item, t, p, q, planned, stretch=False)
            reason = envelope_reason(item, unstretched, planned)
            feasibility.clear_caches()
            stretched = plan_item(item, t, p, q, planned)
            assert reason == envelope_reason(item, stretched, planned), item
            judged += 1
            t, p, q = stretched.t1, stretched.p_end, stretched.q_end
    assert judged > 300


def _figures() -> list[Figure]:
    """Figures from the identity, from a start attitude, and without one (q0 None)."""
    figures = [Figure(0, 0.0, (0.0, 0.0, 3.0), q, amp, 1.0, axis)
               for q in (Q_IDENTITY, Q0, *Q0_FLIPPED)
               for amp, axis in ((2.0, (2.0, 1.0, -3.0)), (0.5, (0.0, 0.3, 0.2)),
                                 (1.0, (0.0, 0.0, 1.0)))]
    bare = Figure(0, 0.0, (1.0, 2.0, 3.0), Q_IDENTITY, 1.5, 1.0, (0.7, -0.2, 0.4))
    bare.figure = FigureInfinity(1.5, 1.0, (0.7, -0.2, 0.4), (1.0, 2.0, 3.0))
    return [*figures, bare]


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_figure_allocations_are_those_of_its_path(vehicle):
    """Given figures (start attitudes, amplitudes, axes; q0 None too), then the allocations
    of their 1 s path and of its poses at rest made by the compiled kernel
    (`Figure.unit_allocations`) are `Envelope.omega_sq` of `Figure.path` and of its poses at
    rest, to the bit."""
    env = envelope(vehicle)
    for fig in _figures():
        sigma = time_order(fig.instants()).stepped
        feasibility.clear_caches()
        om, hover = fig.unit_allocations(env, sigma)
        path = fig.path(sigma)
        assert om.tobytes() == env.omega_sq(path).tobytes(), fig.figure.q0
        assert hover.tobytes() == env.omega_sq(at_rest(path)).tobytes(), fig.figure.q0


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_fits_from_the_allocations_is_fits_kernel(vehicle):
    """Given paths flown from far too fast to slow, and each limit bound alone at a path's
    need and a few doubles either side, then `fits_raw` on the path's allocations answers
    as `fits_kernel` on its parts, and `parts_into` makes the parts to the bit into an array
    whatever it held before (`fits_raw` reuses one)."""
    env = envelope(vehicle)
    for path in _paths():
        sc = _fresh(env, path)
        o, scratch = sc.order, np.empty(sc.samples)
        om, hover = env.allocations(path, o)
        room = np.full((om.shape[1] * 5, sc.samples), np.nan)
        parts_into(om, hover, sc.samples, 2.0 * DIFF_STEP, env.floor, o.places, o.place_ends,
                   room.reshape(sc.parts.shape))
        assert room.tobytes() == sc.parts.tobytes()
        base = [env.limit, env.tau_up, env.tau_down, env.tilt_limit,
                env.tilt_rate_max * TILT_STEP_S]
        for duration in np.geomspace(0.05, 300.0, 40):
            cases = [base]
            for probed in range(5):
                args = [1e300, 0.0, 0.0, 1e300, 1e300]
                args[probed] = 1.0
                need = excess_ratio(sc.parts, o.place_gap, o.place_ends, duration, *args,
                                    False, 1e6, scratch)
                at = 1.0 / need if probed == 2 else need
                cases += [[*args[:probed], float(x), *args[probed + 1:]]
                          for x in (at, *np.nextafter(at, [0.0, np.inf]))]
            for args in cases:
                for use_floor in (False, env.floor > 0.0):
                    assert fits_raw(om, hover, 2.0 * DIFF_STEP, env.floor, o.places,
                                    o.place_gap, o.place_ends, duration, *args,
                                    use_floor, room) == \
                        fits_kernel(sc.parts, o.place_gap, o.place_ends, duration, *args,
                                    use_floor, scratch), (path, duration, args)


def test_a_scaling_asked_fits_first_has_the_parts_of_one_made_at_once():
    """Given paths, when a fresh scaling is asked whether durations fit (from the
    allocations) before its parts, then its answers, its parts, its shortest duration and
    its pickled copy are those of a scaling whose parts were made first."""
    env = envelope(TILTED)
    for path in _paths():
        eager = _fresh(env, path)
        parts = eager.parts.copy()
        lazy = _fresh(env, path)
        for duration in (0.3, 1.0, 4.0, 30.0):
            assert lazy.fits(duration) == eager.fits(duration)
        assert lazy._parts is None
        assert lazy.parts.tobytes() == parts.tobytes()
        assert lazy.shortest() == eager.shortest()
        copy = pickle.loads(pickle.dumps(_fresh(env, path)))
        assert copy.parts.tobytes() == parts.tobytes()


def test_a_scratch_array_is_handed_out_again_only_once_free():
    """Given an envelope's scratch arrays, when one large array is held (directly or
    through a view) it is not handed out again, and once dropped it is; a small one is
    always new."""
    env = Envelope(TILTED)
    held = env.scratch(60, 400)
    view = env.scratch(60, 400)[1:]
    third = env.scratch(60, 400)
    assert len({id(held), id(view.base), id(third)}) == 3
    freed = {id(view.base)}
    del view
    assert id(env.scratch(60, 400)) in freed
    freed.add(id(third))
    del third
    again = env.scratch(60, 400)
    assert id(again) in freed and again is not held
    assert env.scratch(2, 6) is not env.scratch(2, 6)
