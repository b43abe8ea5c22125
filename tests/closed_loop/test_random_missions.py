"""A 50-mission sample of the random-mission campaign (benchmarks/random_missions.py): 25
seeded missions per vehicle, each checked by the FCU's upload check with the FCU's limits and,
if accepted, flown in-process with truth sensors; every accepted mission must hold the
campaign's property (status completed, <= 5 cm, <= 3 deg, no monitor event).

Kept short: at most 6 draws per mission (instead of 12) and a planned timeline of at most
27 s (each run at most 30 s simulated); otherwise the campaign's distributions."""

from __future__ import annotations

import dataclasses

import pytest

from benchmarks.random_mission_gen import DEFAULT
from benchmarks.random_missions import (
    VEHICLES,
    base_scenario,
    fly,
    prepare,
    reason_kind,
    violations,
)

MISSIONS_PER_VEHICLE = 25
SEED = 2
MAX_PLANNED_S = 27.0
SHORT = dataclasses.replace(DEFAULT, n_draws=(2, 6))


@pytest.mark.slow
@pytest.mark.parametrize("vehicle", VEHICLES)
def test_random_missions_track_or_are_refused(vehicle, tmp_path):
    base = base_scenario(vehicle)
    refused: dict[str, int] = {}
    flown, bad = 0, []
    for k in range(MISSIONS_PER_VEHICLE):
        prep = prepare(base, k, SEED, tmp_path, MAX_PLANNED_S, SHORT, vehicle=vehicle)
        assert prep.scenario.duration_s <= MAX_PLANNED_S + 3.0
        if prep.check.result != 0:
            kind = reason_kind(prep.check.reason)
            refused[kind] = refused.get(kind, 0) + 1
            continue
        flight = fly(prep)
        flown += 1
        why = violations(flight)
        if why:
            bad.append(f"mission {k} (cruise {prep.cruise_m_s:.2f} m/s, "
                       f"{len(prep.items)} items): {'; '.join(why)}")
    print(f"{vehicle}: {flown} flown, refused {refused}")
    assert flown > 0, f"every mission refused: {refused}"
    assert not bad, f"{len(bad)} of {flown} accepted missions break the property:\n" + \
        "\n".join(bad)
