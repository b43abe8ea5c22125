"""`gcs campaign FILE.toml --out DIR`: many flights of one base scenario, on Dask.

A campaign file names a base scenario, keys to set on every run (`[set]`), axes (a grid:
every combination of the axes' values) and Monte-Carlo draws (`[monte_carlo]`: N draws of
stated distributions per grid point). A key is a path into the scenario's TOML with its
vehicle and gain files inlined (common.config.scenario.resolved_scenario_data): `controller`,
`seed`, `sensors`, `vehicle.rotor_tau_up_s`, `gains.pid.kp_d`, `params.CA_LAG_COMP`,
`disturbance.force[0].magnitude`, `actuator_fault[0].index`, ...; every run's scenario is
validated by the same loader as a scenario file, before anything flies.

    name = "example"
    base = "../scenarios/case2_impulse.toml"
    transport = "in-process"          # or "udp", "tcp", "zenoh": through processes
    [set]
    duration_s = 8.0
    [[axis]]
    key = "controller"
    values = ["pid", "pd"]
    [[axis]]                           # several keys moving together
    keys = ["disturbance.force[0].azimuth_deg", "disturbance.force[0].elevation_deg"]
    values = [[0.0, 0.0], [90.0, 0.0]]
    [monte_carlo]
    draws = 20
    seed = 1
    [[monte_carlo.draw]]
    key = "vehicle.mass_kg"
    distribution = "normal"           # uniform (low, high), normal (mean, sigma),
    mean = 4.27                       # loguniform (low, high), integers (low, high),
    sigma = 0.1                       # choice (values)
    [keep]
    run_folders = "failed"            # "none" (default), "failed" or "all"

Results: DIR/runs.jsonl, the campaign's journal, gets one line per finished run as it
finishes (flushed; a line cut short by a kill is ignored); DIR/results.csv is rewritten from
it atomically, a row per run: its id (a hash of its full configuration), its axis values,
status and every metric. A run whose id is in the journal is not flown again, so a stopped
campaign resumes where it stopped and a finished one flies nothing. DIR/summary.md and its
figures are written at the end (gcs/campaign/report.py).

Execution: Dask distributed. By default a LocalCluster on 127.0.0.1 (worker processes, one
thread each, one per CPU) with its dashboard; `--scheduler tcp://HOST:8786` submits to a
running cluster. A worker lost mid-run (killed, out of memory) has its run re-executed on
another worker by the scheduler; a run is recorded once, when its result first arrives.

The parts, one job each: `model` (the campaign, its axes and draws), `keys` (paths into the
scenario's TOML), `load` (reading and checking the file), `runs` (the grid and draws as
runs, their ids), `worker` (one run, on a worker), `journal` (runs.jsonl and results.csv),
`progress`, `cluster` (Dask), `run` (`run_campaign`), `report` (summary.md and figures).
"""
