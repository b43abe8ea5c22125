"""`-q`/`--quiet` and `-v`/`--verbose` of the real programs (common/process/diagnostics.py):
their documented output is the same at every level, and -v adds the debug lines."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(120)
ROOT = Path(__file__).resolve().parents[2]


def test_gcs_keygen_output_is_the_same_and_verbose_adds_a_debug_line(tmp_path):
    """The real `gcs keygen`: the same stdout line by default, with -q and with -v; stderr
    empty but for -v's one debug line (the parsed arguments)."""
    lines = {}
    for flag in ("", "-q", "-v"):
        key = tmp_path / f"key{flag}"
        argv = [*([flag] if flag else []), "keygen", str(key)]
        proc = subprocess.run([sys.executable, "-m", "gcs.cli", *argv], cwd=tmp_path,
                              env={**os.environ, "PYTHONPATH": str(ROOT)},
                              capture_output=True, text=True, timeout=90)
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout == f"wrote a 32-byte signing key to {key} (keep it out of " \
                              "version control)\n"
        lines[flag] = proc.stderr
    assert lines[""] == lines["-q"] == ""
    assert lines["-v"] == f"gcs: arguments command=keygen, file={tmp_path / 'key-v'}\n"


def test_sitl_error_line_is_the_same_and_verbose_adds_its_arguments(tmp_path):
    """The real `sitl` with a scenario that does not exist: exit 2 and the same one error
    line by default, with -q and with -v; -v writes the parsed arguments (debug) first."""
    missing = tmp_path / "nope.toml"
    err = {}
    for flag in ("", "-q", "-v"):
        proc = subprocess.run([sys.executable, "-m", "sitl.node",
                               *([flag] if flag else []), str(missing)], cwd=tmp_path,
                              env={**os.environ, "PYTHONPATH": str(ROOT)},
                              capture_output=True, text=True, timeout=90)
        assert (proc.returncode, proc.stdout) == (2, ""), proc.stderr
        err[flag] = proc.stderr.splitlines()
    line = f"sitl: {missing}: file not found"
    assert err[""] == err["-q"] == [line]
    assert len(err["-v"]) == 2 and err["-v"][1] == line
    assert err["-v"][0].startswith("sitl: arguments control_rate=None, ")
    assert f"scenario={missing}, " in err["-v"][0]


def test_fcu_error_line_is_the_same_and_verbose_adds_its_arguments(tmp_path):
    """The real `fcu` with a vehicle file that does not exist: exit 2 and the same one error
    line by default, with -q and with -v; -v writes the parsed arguments (debug) first."""
    missing = tmp_path / "nope.toml"
    gains = ROOT / "config" / "gains" / "pid_eq30.toml"
    err = {}
    for flag in ("", "-q", "-v"):
        proc = subprocess.run([sys.executable, "-m", "fcu.edge.node",
                               *([flag] if flag else []), "--vehicle", str(missing),
                               "--gains", str(gains)], cwd=tmp_path,
                              env={**os.environ, "PYTHONPATH": str(ROOT)},
                              capture_output=True, text=True, timeout=90)
        assert (proc.returncode, proc.stdout) == (2, ""), proc.stderr
        err[flag] = proc.stderr.splitlines()
    line = f"fcu: {missing}: file not found"
    assert err[""] == err["-q"] == [line]
    assert len(err["-v"]) == 2 and err["-v"][1] == line
    assert err["-v"][0].startswith(f"fcu: arguments gains={gains}, ")
    assert f"vehicle={missing}, " in err["-v"][0]
