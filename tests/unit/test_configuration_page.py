"""docs/configuration.md is what `tools.config_doc` generates from the loaders' key
declarations, and every key the loaders read is declared (so on the page): loading every
shipped file and files that use every optional key records what `Table` reads."""

from __future__ import annotations

import math
import re
import shutil
import tomllib
from pathlib import Path
from typing import Any

import pytest

from common.config import reader
from common.config.keys import REQUIRED, KeyTable
from common.config.scenario import load_scenario
from common.config.sensors import load_sensor_profile
from common.wire.mission_items import MissionItem
from gcs.campaign import load as campaign_load
from gcs.campaign.load import load_campaign
from gcs.campaign.model import DISTRIBUTIONS, DRAW_KEYS
from gcs.mission_files.items import MissionFileError
from gcs.mission_files.toml import MISSION_KEYS, parse_toml, parse_toml_doc
from tools import config_doc

CONFIG = Path(__file__).resolve().parents[2] / "config"


def test_the_page_is_the_generated_one():
    assert config_doc.PAGE.read_text() == config_doc.render(), (
        "docs/configuration.md is stale: run python -m tools.config_doc")


def test_check_exits_1_on_a_stale_page(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(config_doc, "PAGE", tmp_path / "configuration.md")
    assert config_doc.main(["--check"]) == 1
    assert config_doc.main([]) == 0
    assert config_doc.main(["--check"]) == 0
    (tmp_path / "configuration.md").write_text(config_doc.render().replace("`mass_kg`", "x"))
    assert config_doc.main(["--check"]) == 1
    assert "stale" in capsys.readouterr().out


def _rows(text: str) -> list[tuple[str, str]]:
    """(the table's title, the key) of every row of the page."""
    rows, title, in_keys = [], "", False
    for line in text.splitlines():
        in_keys = line.startswith("| Key |") or (in_keys and line.startswith("|"))
        if line.endswith(":") and not line.startswith("|"):
            title = line[:-1]
        elif line.startswith("## ") or line.startswith("### "):
            title = "Top level"
        m = re.match(r"^\| (`[^`]+`|\*any name\*) \|", line)
        if m and in_keys:
            rows.append((title, m.group(1).strip("`")))
    return rows


def _documented() -> dict[str, set[tuple[str, str]]]:
    """Per file kind, (table path, key) of every declaration; each also a row of the page
    under its table's title."""
    rows = _rows(config_doc.render())
    out: dict[str, set[tuple[str, str]]] = {}
    for kind, tables in config_doc.FILES.items():
        for t in tables:
            for k in t.keys:
                name = "*any name*" if k.name == "*" else k.name
                assert (config_doc.table_title(t), name) in rows, (kind, t.path, k.name)
                out.setdefault(kind, set()).update((p, k.name) for p in (t.path, *t.also))
    return out


def test_every_declared_key_is_one_row_of_the_page():
    rows = _rows(config_doc.render())
    _documented()
    assert len(rows) == sum(len(t.keys) for ts in config_doc.FILES.values() for t in ts)


# ------------------------------------------------------------------ what the loaders read

SENSORS_EXTRA = """
[gps]
velocity_noise_ned_m_s = [0.1, 0.1, 0.1]
satellites = 10
position_noise_m = 0.5
altitude_noise_m = 0.5
eph_m = 1.0
epv_m = 1.0
"""
SCENARIO = """
name = "every_key"
duration_s = 1.0
controller = "pid"
vehicle = "../vehicles/v.toml"
seed = 1
ground = false
sensors = "../sensors/s.toml"
divergence_position_m = 10.0
divergence_attitude_rad = 2.0
divergence_attitude_hold_s = 1.0
[gains]
pid = "../gains/pid.toml"
pd = "../gains/pd_eq33.toml"
[rates]
control_hz = 500
physics_hz = 1000
[initial]
start = "hover"
position_enu_m = [0.0, 0.0, 0.0]
[trajectory]
kind = "case1_figure8"
position_enu_m = [0.0, 0.0, 1.0]
rise_height_m = 5.0
rise_end_s = 10.0
figure_start_s = 20.0
figure_end_s = 140.0
amplitude_m = 5.0
axis_enu = [1.0, 2.0, 3.0]
[actuators]
ideal = false
[params]
CA_LAG_COMP = 0
[[sensor_fault]]
kind = "gyro_bias_step"
start_s = 1.0
end_s = 2.0
amplitude = [0.01, 0.0, 0.0]
[[sensor_fault]]
kind = "mocap_off"
start_s = 1.0
end_s = 2.0
[[actuator_fault]]
kind = "rotor_off"
index = 0
start_s = 1.0
end_s = 2.0
"""
TERMS = """
[[disturbance.{0}]]
kind = "sine"
magnitude = 1.0
azimuth_deg = 10.0
elevation_deg = 5.0
start_s = 0.0
end_s = 5.0
omega_rad_s = 1.0
phase_rad = 0.5
[[disturbance.{0}]]
kind = "pulse"
magnitude = 1.0
direction_flu = [0.0, 0.0, 1.0]
end_s = 1.0
[[disturbance.{0}]]
kind = "pulse"
amplitude = [0.0, 0.0, 1.0]
end_s = 1.0
"""
MISSION_SCENARIO = """
name = "mission"
duration_s = 1.0
vehicle = "../vehicles/v.toml"
[gains]
pid = "../gains/pid.toml"
pd = "../gains/pd_eq33.toml"
[initial]
start = "ground"
[trajectory]
kind = "mission"
mission = "../missions/square_2m.toml"
"""


def _kind(source: str) -> str:
    """The file kind a Table's source belongs to (an inline table: the kind it is of)."""
    if ": table 'vehicle'" in source:
        return "vehicle"
    if ": table 'gains." in source:
        return "gains"
    folder = Path(source.split(": ")[0]).parent.name
    return {"vehicles": "vehicle", "gains": "gains", "sensors": "sensors",
            "scenarios": "scenario"}[folder]


@pytest.fixture()
def every_key_files(tmp_path: Path) -> Path:
    """A config tree whose files use every optional key the loaders take."""
    for folder in ("vehicles", "gains", "sensors", "scenarios", "missions"):
        (tmp_path / folder).mkdir()
    shutil.copy(CONFIG / "vehicles" / "hexa_tilted.toml", tmp_path / "vehicles" / "v.toml")
    shutil.copy(CONFIG / "gains" / "pid_eq30.toml", tmp_path / "gains" / "pid.toml")
    shutil.copy(CONFIG / "gains" / "pd_eq33.toml", tmp_path / "gains")
    shutil.copy(CONFIG / "missions" / "square_2m.toml", tmp_path / "missions")
    sensors = (CONFIG / "sensors" / "px4-default.toml").read_text()
    sensors = sensors.replace("rate_hz = 250.0", "rate_hz = 500.0", 1)
    (tmp_path / "sensors" / "s.toml").write_text(sensors + SENSORS_EXTRA * ("[gps]" not in
                                                                            sensors))
    terms = TERMS.format("force") + TERMS.format("torque")
    (tmp_path / "scenarios" / "every_key.toml").write_text(SCENARIO + terms)
    (tmp_path / "scenarios" / "mission.toml").write_text(MISSION_SCENARIO)
    return tmp_path


def _read_keys(monkeypatch: pytest.MonkeyPatch) -> set[tuple[str, str, str]]:
    """Record (file kind, table path, key) of every key a Table reads from now on."""
    seen: set[tuple[str, str, str]] = set()
    raw = reader.Table.raw

    def recording(self: reader.Table, key: str, default: Any = ...) -> Any:
        path = re.sub(r"\[\d+\]", "[]", self.prefix.rstrip("."))
        seen.add((_kind(self.source), path, key))
        return raw(self, key, default)

    monkeypatch.setattr(reader.Table, "raw", recording)
    return seen


def test_every_key_the_loaders_read_is_declared_and_every_declared_key_is_read(
        monkeypatch, every_key_files):
    seen = _read_keys(monkeypatch)
    for f in sorted((CONFIG / "scenarios").glob("*.toml")):
        load_scenario(f, firmware=True)
    for f in sorted((CONFIG / "sensors").glob("*.toml")):
        load_sensor_profile(f)
    load_scenario(every_key_files / "scenarios" / "every_key.toml")
    load_scenario(every_key_files / "scenarios" / "mission.toml")
    documented = _documented()
    read = {(kind, path, "*" if path == "params" else key) for kind, path, key in seen}
    declared = {(kind, path, key) for kind in documented if kind not in ("campaign", "mission")
                for path, key in documented[kind]}
    assert read - declared == set(), "read by a loader but not on the page"
    assert declared - read == set(), "on the page but read by no loader"


def _keys_in(data: Any, path: str = "") -> set[tuple[str, str]]:
    """(table path, key) of every key of a campaign file's tables ([set] is scenario keys)."""
    out: set[tuple[str, str]] = set()
    if isinstance(data, dict):
        for k, v in data.items():
            out.add((path, k))
            if k != "set" or path:
                sub = f"{path}.{k}" if path else k
                out |= _keys_in(v, sub + ("[]" if isinstance(v, list) else ""))
    elif isinstance(data, list):
        for v in data:
            out |= _keys_in(v, path)
    return out


def test_every_key_of_the_shipped_campaigns_is_on_the_page():
    documented = _documented()["campaign"]
    for f in sorted((CONFIG / "campaigns").glob("*.toml")):
        load_campaign(f)
        keys = {(p, k) for p, k in _keys_in(tomllib.loads(f.read_text()))
                if not p.startswith("axis[].values")}
        assert keys - documented == set(), f.name


def test_the_campaign_loader_takes_exactly_the_declared_keys():
    documented = _documented()["campaign"]
    assert {("", k) for k in campaign_load._TOP_KEYS} == {
        (p, k) for p, k in documented if p == ""}
    assert {("axis[]", k) for k in campaign_load._AXIS_KEYS} == {
        (p, k) for p, k in documented if p == "axis[]"}
    assert {("monte_carlo", k) for k in campaign_load._MONTE_CARLO_KEYS} == {
        (p, k) for p, k in documented if p == "monte_carlo"}
    args = {"key", "distribution"} | {a for names in DISTRIBUTIONS.values() for a in names}
    assert args == DRAW_KEYS.names()


def test_a_key_reads_as_declared_and_prints_its_declaration():
    from common.config.keys import Key, KeyTable
    from common.config.reader import ConfigError, Table

    k = Key("rate_hz", "number", "a rate", "Hz", 5.0, lo=0.0, hi=10.0, lo_open=True)
    assert k.read(Table({}, "f")) == 5.0
    assert k.read(Table({"rate_hz": 2}, "f")) == 2.0
    with pytest.raises(ConfigError, match=r"key 'rate_hz': expected a number in \(0.0, 10.0\]"):
        k.read(Table({"rate_hz": 0.0}, "f"))
    with pytest.raises(ConfigError, match="missing key 'rate_hz'"):
        k.read(Table({}, "f"), ...)
    assert (k.type_text(), k.default_text(), k.range_text()) == ("number", "5", "(0, 10]")
    choice = Key("kind", "string", "a kind", default="a", choices=("a", "b"), range_doc="x")
    assert (choice.default_text(), choice.range_text()) == ('"a"', "`a`, `b`; x")
    assert Key("v", "numbers", "", n=6).type_text() == "list of 6 numbers"
    with pytest.raises(ValueError, match="unknown type"):
        Key("x", "float", "")
    with pytest.raises(KeyError, match="no key 'y' declared"):
        KeyTable("t", (k,))["y"]


# ------------------------------------------------------------------ mission files

_SAMPLE = {"number": "1.5", "integer": "0", "vec3": "[1.0, 2.0, -3.0]",
           "numbers": "[0.0, 0.0, 0.0, 0.0]"}


def _item(table: KeyTable, drop: str = "", extra: str = "") -> str:
    lines = ['format = "dqflight-mission-1"', "[[item]]"]
    for k in table.keys:
        if k.name != drop:
            value = f'"{k.choices[0]}"' if k.type == "string" else _SAMPLE[k.type]
            lines.append(f"{k.name} = {value}")
    return "\n".join([*lines, extra])


def test_the_mission_reader_takes_the_declared_keys_and_their_defaults():
    """Every [[item]] table on the page parses with all its keys; without a required key it
    is refused naming the key, without a defaulted one it takes the page's default; a key
    the page does not list for that type is refused."""
    tables = [t for t in MISSION_KEYS if t.path == "item[]"]
    assert {t.keys[0].choices[0] for t in tables} == {
        "takeoff", "waypoint", "loiter", "land", "keyframe", "figure_eight", "raw"}
    for t in tables:
        full = parse_toml(_item(t))[0]
        for k in t.keys[1:]:
            if k.default is REQUIRED:
                with pytest.raises(MissionFileError, match=f"key '{k.name}'"):
                    parse_toml(_item(t, drop=k.name))
            else:
                item = parse_toml(_item(t, drop=k.name))[0]
                changed = {f for f in MissionItem._fields
                           if getattr(item, f) != getattr(full, f)
                           and getattr(item, f) == getattr(item, f)}  # NaN != NaN
                fields = changed | {f for f in MissionItem._fields
                                    if getattr(item, f) != getattr(item, f)}
                assert len(fields) == 1, (t.title, k.name, fields)
                got = getattr(item, fields.pop())
                assert got == k.default or (math.isnan(got) and math.isnan(k.default)), \
                    (t.title, k.name, got)
        with pytest.raises(MissionFileError, match="unknown key 'undeclared'"):
            parse_toml(_item(t, extra="undeclared = 1"))


def test_the_mission_files_home_and_top_level_are_the_declared_ones():
    home = next(t for t in MISSION_KEYS if t.path == "home")
    text = _item(next(t for t in MISSION_KEYS if t.path == "item[]"))
    with_home = text + "\n[home]\n" + "\n".join(f"{k.name} = 1.0" for k in home.keys)
    assert parse_toml_doc(with_home).home is not None
    for k in home.keys:
        with pytest.raises(MissionFileError, match=f"key '{k.name}'"):
            parse_toml_doc(with_home.replace(f"{k.name} = 1.0", ""))
    top = {k.name for t in MISSION_KEYS if t.path == "" for k in t.keys}
    assert top == {"format", "item", "home"}
    with pytest.raises(MissionFileError, match="unknown key 'items'"):
        parse_toml("items = 1\n")
