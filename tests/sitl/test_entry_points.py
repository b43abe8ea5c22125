"""The console scripts stop cleanly on Ctrl-C at any moment of their start, importing numba
and loading the kernels included: exit 0 and one line, never a KeyboardInterrupt traceback
(a README block once got exit 130 from `fcu` interrupted while importing numba)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from common.links import free_port

from ..terminal import sigint_default
from .waits import cpu_s

BIN = Path(sys.executable).parent
# CPU seconds within which a console script's process is past the interpreter's own start
# and has set its guard (`common.process.entry`: about 0.05 s on an idle machine)
INTERPRETER_START_CPU_S = 0.15
pytestmark = pytest.mark.timeout(120)


@pytest.mark.parametrize("delay_s", [0.4, 0.8, 1.5, 3.0])
@pytest.mark.parametrize("prog", ["fcu", "sitl", "gcs"])
def test_ctrl_c_while_starting_is_exit_0_without_a_traceback(prog, delay_s, tmp_path):
    port = free_port()
    argv = {"fcu": ["--vehicle", "config/vehicles/hexa_tilted.toml", "--gains",
                    "config/gains/pid_eq30.toml", "--sim", f"udpin:127.0.0.1:{port}", "--gcs",
                    f"udpout:127.0.0.1:{port + 1}"],
            "sitl": ["config/scenarios/case1_figure8.toml", "--link",
                     f"udpout:127.0.0.1:{port}"],
            "gcs": ["run", "config/scenarios/case1_figure8.toml", "--out",
                    str(tmp_path / "run")]}[prog]
    root = Path(__file__).resolve().parents[2]
    # As from a terminal: SIGINT at its default (pytest-xdist's workers ignore it, and a
    # child started with it ignored would ignore a Ctrl-C until its own handler is set).
    proc = subprocess.Popen([str(BIN / prog), *argv], cwd=root, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=sigint_default)
    try:
        # the point of the test: a Ctrl-C at this moment of the start, and past the
        # interpreter's own start (where a Ctrl-C is Python's, before the first line of the
        # console script), which a starved process reaches later than the wall clock says
        time.sleep(delay_s)
        deadline = time.monotonic() + 60.0
        while cpu_s(proc.pid) < INTERPRETER_START_CPU_S and proc.poll() is None:
            assert time.monotonic() < deadline, "the program used no CPU for 60 s"
            time.sleep(0.01)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "Traceback" not in err, err
    # fcu and sitl: 0 (as the README's "by hand" block needs); gcs: 0, or the run's own
    # verdict of a stopped flight, or 130 "interrupted"
    assert proc.returncode in ((0, 1, 130) if prog == "gcs" else (0,)), (proc.returncode, out,
                                                                        err)



_LOADS = """
import contextlib, json, sys
import common.process.startup as startup
inside, loaded = [False], {}
deferred = startup.sigint_deferred

@contextlib.contextmanager
def recording():
    inside[0] = True
    try:
        with deferred():
            yield
    finally:
        inside[0] = False

startup.sigint_deferred = recording

class Finder:
    def find_spec(self, name, path=None, target=None):
        if name in ("numpy", "numba", "pymavlink", "scipy") and name not in loaded:
            loaded[name] = inside[0]

sys.meta_path.insert(0, Finder())
from gcs.cli import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "loaded": loaded}))
"""


@pytest.mark.parametrize(("argv", "libraries"), [
    (["run", "no/such/scenario.toml", "--out", "OUT"], {"numpy", "numba", "pymavlink"}),
    (["goto", "1", "2", "-3", "--connect", "udpin:127.0.0.1:BAD"], {"numpy", "numba"}),
    (["status", "--connect", "udpin:127.0.0.1:BAD"], {"numpy", "pymavlink"}),
    (["param", "list", "--connect", "udpin:127.0.0.1:BAD"], {"numpy", "pymavlink"}),
])
def test_gcs_loads_its_libraries_with_ctrl_c_deferred(argv, libraries, tmp_path):
    """`gcs` loads pymavlink, numpy and (for the commands that need it) numba after parsing
    its command line: each of them first loads inside `sigint_deferred`, so a Ctrl-C then is
    raised after the import, not inside it (a KeyboardInterrupt inside numpy's import once
    left it half made, and `gcs run` failed on `np.logical_and` with a traceback). Judged on
    where each library's import starts, not on a timed Ctrl-C. The commands that only talk
    to a vehicle load no numba."""
    argv = [a.replace("OUT", str(tmp_path / "run")) for a in argv]
    proc = subprocess.run([sys.executable, "-c", _LOADS, *argv], cwd=Path(__file__).resolve()
                          .parents[2], capture_output=True, text=True, timeout=60,
                          check=False)
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["code"] == 2, proc.stdout + proc.stderr  # bad input, after the loads
    assert libraries <= result["loaded"].keys(), result
    assert all(result["loaded"].values()), result
    if "numba" not in libraries:  # a command that only talks to a vehicle does without it
        assert "numba" not in result["loaded"], result


_BLAS = r"""
import json, sys
import numpy as np
import common.jit
import fcu.estimator.filter  # the estimator's kernels, as a program loads them
import numba
@numba.njit
def product(a, b):  # a kernel of numba's BLAS (np.dot)
    return np.dot(a, b)
P, H = np.diag([1.0, 2.0, 3.0]), np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 2.0]])
dot = bool(np.allclose(product(P, H.T), P @ H.T))
kernels = "scipy.linalg" not in sys.modules
numba_blas = __import__("numba.np.arraymath", fromlist=["_HAVE_BLAS"])._HAVE_BLAS
import scipy.linalg
from scipy.linalg import cython_blas
print(json.dumps({"without_package": kernels, "numba_blas": numba_blas, "dot": dot,
                  "same": cython_blas is sys.modules["scipy.linalg.cython_blas"],
                  "linalg": bool(np.allclose(scipy.linalg.inv(np.eye(2) * 2.0),
                                             np.eye(2) * 0.5))}))
"""


def test_numba_gets_its_blas_without_scipy_linalgs_package():
    """A program that loads the kernels gets numba's BLAS from `scipy.linalg.cython_blas`
    loaded alone (`common.blas`), without running `scipy.linalg`'s package (0.3 s of CPU at
    every start); a later `import scipy.linalg` works and shares that module."""
    proc = subprocess.run([sys.executable, "-c", _BLAS], cwd=Path(__file__).resolve()
                          .parents[2], capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == {
        "without_package": True, "numba_blas": True, "dot": True, "same": True,
        "linalg": True}
