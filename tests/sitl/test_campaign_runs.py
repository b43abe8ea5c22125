"""Campaigns really flown on Dask: a local cluster, a scheduler and workers started as
separate processes (one of them killed mid-campaign), runs through processes, resumption,
and the exit codes of `gcs campaign`."""

from __future__ import annotations

import csv
import io
import json
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from common.config.scenario import scenario_from_data
from common.links import free_port
from gcs.campaign import run as run_mod
from gcs.campaign.load import load_campaign
from gcs.campaign.run import run_campaign
from gcs.campaign.runs import RunSpec, expand
from gcs.cli import main
from gcs.run.inprocess import run_scenario

from .conftest import stop

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "config" / "scenarios"
pytestmark = pytest.mark.xdist_group("campaign")  # clusters of two workers: one at a time

# Columns that depend on the machine's speed, not on the flight.
TIMING = ("wall_time_s", "real_time_factor", "run_wall_s", "fcu_step_us", "compile_time_s",
          "udp_rtt_us", "step_wall_us", "step_per_rtt")


def campaign_file(tmp_path: Path, text: str, base: str = "case2_irregular") -> Path:
    path = tmp_path / "campaign.toml"
    path.write_text(f'name = "test"\nbase = "{SCENARIOS / (base + ".toml")}"\n' + text)
    return path


SMALL = """
[set]
duration_s = 1.0
[[axis]]
key = "controller"
values = ["pid", "pd"]
[[axis]]
key = "actuator_fault[0].kind"
values = ["rotor_off", "tilt_stuck"]
[[axis]]
key = "actuator_fault[0].index"
values = [1, 4]
[[axis]]
key = "actuator_fault[0].start_s"
values = [0.501]  # inside a control period: the fault starts at a physics step
"""


def table(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open() as fh:
        return list(csv.DictReader(fh))


def flight_columns(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if not k.startswith(TIMING)} for r in rows]


def journal_ids(out: Path) -> Counter[str]:
    return Counter(json.loads(line)["run_id"]
                   for line in (out / "runs.jsonl").read_text().splitlines())


def test_cli_flies_every_run_once_and_a_rerun_flies_nothing(tmp_path: Path) -> None:
    path = campaign_file(tmp_path, SMALL)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "gcs.cli", "campaign", str(path), "--out", str(out),
           "--workers", "2", "--dashboard", "none"]
    first = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert first.returncode == 0, first.stderr
    rows = table(out)
    assert len(rows) == 8 and journal_ids(out) == Counter({r["run_id"]: 1 for r in rows})
    assert {r["status"] for r in rows} <= {"completed", "limited", "diverged", "failsafe",
                                           "crashed"}
    assert "8 flown now" in first.stdout
    # A row is the run itself: the same figures as flying its scenario here.
    c = load_campaign(path)
    spec = expand(c, out)[5]
    m = run_scenario(scenario_from_data(spec.data, c.base), logs=False).metrics
    row = next(r for r in rows if r["run_id"] == spec.run_id)
    assert row["actuator_fault[0].kind"] == spec.params["actuator_fault[0].kind"]
    assert float(row["position_error_m.max"]) == m["position_error_m"]["max"]
    assert row["status"] == m["status"]
    # The faults matter: the same runs without them fly differently.
    assert len({r["position_error_m.max"] for r in rows}) == 8
    summary = (out / "summary.md").read_text()
    assert "Actuator failures" in summary and (out / "failures.png").stat().st_size > 0

    again = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert again.returncode == 0, again.stderr
    assert "8 recorded in" in again.stderr and "(8 before, 0 flown now" in again.stdout
    assert sum(journal_ids(out).values()) == 8
    assert table(out) == rows


def test_separate_scheduler_and_workers_one_killed_give_the_same_table(
        tmp_path: Path) -> None:
    path = campaign_file(tmp_path, SMALL)
    local = tmp_path / "local"
    run_campaign(load_campaign(path), local, workers=2, dashboard=None, report=False,
                 progress_stream=io.StringIO())
    port = free_port(socket.SOCK_STREAM)
    logs = tmp_path / "logs"
    logs.mkdir()
    procs: list[subprocess.Popen] = []

    def start(name: str, *argv: str) -> subprocess.Popen:
        fh = (logs / f"{name}.log").open("wb")
        p = subprocess.Popen([sys.executable, "-m", "dask", *argv], cwd=ROOT, stdout=fh,
                             stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        fh.close()
        procs.append(p)
        return p

    address = f"tcp://127.0.0.1:{port}"
    try:
        start("scheduler", "scheduler", "--host", "127.0.0.1", "--port", str(port),
              "--no-dashboard")
        workers = [start(f"worker{i}", "worker", address, "--nthreads", "1", "--no-nanny",
                         "--no-dashboard", "--host", "127.0.0.1", "--name", f"w{i}")
                   for i in range(2)]
        killed: list[int] = []

        def kill_one(_row: dict) -> None:
            if not killed:  # mid-campaign: after the first result, one worker dies
                workers[0].send_signal(signal.SIGKILL)
                killed.append(workers[0].pid)

        deadline = time.monotonic() + 60
        while True:  # the scheduler and both workers up
            try:
                from dask.distributed import Client

                with Client(address, timeout=5) as client:
                    client.wait_for_workers(2, timeout=5)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)  # pacing the retries of this poll
        remote = tmp_path / "remote"
        outcome = run_campaign(load_campaign(path), remote, scheduler=address,
                               report=False, on_result=kill_one,
                               progress_stream=io.StringIO())
        assert killed and workers[0].wait(timeout=10) == -signal.SIGKILL
        assert outcome.exit_code == 0 and not outcome.failed
        assert sum(journal_ids(remote).values()) == 8 == len(journal_ids(remote))
        assert flight_columns(table(remote)) == flight_columns(table(local))
        # A rerun of the finished campaign flies nothing (one worker left is enough).
        again = run_campaign(load_campaign(path), remote, scheduler=address, report=False)
        assert again.flown == 0 and again.recorded_before == 8
        assert sum(journal_ids(remote).values()) == 8
    finally:
        stop({str(i): p for i, p in enumerate(procs)})


