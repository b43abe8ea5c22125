"""tools/fastest_python.py: the interpreter `make` builds .venv with."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tools import fastest_python as fp

ROOT = Path(__file__).resolve().parents[2]
HERE = (sys.version_info[0], sys.version_info[1])


def _probe(exe: str, seconds: float, version: tuple[int, int] = HERE,
           can_venv: bool = True) -> fp.Probe:
    return fp.Probe(exe, version, can_venv, seconds)


def test_an_interpreter_answers_with_its_real_executable_version_and_a_time() -> None:
    p = fp.probe(sys.executable)
    assert p is not None
    assert p.exe == os.path.realpath(sys.executable)
    assert p.version == HERE
    assert p.can_venv  # the suite's own venv was made by one
    assert 0.0 < p.seconds < fp.PROBE_TIMEOUT_S


def test_what_does_not_answer_the_probe_is_no_candidate(tmp_path: Path) -> None:
    liar = tmp_path / "python3"
    liar.write_text("#!/bin/sh\necho 'Python 3.11.0'\n")
    liar.chmod(0o755)
    assert fp.probe(str(liar)) is None
    assert fp.probe(str(tmp_path / "missing")) is None


def test_the_fastest_build_of_the_default_version_that_can_make_a_venv_is_picked() -> None:
    slow, fast = _probe("/a/python3", 0.03), _probe("/b/python3", 0.02)
    assert fp.pick([slow, None, fast], HERE) == fast
    newer = _probe("/c/python3.99", 0.001, version=(3, 99))
    assert fp.pick([slow, newer], HERE) == slow  # another version: other packages, figures
    no_venv = _probe("/d/python3", 0.001, can_venv=False)
    assert fp.pick([slow, no_venv], HERE) == slow
    old = _probe("/e/python3.10", 0.001, version=(3, 10))
    assert fp.pick([old], (3, 10)) is None  # below the project's 3.11
    assert fp.pick([None], HERE) is None


def test_the_version_is_python3s_unless_it_is_too_old() -> None:
    old, mid, new = (_probe("/usr/bin/python3", 0.01, version=(3, 10)),
                     _probe("/usr/bin/python3.12", 0.03, version=(3, 12)),
                     _probe("/usr/bin/python3.13", 0.02, version=(3, 13)))
    assert fp.wanted_version(mid, [old, mid, new]) == (3, 12)
    assert fp.wanted_version(old, [old, new, mid]) == (3, 12)  # the oldest that will do
    assert fp.wanted_version(None, [new, None]) == (3, 13)  # python3 did not answer
    assert fp.wanted_version(old, [old]) is None


def test_one_interpreter_under_two_names_is_measured_once(tmp_path: Path) -> None:
    alias = tmp_path / "python3"
    alias.symlink_to(os.path.realpath(sys.executable))
    probes = fp.measured([sys.executable, str(alias)], rounds=2)
    assert list(probes) == [sys.executable]
    assert probes[sys.executable] is not None


@pytest.mark.skipif(shutil.which("make") is None or shutil.which("python3") is None,
                    reason="needs make and a python3 on PATH")
def test_make_builds_the_venv_with_the_picked_interpreter() -> None:
    """`make -n` shows the recipe with PYTHON expanded: the tool's pick, an interpreter of
    python3's own version (not the literal `python3` unless nothing else answered)."""
    shown = subprocess.run(["make", "-n", "-B", "-C", str(ROOT), ".venv/.installed"],
                           capture_output=True, text=True, timeout=120, check=True,
                           env={k: v for k, v in os.environ.items() if k != "PYTHON"}).stdout
    line = next(ln for ln in shown.splitlines() if "-m venv" in ln)
    exe = line.split('py="', 1)[1].split('"', 1)[0]
    assert os.path.isabs(exe), line  # the tool's pick, a real executable's path
    version = subprocess.run([exe, "-c", "import sys; print(sys.version_info[:2])"],
                             capture_output=True, text=True, timeout=60, check=True).stdout
    default = subprocess.run(["python3", "-c", "import sys; print(sys.version_info[:2])"],
                             capture_output=True, text=True, timeout=60, check=True).stdout
    assert version == default
