"""Typed TOML configuration: shipped files load, broken files are refused with a clear error."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pytest

from common.config.scenario import (
    ConfigError,
    Gains,
    check_stability,
    load_gains,
    load_scenario,
    load_vehicle,
)

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config"
VEHICLES = sorted((CONFIG / "vehicles").glob("*.toml"))
GAINS = sorted((CONFIG / "gains").glob("*.toml"))
SCENARIOS = sorted((CONFIG / "scenarios").glob("*.toml"))


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """A writable copy of config/ (scenarios refer to vehicles and gains by relative path)."""
    dst = tmp_path / "config"
    shutil.copytree(CONFIG, dst)
    return dst


def edit(path: Path, old: str, new: str) -> Path:
    text = path.read_text()
    assert old in text, f"{old!r} not in {path}"
    path.write_text(text.replace(old, new, 1))
    return path


def refused(loader, path: Path, *needles: str) -> str:
    with pytest.raises(ConfigError) as info:
        loader(path)
    msg = str(info.value)
    for needle in needles:
        assert needle in msg, msg
    return msg


# ----------------------------------------------------------------------------------------
# Shipped files
# ----------------------------------------------------------------------------------------


def test_shipped_file_lists_are_complete():
    """Given config/, when listed, then every preset directory holds files."""
    assert len(VEHICLES) == 3 and len(GAINS) == 2 and len(SCENARIOS) == 8


@pytest.mark.parametrize("path", VEHICLES, ids=lambda p: p.name)
def test_shipped_vehicles_load(path):
    """Given a shipped vehicle, when loaded, then it is a consistent hexarotor."""
    v = load_vehicle(path)
    assert v.n_rotors == 6 and len(v.arm_elevation_rad) == 6 and len(v.spin) == 6
    assert v.name == path.stem
    assert v.arm_azimuth_rad[0] == pytest.approx(math.radians(30.0))
    assert v.mass_kg == 4.27


@pytest.mark.parametrize("path", GAINS, ids=lambda p: p.name)
def test_shipped_gains_load(path):
    """Given a shipped gains file, when loaded, then it passes the stability check."""
    g = load_gains(path)
    check_stability(g)
    assert g.is_pd == (path.stem == "pd_eq33")


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.name)
def test_shipped_scenarios_load(path):
    """Given a shipped scenario, when loaded, then its files resolve and rates divide."""
    sc = load_scenario(path)
    assert sc.name == path.stem
    assert sc.physics_rate_hz % sc.control_rate_hz == 0
    assert sc.gains_pd.is_pd and not sc.gains_pid.is_pd
    assert all(Path(f).is_file() for f in sc.files.values())


def test_scenario_defaults_follow_start():
    """Given the shipped scenarios, when loaded, then ground follows the start kind."""
    assert load_scenario(CONFIG / "scenarios/case1_figure8.toml").ground_enabled
    impulse = load_scenario(CONFIG / "scenarios/case2_impulse.toml")
    assert not impulse.ground_enabled and impulse.start == "hover"
    assert len(impulse.force_terms) == 1 and impulse.force_terms[0].end_s == 22.0


# ----------------------------------------------------------------------------------------
# Gains
# ----------------------------------------------------------------------------------------


def test_gains_violating_routh_hurwitz_refused(tree):
    """Given k_i > k_p k_d, when the gains load, then the error names ki_r and the file."""
    path = edit(tree / "gains/pid_eq30.toml", "ki_r = [0.1, 0.1, 0.1]", "ki_r = [0.1, 0.1, 60.0]")
    refused(load_gains, path, "ki_r", "k_p k_d > k_i", str(path))


def test_gains_at_routh_hurwitz_boundary_refused(tree):
    """Given k_i = k_p k_d exactly, when the gains load, then they are refused (strict)."""
    path = edit(tree / "gains/pid_eq30.toml", "ki_d = [0.1, 0.1, 0.1]", "ki_d = [0.1, 50.0, 0.1]")
    refused(load_gains, path, "ki_d")


@pytest.mark.parametrize(("old", "new", "needle"), [
    ("kp_r = [5.0, 5.0, 5.0]", "kp_r = [5.0, 0.0, 5.0]", "kp_r"),
    ("kp_d = [5.0, 5.0, 5.0]", "kp_d = [5.0, 5.0, -1.0]", "kp_d"),
    ("kd_r = [10.0, 10.0, 10.0]", "kd_r = [0.0, 10.0, 10.0]", "kd_r"),
    ("ki_d = [0.1, 0.1, 0.1]", "ki_d = [0.1, -0.1, 0.1]", "ki_d"),
])
def test_gains_with_nonpositive_terms_refused(tree, old, new, needle):
    """Given k_p <= 0 (or k_d <= 0, k_i < 0), when loaded, then the error names that gain."""
    path = edit(tree / "gains/pid_eq30.toml", old, new)
    refused(load_gains, path, needle)


def test_check_stability_names_axis():
    """Given gains bad on one axis, when checked, then the message names gain and axis."""
    gains = Gains(kp_r=(1.0, 1.0, 1.0), kp_d=(1.0, 1.0, 1.0), ki_r=(0.0, 0.0, 0.0),
                  ki_d=(0.0, 0.0, 2.0), kd_r=(1.0, 1.0, 1.0), kd_d=(1.0, 1.0, 1.0))
    with pytest.raises(ConfigError, match=r"ki_d\[z\]"):
        check_stability(gains)


def test_gains_unknown_key_refused(tree):
    """Given a typo key, when the gains load, then the error names the key and the file."""
    path = tree / "gains/pd_eq33.toml"
    path.write_text(path.read_text() + "kp_x = [1.0, 1.0, 1.0]\n")
    refused(load_gains, path, "unknown key 'kp_x'", str(path))


def test_gains_missing_key_refused(tree):
    """Given a required gain removed, when the gains load, then the error names it."""
    path = edit(tree / "gains/pd_eq33.toml", "kd_d = [5.0, 5.0, 5.0]", "")
    refused(load_gains, path, "missing key 'kd_d'", str(path))


@pytest.mark.parametrize(("old", "new", "needle"), [
    ("kp_r = [5.0, 5.0, 5.0]", 'kp_r = "5.0"', "kp_r"),
    ("kp_r = [5.0, 5.0, 5.0]", 'kp_r = [5.0, "5.0", 5.0]', "kp_r"),
    ("kp_r = [5.0, 5.0, 5.0]", "kp_r = [5.0, 5.0]", "kp_r"),
    ("kp_r = [5.0, 5.0, 5.0]", "kp_r = [true, 5.0, 5.0]", "kp_r"),
    ('damping = "log_rate"', "damping = 1", "damping"),
    ('damping = "log_rate"', 'damping = "fast"', "damping"),
])
def test_gains_wrong_type_refused(tree, old, new, needle):
    """Given a value of the wrong type or shape, when loaded, then the error names the key."""
    path = edit(tree / "gains/pid_eq30.toml", old, new)
    refused(load_gains, path, needle, str(path))


# ----------------------------------------------------------------------------------------
# Vehicle
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("old", "new", "needles"), [
    ("mass_kg = 4.27", 'mass_kg = "4.27"', ("mass_kg", "a number")),
    ("mass_kg = 4.27", "mass_kg = 0.0", ("mass_kg",)),
    ("n_rotors = 6", "n_rotors = 6.0", ("n_rotors", "an integer")),
    ("spin = [1, -1, 1, -1, 1, -1]", "spin = [1, -1, 1, -1, 1, 0]", ("spin",)),
    ("spin = [1, -1, 1, -1, 1, -1]", "spin = [1, -1, 1, -1, 1]", ("spin",)),
    ("rotor_tau_up_s = 0.0125", "rotor_tau_up_s = -0.0125", ("rotor_tau_up_s",)),
    ("rotor_tau_up_s = 0.0125", "rotor_tau_up_s = 0.0125\nrotor_tau_s = 0.01",
     ("unknown key 'rotor_tau_s'",)),
    ("thrust_coeff = 7.1e-6", "", ("missing key 'thrust_coeff'",)),
    ("inertia_diag_kg_m2 = [0.086, 0.088, 0.16]", "inertia_diag_kg_m2 = [0.086, 0.088]",
     ("inertia_diag_kg_m2",)),
])
def test_vehicle_broken_refused(tree, old, new, needles):
    """Given a broken vehicle file, when loaded, then the error names the key and file."""
    path = edit(tree / "vehicles/hexa_tilted.toml", old, new)
    refused(load_vehicle, path, *needles, str(path))


@pytest.mark.parametrize("n", [4, 8, 1, 16, 0, -6, 7])
def test_vehicle_other_than_hexarotor_refused(tree, n):
    """Given a vehicle file consistent for n != 6 rotors, when loaded, then it is refused:
    the logs and the simulator link carry six rotors and six tilts."""
    path = tree / "vehicles/hexa_tilted.toml"
    lines = []
    for line in path.read_text().splitlines():
        key = line.split("=")[0].strip()
        if key == "n_rotors":
            line = f"n_rotors = {n}"
        elif key == "arm_azimuth_deg":
            continue  # the default spacing of n arms
        elif key == "arm_elevation_rad":
            line = f"arm_elevation_rad = {[0.6154 * (-1) ** i for i in range(max(n, 0))]}"
        elif key == "spin":
            line = f"spin = {[(-1) ** i for i in range(max(n, 0))]}"
        lines.append(line)
    path.write_text("\n".join(lines) + "\n")
    msg = refused(load_vehicle, path, "key 'n_rotors'", "expected 6", f"got {n}", "hexarotor",
                  str(path))
    assert "six rotor speeds and six tilts" in msg


def test_vehicle_hexarotor_with_default_azimuths_loads(tree):
    """Given n_rotors = 6 without arm_azimuth_deg, when loaded, then gamma_i = pi/3 i - pi/6."""
    path = edit(tree / "vehicles/hexa_tilted.toml",
                "arm_azimuth_deg = [30.0, 90.0, 150.0, 210.0, 270.0, 330.0]", "")
    v = load_vehicle(path)
    assert v.n_rotors == 6
    assert v.arm_azimuth_rad == pytest.approx(
        [math.pi / 3 * i - math.pi / 6 for i in range(1, 7)], abs=1e-15)


def test_unreadable_files_refused(tmp_path):
    """Given a missing or non-TOML file, when loaded, then ConfigError names the file."""
    missing = tmp_path / "nope.toml"
    refused(load_vehicle, missing, str(missing), "not found")
    bad = tmp_path / "bad.toml"
    bad.write_text("kp_r = [1.0, \n")
    refused(load_gains, bad, str(bad), "not valid TOML")


# ----------------------------------------------------------------------------------------
# Scenario
# ----------------------------------------------------------------------------------------


def test_physics_rate_not_multiple_of_control_rate_refused(tree):
    """Given physics_hz not a multiple of control_hz, when loaded, then it is refused."""
    path = edit(tree / "scenarios/case1_figure8.toml", "physics_hz = 1000", "physics_hz = 750")
    refused(load_scenario, path, "rates.physics_hz", "multiple", str(path))


@pytest.mark.parametrize(("old", "new", "needles"), [
    ("[rates]", "[rates]\ncontrol_rate = 100", ("unknown key 'rates.control_rate'",)),
    ('name = "case1_figure8"', 'name = "case1_figure8"\nduraton_s = 3.0',
     ("unknown key 'duraton_s'",)),
    ("duration_s = 160.0", 'duration_s = "160"', ("duration_s", "a number")),
    ("duration_s = 160.0", "", ("missing key 'duration_s'",)),
    ('controller = "pid"', 'controller = "lqr"', ("controller",)),
    ('start = "ground"', 'start = "air"', ("initial.start",)),
    ("control_hz = 500", 'control_hz = "500"', ("rates.control_hz", "an integer")),
    ("figure_start_s = 20.0", "figure_start_s = 150.0", ("figure_end_s",)),
    ('vehicle = "../vehicles/hexa_tilted.toml"', 'vehicle = "../vehicles/none.toml"',
     ("none.toml", "not found")),
])
def test_scenario_broken_refused(tree, old, new, needles):
    """Given a broken scenario, when loaded, then the error says what and where."""
    path = edit(tree / "scenarios/case1_figure8.toml", old, new)
    msg = refused(load_scenario, path, *needles)
    assert "case1_figure8.toml" in msg or "none.toml" in msg


def test_scenario_sensors_and_params(tree):
    """Given a scenario naming a sensor profile and FCU parameters, then both load; a
    profile that does not exist, a non-numeric parameter or an over-long name is refused."""
    path = tree / "scenarios/case1_figure8.toml"
    original = path.read_text()
    path.write_text(original.replace("seed = 0", 'seed = 4\nsensors = "degraded"') +
                    "\n[params]\nCA_LAG_COMP = 0\nEKF_EV_GATE = 3.5\n")
    sc = load_scenario(path)
    assert sc.seed == 4 and sc.uses_sensors and sc.sensors is not None
    assert sc.sensors.name == "degraded"
    assert sc.params == {"CA_LAG_COMP": 0.0, "EKF_EV_GATE": 3.5}
    path.write_text(original.replace("seed = 0", 'seed = 0\nsensors = "nosuch"'))
    refused(load_scenario, path, "nosuch", "mocap-indoor")
    path.write_text(original + '\n[params]\nCA_LAG_COMP = "on"\n')
    refused(load_scenario, path, "params.CA_LAG_COMP", "a number")
    path.write_text(original + "\n[params]\nA_NAME_BEYOND_SIXTEEN = 1\n")
    refused(load_scenario, path, "16 characters")
    path.write_text(original)
    assert not load_scenario(path).uses_sensors and load_scenario(path).params == {}


def test_scenario_disturbance_errors_refused(tree):
    """Given a pulse without end or an unknown term key, when loaded, then it is refused."""
    path = tree / "scenarios/case2_impulse.toml"
    original = path.read_text()
    edit(path, "end_s = 22.0", "")
    refused(load_scenario, path, "disturbance.force[0].end_s", "finite")
    path.write_text(original)
    edit(path, "end_s = 22.0", "end_s = 22.0\nomega_rad_s = 1.0")
    refused(load_scenario, path, "unknown key 'disturbance.force[0].omega_rad_s'")


def test_scenario_refuses_pd_file_with_integral_gain(tree):
    """Given a PD baseline file with k_i, when the scenario loads, then it is refused."""
    pd = edit(tree / "gains/pd_eq33.toml", "kp_r", "ki_r = [0.1, 0.1, 0.1]\nkp_r")
    refused(load_scenario, tree / "scenarios/case1_figure8.toml", str(pd.resolve()), "PD")


def test_scenario_reports_broken_referenced_file(tree):
    """Given a scenario whose gains file is unstable, when loaded, then that file is named."""
    pid = edit(tree / "gains/pid_eq30.toml", "ki_r = [0.1, 0.1, 0.1]", "ki_r = [99.0, 0.1, 0.1]")
    refused(load_scenario, tree / "scenarios/case2_sine.toml", "ki_r", str(pid.resolve()))
