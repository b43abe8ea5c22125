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


GAINS = ROOT / "config" / "gains" / "pid_eq30.toml"
# (program, its module, its arguments with a file that does not exist (MISSING), the start of
# -v's arguments line, a field of it naming that file)
PROGRAMS = [
    ("sitl", "sitl.node", ["MISSING"], "arguments control_rate=None, ", "scenario"),
    ("fcu", "fcu.edge.node", ["--vehicle", "MISSING", "--gains", str(GAINS)],
     f"arguments gains={GAINS}, ", "vehicle"),
]


@pytest.mark.parametrize(("program", "module", "argv", "first", "field"), PROGRAMS,
                         ids=[p[0] for p in PROGRAMS])
def test_error_line_is_the_same_and_verbose_adds_its_arguments(tmp_path, program, module,
                                                               argv, first, field):
    """The real `sitl` and `fcu` given a file that does not exist: exit 2 and the same one
    error line by default, with -q and with -v; -v writes the parsed arguments (debug)
    first."""
    missing = tmp_path / "nope.toml"
    args = [str(missing) if a == "MISSING" else a for a in argv]
    err = {}
    for flag in ("", "-q", "-v"):
        proc = subprocess.run([sys.executable, "-m", module, *([flag] if flag else []),
                               *args], cwd=tmp_path,
                              env={**os.environ, "PYTHONPATH": str(ROOT)},
                              capture_output=True, text=True, timeout=90)
        assert (proc.returncode, proc.stdout) == (2, ""), proc.stderr
        err[flag] = proc.stderr.splitlines()
    line = f"{program}: {missing}: file not found"
    assert err[""] == err["-q"] == [line]
    assert len(err["-v"]) == 2 and err["-v"][1] == line
    assert err["-v"][0].startswith(f"{program}: {first}")
    assert f"{field}={missing}, " in err["-v"][0]