def test_runs_that_cannot_be_executed_exit_1_and_are_flown_on_resume(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = campaign_file(tmp_path, "[set]\nduration_s = 0.5\n[[axis]]\nkey = \"seed\"\n"
                                   "values = [1, 2, 3]\n")
    out = tmp_path / "out"
    real_expand = run_mod.expand

    def broken(c, o):  # run 1's scenario names a mission file that has gone meanwhile
        specs = real_expand(c, o)
        data = json.loads(json.dumps(specs[1].data))
        data["trajectory"] = {"kind": "mission", "mission": str(tmp_path / "gone.toml")}
        specs[1] = RunSpec(**{**specs[1].__dict__, "data": data})
        return specs

    monkeypatch.setattr(run_mod, "expand", broken)
    outcome = run_campaign(load_campaign(path), out, workers=1, dashboard=None, report=False)
    assert outcome.exit_code == 1 and list(outcome.failed) == [1]
    assert "gone.toml" in outcome.failed[1]
    assert len(table(out)) == 2 and sum(journal_ids(out).values()) == 2
    monkeypatch.setattr(run_mod, "expand", real_expand)
    outcome = run_campaign(load_campaign(path), out, workers=1, dashboard=None, report=False)
    assert outcome.exit_code == 0 and outcome.flown == 1 and outcome.recorded_before == 2
    assert [r["seed"] for r in table(out)] == ["1", "2", "3"]


def test_cli_exit_codes_for_bad_input_and_no_scheduler(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    bad = campaign_file(tmp_path, "[[axis]]\nkey = \"vehicle.mass_kg\"\nvalues = [0.0]\n")
    assert main(["campaign", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "mass_kg" in capsys.readouterr().err
    good = campaign_file(tmp_path, "[set]\nduration_s = 0.2\n")
    assert main(["campaign", str(good), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert main(["campaign", str(good), "--out", str(tmp_path / "o"), "--workers", "1",
                 "--scheduler", "tcp://127.0.0.1:1"]) == 2
    closed = free_port(socket.SOCK_STREAM)
    assert main(["campaign", str(good), "--out", str(tmp_path / "o"), "--scheduler",
                 f"tcp://127.0.0.1:{closed}"]) == 1
    err = capsys.readouterr().err
    assert f"127.0.0.1:{closed}" in err, err
    assert not (tmp_path / "o" / "runs.jsonl").exists() or \
        (tmp_path / "o" / "runs.jsonl").read_text() == ""


def test_runs_through_processes_equal_the_in_process_runs(tmp_path: Path) -> None:
    text = SMALL.replace('values = ["pid", "pd"]', 'values = ["pid"]').replace(
        "values = [1, 4]", "values = [2]")
    inproc = campaign_file(tmp_path, text)
    procs = tmp_path / "procs.toml"
    procs.write_text(inproc.read_text().replace('name = "test"\n',
                                                'name = "test"\ntransport = "udp"\n')
                     + '[keep]\nrun_folders = "all"\n')
    a, b = tmp_path / "a", tmp_path / "b"
    run_campaign(load_campaign(inproc), a, workers=2, dashboard=None, report=False)
    outcome = run_campaign(load_campaign(procs), b, workers=2, dashboard=None, report=False)
    assert outcome.exit_code == 0
    ra, rb = table(a), table(b)
    assert len(ra) == len(rb) == 2
    for x, y in zip(ra, rb, strict=True):
        assert y["transport"] == "udp" and x["transport"] == "in-process"
        for k in ("status", "position_error_m.max", "attitude_error_rad.rmse", "samples"):
            assert x[k] == y[k], k
    folders = sorted((b / "runs").iterdir())
    assert len(folders) == 2
    for f in folders:
        assert (f / "metrics.json").exists() and (f / "truth.ulg").exists()
        assert (f / "vehicle.toml").exists() and (f / "fcu.log").exists()
