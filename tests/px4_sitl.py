"""A real PX4 SITL for the tests, only ever inside a private network namespace, flying on
this project's plant (`sitl --protocol px4-hil`).

PX4 binds its MAVLink UDP ports (18570+i, 14580+i, ...) on every interface and cannot be
told otherwise, so it runs in a user + network namespace of our own with nothing but
loopback (`tests.arducopter.Namespace`, checked before anything starts), and everything
that talks to it is started in the same namespace. PX4 keeps lock files in /tmp that are
shared across namespaces (`/tmp/px4_lock-N`): each run takes a free instance N.

`$PX4_SITL` names a `px4_sitl_default` build folder (`bin/px4`, `etc/`); without it the
tests that need it are skipped with the reason. Airframe 6011 (hexa X) starts
`simulator_mavlink`, which connects as a TCP client to 127.0.0.1:4560+N; PX4's system id is
1+N; its ground-station link sends to UDP 14550.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.arducopter import ROOT, Namespace, namespace, namespace_reason, stop_group

SCENARIO = ROOT / "config" / "scenarios" / "px4_hexa.toml"
GCS_URL = "udpin:127.0.0.1:14550"


def build_folder() -> Path | None:
    """The px4_sitl_default folder $PX4_SITL names, None when unset or incomplete."""
    value = os.environ.get("PX4_SITL", "")
    if not value:
        return None
    path = Path(value).expanduser().resolve()
    ok = (path / "bin" / "px4").is_file() and (path / "etc" / "init.d-posix").is_dir()
    return path if ok else None


def skip_reason() -> str | None:
    """Why PX4 tests cannot run here, or None."""
    if not os.environ.get("PX4_SITL"):
        return "set $PX4_SITL to a px4_sitl_default build folder to run the PX4 tests"
    if build_folder() is None:
        return f"$PX4_SITL={os.environ['PX4_SITL']} has no bin/px4 and etc/init.d-posix"
    return namespace_reason()


needs_px4 = pytest.mark.skipif(skip_reason() is not None, reason=skip_reason() or "")


def free_instance() -> int:
    """A PX4 instance number whose lock file nobody holds (PX4's /tmp/px4_lock-N)."""
    for n in range(20, 60):
        if not Path(f"/tmp/px4_lock-{n}").exists():
            return n
    raise RuntimeError("no free PX4 instance in 20..59")


@dataclass
class Px4Run:
    """PX4 and the plant running in `ns`; `gcs(...)` runs a ground-station command there."""

    ns: Namespace
    folder: Path
    instance: int
    sitl: subprocess.Popen
    px4: subprocess.Popen

    @property
    def system_id(self) -> int:
        return 1 + self.instance

    def px4_log(self) -> str:
        return (self.folder / "px4.log").read_text(errors="replace")

    def sitl_log(self) -> str:
        return (self.folder / "sitl.log").read_text(errors="replace")

    def gcs(self, *args: str, timeout: float = 180.0) -> subprocess.CompletedProcess:
        return self.ns.run([sys.executable, "-m", "gcs.cli", *args, "--connect", GCS_URL],
                           cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                           check=False)

    def wait_log(self, text: str, timeout: float = 120.0) -> None:
        deadline = time.monotonic() + timeout
        while text not in self.px4_log():
            assert self.px4.poll() is None, self.px4_log()[-3000:]
            assert self.sitl.poll() is None, self.sitl_log()[-3000:]
            assert time.monotonic() < deadline, f"PX4 said no {text!r} within {timeout:g} s"
            time.sleep(0.1)

    def ulog(self) -> Path:
        return self.ulogs()[-1]

    def ulogs(self) -> list[Path]:
        """PX4's ULogs in time order (its logger starts a new file at each arming)."""
        logs = sorted((self.folder / "px4" / "log").glob("*/*.ulg"))
        assert logs, "PX4 wrote no ULog"
        return logs

    def status(self) -> str:
        """`gcs status`'s output (asserted exit 0)."""
        done = self.gcs("status", timeout=60)
        assert done.returncode == 0, done.stdout + done.stderr
        return done.stdout

    def wait_ready(self, timeout: float = 60.0) -> str:
        """Until `gcs status` says `readiness: ready to arm` (PX4's pre-arm checks pass, as
        a pilot waits for them); that status."""
        deadline = time.monotonic() + timeout
        while True:
            done = self.gcs("status", timeout=60)
            if done.returncode == 0 and "readiness: ready to arm" in done.stdout:
                return done.stdout
            assert time.monotonic() < deadline, f"not ready to arm after {timeout:g} s:\n" \
                + done.stdout + done.stderr
            time.sleep(1.0)

    def wait_disarmed(self, timeout: float = 240.0) -> None:
        """Until `gcs status` says `armed: no` (wall-clock seconds)."""
        deadline = time.monotonic() + timeout
        while True:
            done = self.gcs("status", timeout=60)
            if done.returncode == 0 and re.search(r"armed: no\b", done.stdout):
                return
            assert time.monotonic() < deadline, f"still armed after {timeout:g} s:\n" + \
                done.stdout + done.stderr
            time.sleep(2.0)


def sitl_stats(folder: Path) -> dict[str, Any]:
    """The plant's --stats (written when it stops, after the run)."""
    return json.loads((folder / "sitl_stats.json").read_text())


def truth(folder: Path) -> dict[str, np.ndarray]:
    """The plant's truth log (topic dq_truth: timestamp in us on PX4's lockstep clock, ENU
    position px east, py north, pz up, velocities vx, vy, vz, landed)."""
    from pyulog import ULog
    return dict(ULog(str(folder / "truth.ulg")).get_dataset("dq_truth").data)


def topic(logs: Sequence[Path], name: str, instance: int = 0) -> dict[str, np.ndarray]:
    """One topic of PX4's ULogs, the files joined in time order (empty when absent)."""
    from pyulog import ULog
    parts: list[dict[str, np.ndarray]] = []
    for path in logs:
        ulog = ULog(str(path), [name])
        for d in ulog.data_list:
            if d.name == name and d.multi_id == instance:
                parts.append(d.data)
    if not parts:
        return {}
    keys = set.intersection(*(set(p) for p in parts))
    return {k: np.concatenate([p[k] for p in parts]) for k in keys}


def parameter(logs: Sequence[Path], name: str) -> float:
    """A PX4 parameter's value as the first ULog recorded it (its initial parameters)."""
    from pyulog import ULog
    return float(ULog(str(logs[0]), []).initial_parameters[name])


def logged_messages(logs: Sequence[Path]) -> list[tuple[float, str]]:
    """PX4's logged messages (time in s, text) from its ULogs."""
    from pyulog import ULog
    out: list[tuple[float, str]] = []
    for path in logs:
        ulog = ULog(str(path), [])
        out += [(m.timestamp * 1e-6, m.message) for m in ulog.logged_messages]
        for tagged in getattr(ulog, "logged_messages_tagged", {}).values():
            out += [(m.timestamp * 1e-6, m.message) for m in tagged]
    return sorted(set(out))


@contextlib.contextmanager
def px4_on_plant(folder: Path, *, sitl_args: Sequence[str] = (),
                 env: dict[str, str] | None = None) -> Iterator[Px4Run]:
    """The plant (`sitl SCENARIO --protocol px4-hil`, truth log in folder/truth.ulg) and
    PX4 (airframe 6011, working directory folder/px4) in a private namespace, until PX4
    says "Ready for takeoff"."""
    exe = build_folder()
    assert exe is not None, skip_reason()
    folder.mkdir(parents=True, exist_ok=True)
    with namespace() as ns:
        instance = free_instance()
        port = 4560 + instance
        slog = (folder / "sitl.log").open("wb")
        sitl = ns.popen([sys.executable, "-m", "sitl.node", SCENARIO, "--protocol", "px4-hil",
                         "--link", f"tcpin:127.0.0.1:{port}", "--sysid", str(1 + instance),
                         "--truth-log", folder / "truth.ulg", "--stats",
                         folder / "sitl_stats.json", *sitl_args],
                        cwd=ROOT, stdout=slog, stderr=subprocess.STDOUT)
        slog.close()
        deadline = time.monotonic() + 60
        while b"sitl: serving" not in (folder / "sitl.log").read_bytes():
            assert sitl.poll() is None, (folder / "sitl.log").read_text()
            assert time.monotonic() < deadline, "sitl did not start serving"
            time.sleep(0.05)
        (folder / "px4").mkdir(exist_ok=True)
        plog = (folder / "px4.log").open("wb")
        px4_env = dict(os.environ, PX4_SYS_AUTOSTART="6011",
                       PX4_SIM_MODEL="gazebo-classic_typhoon_h480", **(env or {}))
        px4 = ns.popen([exe / "bin" / "px4", "-d", "-i", str(instance), "-w",
                        folder / "px4", exe / "etc"], env=px4_env, stdout=plog,
                       stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        plog.close()
        run = Px4Run(ns, folder, instance, sitl, px4)
        try:
            run.wait_log("Ready for takeoff")
            yield run
        finally:
            stop_group(px4)
            stop_group(sitl)
