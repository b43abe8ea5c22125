"""Campaign files: keys, axes, draws, validation of every run, run ids, the journal and the
table; actuator faults on the plant's commands; the envelope of the summary."""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import pytest

from common.config.scenario import (
    ActuatorFault,
    ConfigError,
    load_scenario,
    resolved_scenario_data,
    scenario_from_data,
)
from gcs.campaign.journal import Journal, read_journal, write_table
from gcs.campaign.keys import key_path, set_key
from gcs.campaign.load import load_campaign
from gcs.campaign.model import CampaignError
from gcs.campaign.report import envelope, per_value
from gcs.campaign.runs import expand, run_id
from gcs.campaign.worker import flatten
from sitl.actuator_faults import ActuatorFaults
from sitl.plant import ActuatorCommand, Plant, initial_state

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"
CAMPAIGNS = ROOT / "config" / "campaigns"


def write(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    path = tmp_path / name
    path.write_text(f'name = "t"\nbase = "{SCENARIOS / "case2_impulse.toml"}"\n' + text)
    return path


# ------------------------------------------------------------------ scenario data


def test_resolved_data_loads_as_the_file_does() -> None:
    for name in ("case1_figure8", "case2_impulse", "mission_tour"):
        path = SCENARIOS / f"{name}.toml"
        a, b = load_scenario(path), scenario_from_data(resolved_scenario_data(path), path)
        assert dataclasses.replace(b, files=a.files) == a


def test_inline_tables_are_validated_like_files() -> None:
    path = SCENARIOS / "case2_impulse.toml"
    data = resolved_scenario_data(path)
    data["vehicle"]["mass_kg"] = -1.0
    with pytest.raises(ConfigError, match="mass_kg"):
        scenario_from_data(data, path)
    data = resolved_scenario_data(path)
    data["gains"]["pid"]["ki_d"] = [100.0, 100.0, 100.0]  # k_p k_d > k_i violated
    with pytest.raises(ConfigError, match="k_p k_d > k_i"):
        scenario_from_data(data, path)


def test_magnitude_and_direction_give_the_amplitude() -> None:
    path = SCENARIOS / "case2_impulse.toml"
    data = resolved_scenario_data(path)
    data["disturbance"]["force"] = [{"kind": "pulse", "start_s": 1.0, "end_s": 2.0,
                                     "magnitude": 10.0, "azimuth_deg": 90.0,
                                     "elevation_deg": 30.0}]
    a = scenario_from_data(data, path).force_terms[0].amplitude
    assert a == pytest.approx((0.0, 10.0 * math.cos(math.radians(30)), 5.0), abs=1e-12)
    data["disturbance"]["force"][0] = {"kind": "pulse", "start_s": 1.0, "end_s": 2.0,
                                       "magnitude": 3.0, "direction_flu": [0.0, 0.0, -2.0]}
    assert scenario_from_data(data, path).force_terms[0].amplitude == (0.0, 0.0, -3.0)
    data["disturbance"]["force"][0]["amplitude"] = [1.0, 1.0, 1.0]
    with pytest.raises(ConfigError, match="not both"):
        scenario_from_data(data, path)
    data["disturbance"]["force"][0] = {"kind": "pulse", "start_s": 1.0, "end_s": 2.0,
                                       "magnitude": 3.0, "direction_flu": [0.0, 0.0, 0.0]}
    with pytest.raises(ConfigError, match="non-zero"):
        scenario_from_data(data, path)


def test_actuator_faults_are_parsed_and_checked() -> None:
    path = SCENARIOS / "case2_impulse.toml"
    data = resolved_scenario_data(path)
    data["actuator_fault"] = [{"kind": "rotor_off", "index": 2, "start_s": 1.5}]
    assert scenario_from_data(data, path).actuator_faults == (
        ActuatorFault("rotor_off", 2, 1.5),)
    for bad, match in (({"kind": "rotor_gone", "index": 0}, "kind"),
                       ({"kind": "rotor_off", "index": 6}, "index"),
                       ({"kind": "rotor_off", "index": 0, "start_s": 2.0, "end_s": 1.0},
                        "end_s"),
                       ({"kind": "rotor_off", "index": 0, "when": 1.0}, "unknown")):
        data["actuator_fault"] = [bad]
        with pytest.raises(ConfigError, match=match):
            scenario_from_data(data, path)


# ------------------------------------------------------------------ actuator faults


def _plant() -> tuple[Plant, object]:
    sc = load_scenario(SCENARIOS / "case2_impulse.toml")
    plant = Plant(sc.vehicle, dt_us=1000)
    return plant, initial_state(sc, plant)


@pytest.mark.parametrize("kind", ["rotor_off", "rotor_stuck", "tilt_stuck", "tilt_off"])
def test_faults_change_only_their_actuator_from_their_start(kind: str) -> None:
    plant, s = _plant()
    faults = ActuatorFaults((ActuatorFault(kind, 3, 0.010, 0.020),), flight_start_us=5000)
    cmd = ActuatorCommand(tuple(900.0 + i for i in range(6)), tuple(0.1 * i for i in range(6)))
    seen = []
    for _ in range(40):
        applied = faults.apply(cmd, s)
        seen.append((s.time_us, applied))
        s = plant.step(s, applied)
    for t_us, applied in seen:
        in_window = 15000 <= t_us < 25000
        for i in range(6):
            same = (applied.rotor_speed_rad_s[i] == cmd.rotor_speed_rad_s[i]
                    and applied.tilt_rad[i] == cmd.tilt_rad[i])
            assert same or (in_window and i == 3), (t_us, i)
        if not in_window:
            assert applied == cmd
    window = [a for t, a in seen if 15000 <= t < 25000]
    onset = next(st for st in _states(plant, cmd, faults) if st.time_us == 15000)
    if kind == "rotor_off":
        assert all(a.rotor_speed_rad_s[3] == 0.0 for a in window)
    elif kind == "rotor_stuck":
        assert {a.rotor_speed_rad_s[3] for a in window} == {onset.rotor_speed_rad_s[3]}
        assert onset.rotor_speed_rad_s[3] != cmd.rotor_speed_rad_s[3]
    else:
        assert {a.tilt_rad[3] for a in window} == {onset.tilt_rad[3]}
        assert onset.tilt_rad[3] != cmd.tilt_rad[3]


def _states(plant: Plant, cmd: ActuatorCommand, faults: ActuatorFaults):
    _, s = _plant()
    replay = ActuatorFaults(faults.faults, faults.start_us)
    for _ in range(40):
        yield s
        s = plant.step(s, replay.apply(cmd, s))


def test_a_rotor_switched_off_spins_down_with_its_lag() -> None:
    plant, s = _plant()
    faults = ActuatorFaults((ActuatorFault("rotor_off", 0, 0.0),))
    cmd = ActuatorCommand(s.rotor_speed_rad_s, s.tilt_rad)
    w0 = s.rotor_speed_rad_s[0]
    for _ in range(25):  # 25 ms = tau_down
        s = plant.step(s, faults.apply(cmd, s))
    assert s.rotor_speed_rad_s[0] == pytest.approx(w0 * math.exp(-1.0), rel=1e-9)
    assert s.rotor_speed_rad_s[1] == pytest.approx(w0, rel=1e-12)


# ------------------------------------------------------------------ keys


def test_key_paths_and_setting() -> None:
    assert key_path("disturbance.force[0].amplitude") == ["disturbance", "force", 0,
                                                          "amplitude"]
    data: dict = {"a": {"b": 1}, "l": [{"x": 1}]}
    set_key(data, "a.b", 2)
    set_key(data, "a.c.d", 3)
    set_key(data, "l[0].x", 4)
    set_key(data, "l[1].x", 5)  # one past the end appends a table
    assert data == {"a": {"b": 2, "c": {"d": 3}}, "l": [{"x": 4}, {"x": 5}]}
    for bad in ("", "a..b", "a[x]", "1a", "a.b[0]"):
        with pytest.raises(CampaignError):
            set_key(data, bad, 0)
    with pytest.raises(CampaignError, match="no element"):
        set_key(data, "l[5].x", 0)


# ------------------------------------------------------------------ campaign files


def test_example_campaigns_load_and_expand(tmp_path: Path) -> None:
    files = sorted(CAMPAIGNS.glob("*.toml"))
    assert files
    for f in files:
        c = load_campaign(f)
        specs = expand(c, tmp_path)
        assert len({s.run_id for s in specs}) == len(specs) > 1, f


def test_grid_product_zipped_axes_linspace_and_draws(tmp_path: Path) -> None:
    c = load_campaign(write(tmp_path, """
[set]
duration_s = 2.0
[[axis]]
key = "controller"
values = ["pid", "pd"]
[[axis]]
keys = ["vehicle.rotor_tau_up_s", "vehicle.rotor_tau_down_s"]
values = [[0.01, 0.02], [0.02, 0.04]]
[[axis]]
key = "seed"
start = 1
stop = 3
num = 3
[monte_carlo]
draws = 2
seed = 7
[[monte_carlo.draw]]
key = "vehicle.mass_kg"
distribution = "normal"
mean = 4.27
sigma = 0.1
"""))
    specs = expand(c, tmp_path)
    assert len(specs) == 2 * 2 * 3 * 2
    assert c.columns == ("controller", "vehicle.rotor_tau_up_s", "vehicle.rotor_tau_down_s",
                         "seed", "draw", "vehicle.mass_kg")
    s = specs[5]
    sc = scenario_from_data(s.data, c.base)
    assert sc.duration_s == 2.0 and sc.controller == s.params["controller"]
    assert sc.vehicle.rotor_tau_down_s == s.params["vehicle.rotor_tau_down_s"]
    assert sc.vehicle.mass_kg == s.params["vehicle.mass_kg"]
    assert isinstance(sc.seed, int)
    # The same draws at every grid point; the expansion is deterministic.
    masses = {(x.params["draw"], x.params["vehicle.mass_kg"]) for x in specs}
    assert len(masses) == 2
    assert [x.run_id for x in expand(load_campaign(c.source), tmp_path)] == \
        [x.run_id for x in specs]


def test_run_ids_hash_the_full_configuration(tmp_path: Path) -> None:
    data = resolved_scenario_data(SCENARIOS / "case2_impulse.toml")
    a = run_id(data, "in-process")
    assert run_id(dict(reversed(list(data.items()))), "in-process") == a  # key order
    assert run_id(data, "udp") != a
    data["vehicle"]["mass_kg"] += 1e-12
    assert run_id(data, "in-process") != a


@pytest.mark.parametrize("text, match", [
    ("[[axis]]\nkey = \"vehicle.mass_kg\"\nvalues = [-1.0]\n", "run 0.*mass_kg"),
    ("[[axis]]\nkey = \"controller\"\nvalues = [\"pid\", \"lqr\"]\n", "run 1.*controller"),
    ("[[axis]]\nkey = \"seed\"\nvalues = [1, 1]\n", "same run"),
    ("[[axis]]\nkey = \"seed\"\nvalues = []\n", "non-empty"),
    ("[[axis]]\nkey = \"seed\"\nvalues = [1]\n[[axis]]\nkey = \"seed\"\nvalues = [2]\n",
     "two axes"),
    ("[[axis]]\nkeys = [\"seed\", \"duration_s\"]\nvalues = [[1]]\n", "list of 2"),
    ("[[axis]]\nkey = \"seed\"\nstart = 0\nstop = 1\nnum = 0\n", "num"),
    ("[monte_carlo]\ndraws = 3\n", "at least one"),
    ("[monte_carlo]\ndraws = 3\n[[monte_carlo.draw]]\nkey = \"seed\"\n"
     "distribution = \"poisson\"\n", "distribution"),
    ("[monte_carlo]\ndraws = 3\n[[monte_carlo.draw]]\nkey = \"vehicle.mass_kg\"\n"
     "distribution = \"uniform\"\nlow = 2.0\nhigh = 1.0\n", "low <= high"),
    ("transport = \"carrier-pigeon\"\n", "transport"),
    ("[keep]\nrun_folders = \"some\"\n", "run_folders"),
    ("colour = 1\n", "unknown key 'colour'"),
    ("[[axis]]\nkey = \"a[x]\"\nvalues = [1]\n", "name or name"),
])
def test_bad_campaigns_are_refused_with_the_reason(tmp_path: Path, text: str,
                                                   match: str) -> None:
    with pytest.raises(CampaignError, match=match):
        expand(load_campaign(write(tmp_path, text)), tmp_path)


def test_the_first_failing_section_is_the_reason(tmp_path: Path) -> None:
    """Given a file wrong in several sections, then the reason names the first in the order
    of checking: transport, [set], [[axis]], [monte_carlo], [keep]; within a section, its
    first (an axis's keys before its values, draws before seed)."""
    bad = {"transport": 'transport = "x"\n',
           "set": "set = 1\n",
           "axis": '[[axis]]\nkey = "a..b"\nvalues = []\n',
           "monte_carlo": "[monte_carlo]\ndraws = 0\nseed = -1\n",
           "keep": '[keep]\nrun_folders = "some"\n'}
    reasons = ["key 'transport'", "key 'set'", "'a..b'", "key 'draws'", "key 'keep.run_folders'"]
    sections = list(bad)
    for i, reason in enumerate(reasons):
        text = "".join(bad[k] for k in sections[i:])  # top-level keys before the tables
        with pytest.raises(CampaignError, match=reason):
            load_campaign(write(tmp_path, text, f"c{i}.toml"))


def test_unreadable_campaign_files(tmp_path: Path) -> None:
    with pytest.raises(CampaignError, match="not found"):
        load_campaign(tmp_path / "nope.toml")
    (tmp_path / "bad.toml").write_text("name = [")
    with pytest.raises(CampaignError, match="TOML"):
        load_campaign(tmp_path / "bad.toml")
    (tmp_path / "nobase.toml").write_text('name = "x"\nbase = "missing.toml"\n')
    with pytest.raises(CampaignError, match="base"):
        load_campaign(tmp_path / "nobase.toml")


# ------------------------------------------------------------------ journal and table


def test_journal_survives_a_cut_line_and_records_once(tmp_path: Path) -> None:
    j = Journal(tmp_path)
    j.add({"run_id": "a", "status": "completed", "x": math.nan})
    j.add({"run_id": "b", "status": "diverged"})
    j.close()
    with (tmp_path / "runs.jsonl").open("a") as fh:
        fh.write('{"run_id": "c", "sta')  # killed mid-line
    rows = read_journal(tmp_path)
    assert set(rows) == {"a", "b"} and rows["a"]["x"] is None
    j = Journal(tmp_path)  # the cut line does not swallow the next one
    j.add({"run_id": "c", "status": "completed"})
    j.add({"run_id": "a", "status": "crashed"})  # a second result for a: the first stands
    j.close()
    rows = read_journal(tmp_path)
    assert set(rows) == {"a", "b", "c"} and rows["a"]["status"] == "completed"


def test_table_has_a_row_per_run_in_run_order(tmp_path: Path) -> None:
    c = load_campaign(write(tmp_path, "[[axis]]\nkey = \"seed\"\nvalues = [3, 1, 2]\n"))
    specs = expand(c, tmp_path)
    rows = {s.run_id: {"run_id": s.run_id, "index": s.index, **s.params,
                       "status": "completed",
                       **flatten({"position_error_m": {"max": 0.1 * s.index},
                                  "events": [{"t_s": 0.0}]})}
            for s in specs if s.index != 1}
    write_table(tmp_path, c, specs, rows)
    with (tmp_path / "results.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert [r["seed"] for r in table] == ["3", "2"]
    assert table[1]["position_error_m.max"] == repr(0.2)
    assert table[0]["events"] == '[{"t_s":0.0}]'


# ------------------------------------------------------------------ the summary


def test_envelope_is_the_largest_magnitude_with_all_smaller_survived() -> None:
    rows = []
    for ctrl, fails_at in (("pid", {0.0: 40.0, 90.0: 30.0}), ("pd", {0.0: 20.0, 90.0: 99.0})):
        for az in (0.0, 90.0):
            for m in (10.0, 20.0, 30.0, 40.0, 50.0):
                ok = m < fails_at[az]
                if ctrl == "pd" and az == 90.0 and m == 20.0:
                    ok = False  # a failure below survived magnitudes cuts the envelope
                rows.append({"controller": ctrl, "f.magnitude": m, "f.azimuth_deg": az,
                             "status": "completed" if ok else "diverged",
                             "position_error_m.max": m / 100})
    env = envelope(rows, "f.magnitude", ["f.azimuth_deg"], "controller")
    assert env == {"pid": {(0.0,): 30.0, (90.0,): 20.0},
                   "pd": {(0.0,): 10.0, (90.0,): 10.0}}
    by_ctrl = {g["value"]: g for g in per_value(rows, "controller")}
    assert by_ctrl["pid"]["runs"] == 10 and by_ctrl["pid"]["success"] == 0.5
    assert by_ctrl["pd"]["pos_max"] == 0.5
