"""The CPython `make` builds `.venv` with: of the builds on this machine of python3's own
version (where python3 is older than 3.11, of the oldest version that is not), those with
`venv` and `ensurepip`, the one that runs a short pure-Python workload fastest. Prints its
path; `python3` when none of them answers.

    python3 tools/fastest_python.py [-v]

Why: the flight stack's step is mostly interpreted Python around compiled kernels, and how
CPython was built changes its speed a lot. On the 2-core machine of docs/benchmarks.md,
Debian's python3.11 (its distribution's build, libpython linked into the executable) runs
this tool's workload in two thirds of the time pyenv's default build of 3.11 takes (no
profile-guided or link-time optimisation, a shared libpython), and the in-process mocap
flight 6-8 % faster, with the same figures to the last bit
(docs/benchmarks.md#the-interpreter).
`make PYTHON=/path/to/python3` chooses instead. Only builds of the version `python3` is
are compared, so the packages installed, and the figures, are those python3 would give.

Candidates: python3 and python3.11 to python3.14 on PATH, and the same names in /usr/bin
and /usr/local/bin, each asked for its real executable (a pyenv shim answers with the
interpreter it runs, so one interpreter is measured once).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from typing import NamedTuple

NAMES = ("python3", "python3.11", "python3.12", "python3.13", "python3.14")
DIRS = ("/usr/bin", "/usr/local/bin")
MIN_VERSION = (3, 11)
PROBE_TIMEOUT_S = 20.0
ROUNDS = 3

# Run by each candidate: its executable, version, whether it can make a venv with pip, and
# the best of 7 timings of a workload like the stack's glue (calls, tuples of floats, named
# tuples, struct round trips).
PROBE = r"""
import json, os, struct, sys, time
from typing import NamedTuple
try:
    import ensurepip, venv
    can_venv = True
except ImportError:
    can_venv = False
class S(NamedTuple):
    t: int
    v: tuple
def f(a, b):
    return (a[0] + b[0], a[1] - b[1], -a[2] * b[2])
W = struct.Struct("<6f")
def work(n):
    acc, v, out = (0.0, 0.0, 0.0), (1.0, 2.0, 0.5), []
    for i in range(n):
        acc = f(acc, v)
        out.append(S(i, W.unpack(W.pack(*acc, *v))))
        if len(out) > 64:
            out.clear()
best = 1e9
for _ in range(7):
    t0 = time.perf_counter()
    work(50000)
    best = min(best, time.perf_counter() - t0)
print(json.dumps({"exe": os.path.realpath(sys.executable), "version": sys.version_info[:2],
                  "venv": can_venv, "seconds": best}))
"""


class Probe(NamedTuple):
    exe: str
    version: tuple[int, int]
    can_venv: bool
    seconds: float


def candidates() -> list[str]:
    """Every python3 name on PATH and in DIRS, once each by path."""
    found: list[str] = []
    for name in NAMES:
        for path in (shutil.which(name), *(os.path.join(d, name) for d in DIRS)):
            if path and os.access(path, os.X_OK) and path not in found:
                found.append(path)
    return found


def probe(path: str) -> Probe | None:
    """What `path` answers to PROBE; None when it does not run or answers nonsense."""
    try:
        done = subprocess.run([path, "-I", "-c", PROBE], capture_output=True, text=True,
                              timeout=PROBE_TIMEOUT_S, check=False)
        answer = json.loads(done.stdout)
        return Probe(str(answer["exe"]), (int(answer["version"][0]), int(answer["version"][1])),
                     bool(answer["venv"]), float(answer["seconds"]))
    except (OSError, subprocess.SubprocessError, ValueError, KeyError, TypeError, IndexError):
        return None


def pick(probes: list[Probe | None], version: tuple[int, int]) -> Probe | None:
    """The fastest probe of `version` that can build the venv (3.11 or newer, venv and
    ensurepip)."""
    usable = [p for p in probes if p is not None and p.version == version and
              p.version >= MIN_VERSION and p.can_venv]
    return min(usable, key=lambda p: p.seconds, default=None)


def wanted_version(default: Probe | None, probes: list[Probe | None]
                   ) -> tuple[int, int] | None:
    """python3's version (`default`) when it is 3.11 or newer; else the oldest version that
    is, among the probes (a machine whose python3 is older, with a newer one installed)."""
    if default is not None and default.version >= MIN_VERSION:
        return default.version
    return min((p.version for p in probes if p is not None and p.version >= MIN_VERSION),
               default=None)


def measured(paths: list[str], rounds: int = ROUNDS) -> dict[str, Probe | None]:
    """Each interpreter's probe (one per interpreter, under its first name), its time the
    best of `rounds` probes taken in turn (so that a machine's changing speed is shared)."""
    probes: dict[str, Probe | None] = {}
    for path in paths:
        p = probe(path)
        if p is not None and any(q is not None and q.exe == p.exe for q in probes.values()):
            continue  # an interpreter already measured under another name
        probes[path] = p
    for _ in range(rounds - 1):
        for path, p in probes.items():
            again = probe(path) if p is not None else None
            if p is not None and again is not None and again.seconds < p.seconds:
                probes[path] = again
    return probes


def main(argv: list[str]) -> int:
    probes = measured(candidates())
    if "-v" in argv:
        for path, p in probes.items():
            print(f"{path}: {'no answer' if p is None else p}", file=sys.stderr)
    found = list(probes.values())
    version = wanted_version(probes.get(shutil.which("python3") or ""), found)
    best = pick(found, version) if version is not None else None
    print(best.exe if best is not None else "python3")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
