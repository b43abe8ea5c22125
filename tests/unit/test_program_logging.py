"""`-q`/`--quiet` and `-v`/`--verbose` of `fcu`, `sitl` and `gcs` (common/process/diagnostics.py):
program output on stdout stays as it is, `-q` drops the informational diagnostics on stderr,
`-v` adds the debug lines; warnings and errors are written whatever the level."""

from __future__ import annotations

import gc
import logging
from pathlib import Path

import pytest

from common.process.diagnostics import get_logger, setup_logging
from common.process.realtime import schedule_loop
from fcu.edge.node_args import build_parser as fcu_parser
from gcs.cli.parser import build_parser as gcs_parser
from sitl.node import build_parser as sitl_parser
from tests.unit.scripted_autopilot import ScriptedAutopilot, gcs

pytestmark = pytest.mark.timeout(120)
ROOT = Path(__file__).resolve().parents[2]
FCU_ARGS = ["--vehicle", "v.toml", "--gains", "g.toml"]
NOT_ASKED = "fcu: loop at normal priority: real-time priority not asked (--rt-priority 0)\n"


@pytest.fixture(autouse=True)
def _default_level():
    yield
    setup_logging("test", fcu_parser().parse_args(FCU_ARGS))  # the next test starts at info


def _said(capsys, flags: list[str]) -> tuple[str, str]:
    """(stdout, stderr) of an fcu module's info diagnostic and of the loop's scheduling
    status line (program output), fcu's level set from FLAGS."""
    setup_logging("fcu", fcu_parser().parse_args([*flags, *FCU_ARGS]))
    capsys.readouterr()
    get_logger("fcu.edge.node").info("fcu: an info line")
    schedule_loop("fcu", 0)
    gc.unfreeze()
    out = capsys.readouterr()
    return out.out, out.err


def test_quiet_drops_the_info_line_not_the_output(capsys):
    """Given fcu's parser, an info diagnostic is on stderr by default and with -v, not with
    -q or --quiet; the scheduling status line on stdout is the same in all four."""
    assert _said(capsys, []) == (NOT_ASKED, "fcu: an info line\n")
    assert _said(capsys, ["-v"]) == (NOT_ASKED, "fcu: an info line\n")
    assert _said(capsys, ["-q"]) == (NOT_ASKED, "")
    assert _said(capsys, ["--quiet"]) == (NOT_ASKED, "")


def test_warnings_pass_quiet_and_debug_needs_verbose(capsys):
    """A warning is written with -q, a debug line only with -v (--verbose)."""
    log = get_logger("sitl.anything")
    for flags, debug_seen in (([], False), (["-q"], False), (["--verbose"], True)):
        setup_logging("sitl", sitl_parser().parse_args([*flags, "s.toml"]))
        capsys.readouterr()
        log.warning("sitl: a warning")
        log.debug("sitl: a debug line")
        err = capsys.readouterr().err
        assert err == "sitl: a warning\n" + ("sitl: a debug line\n" if debug_seen else ""), flags


def test_verbose_and_quiet_exclude_each_other():
    """-v with -q is refused (exit 2), for fcu and for a gcs command alike."""
    for parser, args in ((fcu_parser(), ["-v", "-q", *FCU_ARGS]),
                         (gcs_parser(), ["run", "-v", "-q", "s.toml", "--out", "o"])):
        with pytest.raises(SystemExit) as stop:
            parser.parse_args(args)
        assert stop.value.code == 2


@pytest.mark.parametrize("args,level", [
    (["status"], logging.INFO), (["-q", "status"], logging.WARNING),
    (["status", "-q"], logging.WARNING), (["-v", "mission", "clear"], logging.DEBUG),
    (["mission", "clear", "--verbose"], logging.DEBUG), (["-q", "run", "s.toml", "--out", "o"],
                                                         logging.WARNING)])
def test_gcs_takes_the_options_before_and_after_its_command(args, level):
    """gcs -q CMD and gcs CMD -q mean the same; a subcommand does not reset the level given
    before it."""
    assert gcs_parser().parse_args(args).log_level == level


@pytest.fixture
def vehicle():
    v = ScriptedAutopilot("ardupilot", {"DISARM_DELAY": (10.0, 1), "MAV_SYSID": (1.0, 4)})
    yield v
    v.close()


def test_gcs_param_load_note_is_info_and_its_result_is_output(vehicle, capsys, tmp_path):
    """Given a .params file of system 2 loaded into system 1, the note about it is an info
    diagnostic on stderr that -q drops, -v adds the parsed arguments (debug), and the result
    line on stdout is the same in the three."""
    saved = tmp_path / "p.params"
    assert gcs(capsys, vehicle, "param", "save", str(saved))[0] == 0
    saved.write_text("".join("2" + line[1:] if line[:2] == "1\t" else line
                             for line in saved.read_text().splitlines(keepends=True)))
    note = "note: the file holds parameters of another vehicle; loading into system 1\n"
    result = f"loaded 2 of 2 parameters from {saved}\n"
    code, out, err = gcs(capsys, vehicle, "param", "load", str(saved))
    assert (code, out, err) == (0, result, note)
    code, out, err = gcs(capsys, vehicle, "param", "load", "-q", str(saved))
    assert (code, out, err) == (0, result, "")
    code, out, err = gcs(capsys, vehicle, "param", "load", "-v", str(saved))
    assert (code, out) == (0, result)
    assert err.startswith("gcs: arguments action=load, ") and err.endswith(note), err
