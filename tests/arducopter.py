"""A real ArduCopter SITL for the tests, only ever inside a private network namespace.

The binary listens on 0.0.0.0 (MAVLink on TCP 5760, 5762, 5763; RC input on UDP 5501) and
cannot be told otherwise, so it runs in a user + network namespace of our own that has
nothing but loopback (checked before it starts), and everything that talks to it (`gcs`,
`sitl`, pymavlink) is started in the same namespace with `nsenter`.

`$ARDUCOPTER` names the binary; without it the tests that need it are skipped with the
reason (`.ci/run` sets it when the binary is beside the repository).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def binary() -> Path | None:
    """The ArduCopter SITL binary named by $ARDUCOPTER, None when unset or not executable."""
    value = os.environ.get("ARDUCOPTER", "")
    if not value:
        return None
    path = Path(value).expanduser().resolve()
    return path if path.is_file() and os.access(path, os.X_OK) else None


def default_params() -> Path:
    """ArduPilot's copter.parm and copter-hexa.parm: `default_params/` beside the binary, or
    the folder $ARDUCOPTER_DEFAULTS names (ArduPilot's Tools/autotest/default_params/)."""
    if os.environ.get("ARDUCOPTER_DEFAULTS"):
        return Path(os.environ["ARDUCOPTER_DEFAULTS"]).expanduser().resolve()
    exe = binary()
    assert exe is not None
    return exe.parent / "default_params"


def skip_reason() -> str | None:
    """Why ArduCopter tests cannot run here, or None."""
    if not os.environ.get("ARDUCOPTER"):
        return "set $ARDUCOPTER to an ArduCopter SITL binary to run the ArduPilot tests"
    if binary() is None:
        return f"$ARDUCOPTER={os.environ['ARDUCOPTER']} is not an executable file"
    missing = [name for name in ("copter.parm", "copter-hexa.parm")
               if not (default_params() / name).is_file()]
    if missing:
        return (f"{default_params()} lacks {', '.join(missing)} (ArduPilot's "
                "Tools/autotest/default_params/)")
    return namespace_reason()


def namespace_reason() -> str | None:
    """Why a private network namespace cannot be made here, or None."""
    for tool in ("unshare", "nsenter", "ip"):
        if shutil.which(tool) is None:
            return f"needs {tool} for a private network namespace"
    done = subprocess.run(["unshare", "-rn", "ip", "link", "set", "lo", "up"],
                          capture_output=True, check=False)
    if done.returncode != 0:
        return "cannot create a private network namespace (unshare -rn)"
    return None


needs_arducopter = pytest.mark.skipif(skip_reason() is not None,
                                      reason=skip_reason() or "")


class Namespace:
    """A private user + network namespace held open by a sleeping process; `lo` up, and
    nothing else in it (refused otherwise, before anything runs in it)."""

    def __init__(self) -> None:
        self._holder = subprocess.Popen(
            ["unshare", "-rn", "bash", "-c", "ip link set lo up && echo up && exec sleep 1d"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            start_new_session=True)
        assert self._holder.stdout is not None
        line = self._holder.stdout.readline().strip()
        if line != "up":
            err = self._holder.stderr.read() if self._holder.stderr else ""
            self.close()
            raise RuntimeError(f"private namespace not created: {err.strip()}")
        self.children: list[subprocess.Popen] = []
        links = self.run(["ip", "-o", "link", "show"], capture_output=True, text=True,
                         check=True).stdout.splitlines()
        names = [entry.split(":")[1].strip() for entry in links if entry.strip()]
        if names != ["lo"]:
            self.close()
            raise RuntimeError(f"the namespace has other interfaces than lo: {names}")

    @property
    def pid(self) -> int:
        return self._holder.pid

    def argv(self, argv: Sequence[str | os.PathLike[str]]) -> list[str]:
        """`argv` as run inside the namespace."""
        return ["nsenter", "-t", str(self.pid), "-U", "-n", "--preserve-credentials",
                *map(str, argv)]

    def popen(self, argv: Sequence[str | os.PathLike[str]], **kwargs) -> subprocess.Popen:
        """A long-running child inside the namespace, in its own process group; stopped by
        `close`."""
        kwargs.setdefault("start_new_session", True)
        proc = subprocess.Popen(self.argv(argv), **kwargs)
        self.children.append(proc)
        return proc

    def run(self, argv: Sequence[str | os.PathLike[str]], **kwargs
            ) -> subprocess.CompletedProcess:
        kwargs.setdefault("timeout", 120)
        return subprocess.run(self.argv(argv), **kwargs)

    def gcs(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
        """`gcs ARGS...` inside the namespace, its output as text."""
        return self.run([sys.executable, "-m", "gcs.cli", *args], cwd=ROOT,
                        capture_output=True, text=True, timeout=timeout, check=False)

    def close(self) -> None:
        for proc in reversed(getattr(self, "children", [])):
            stop_group(proc)
        stop_group(self._holder)


def stop_group(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """SIGTERM to the child's process group (its own session), SIGKILL if it lingers."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=timeout)
    for stream in (proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()


def start_arducopter(ns: Namespace, workdir: Path, *, model: str = "hexa", speedup: int = 10,
                     defaults: Sequence[Path] = (), extra: Sequence[str] = ()
                     ) -> subprocess.Popen:
    """ArduCopter in `workdir` (it writes eeprom.bin, logs/ there), parameters wiped, with
    ArduPilot's copter.parm and copter-hexa.parm and then `defaults`; its console in
    workdir/arducopter.log. It waits for a client on TCP 5760 before it runs."""
    exe = binary()
    assert exe is not None, skip_reason()
    params = default_params()
    files = [params / "copter.parm", params / "copter-hexa.parm", *defaults]
    workdir.mkdir(parents=True, exist_ok=True)
    log = (workdir / "arducopter.log").open("wb")
    try:
        return ns.popen([exe, "--model", model, "--speedup", str(speedup), "-I0", "-w",
                         "--defaults", ",".join(str(f) for f in files), *extra],
                        cwd=workdir, stdout=log, stderr=subprocess.STDOUT,
                        stdin=subprocess.DEVNULL)
    finally:
        log.close()


def wait_port(ns: Namespace, port: int, timeout: float = 30.0) -> None:
    """Wait until something listens on TCP `port` inside the namespace."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out = ns.run(["ss", "-ltn"], capture_output=True, text=True, check=False).stdout
        if f":{port} " in out:
            return
        time.sleep(0.2)
    raise TimeoutError(f"nothing listens on TCP {port} within {timeout:g} s")


@contextlib.contextmanager
def namespace() -> Iterator[Namespace]:
    ns = Namespace()
    try:
        yield ns
    finally:
        ns.close()
