"""Run reports: the paper's figures and a one-page report.md for a run folder or for a
folder written by `gcs table1 --out DIR`. The functions are in `run_report`,
`table1_report` and `chart`, which load matplotlib; this package loads none of them, so the
ground station's other commands start without it.

`make_report(run_dir)` (`run_report`) reads metrics.json, scenario.toml and the two ULogs written by
`gcs run ... --out DIR` (in-process or through processes) and writes `DIR/figures/*.png`
and `DIR/report.md`:

- fig3_tilt_unwrapping.png: tilt angles before (atan2, jumping at +-pi) and after unwrapping.
- fig4_tracking.png: (a) quaternion actual vs desired with the instants where a Z-Y-X Euler
  description of the desired attitude is singular or jumps, (b) attitude error angle,
  (c) position actual vs desired, (d) position error norm and per-axis errors.
- fig5_pd_tracking_errors.png (Case I runs with the PD controller only): the paper's Fig. 5,
  "tracking errors for the PD controller": (a) attitude error angle and (b) position error,
  drawn as Fig. 4 (b) and (d). It comes in addition to Fig. 4, which every run gets (the
  paper draws Fig. 4 for PID only, but a PD run's quaternion and position traces are worth
  having too); a PID Case I run has no Fig. 5 (its errors are Fig. 4 (b) and (d)).
- fig6_path_3d.png: desired vs flown path in 3D.
- fig7_8_disturbance.png (runs with [[disturbance.*]] tables only): one run's position and
  attitude error with the pulse intervals shaded and the applied body-frame force and torque.
- estimation.png and innovations.png (runs with the estimator only: metrics.json has
  `estimation_error`): the estimate (dq_onboard's state) minus the truth (dq_truth, joined on
  time_us): position and velocity error norms and the attitude error angle; the pose's
  innovations (estimator_innovations: position NED, heading) and test ratios
  (estimator_innovation_test_ratios, the gate at 1). report.md gets the estimation_error
  figures beside them.

`make_table1_report(dir)` (`table1_report`) does the above for each of the 8 run folders of
a table1 folder (`<scenario>_<controller>`, e.g. `case2_impulse_pd`) and writes, in the
table1 folder itself:

- table1.png: the Table I chart (`table1_chart`), redrawn from the run folders.
- fig5_pd_tracking_errors.png: Fig. 5 from `case1_figure8_pd`, with the PID run's errors
  (`case1_figure8_pid`, Fig. 4) in grey for comparison, as the paper's text compares them.
- fig7_disturbance_pid.png and fig8_disturbance_pd.png: the paper's Figs. 7 (PID) and 8
  (PD), drawn from the three Case II runs of that controller: one row per disturbance
  (impulse, sinusoidal ("regular" in Table I), irregular) and three columns lettered down
  the columns, as the paper's text reads them ("Figs. 7 (a) and (d)" are both the impulse
  row): attitude error angle (a-c), position error (d-f) and the applied disturbance (g-i);
  pulse intervals are shaded on the whole row. A diverged run is drawn up to its divergence
  (`divergence_t_s`), marked by a red dotted line and named in its row's titles; a missing
  run leaves its row empty and says so.
- report.md: Table I (ours beside the paper), every run's status, why, and its events, links
  to every figure, and the run folders that are missing or could not be read.

`table1_chart(table, png)` (`chart`) draws `gcs.report.table1.table_json` output as grouped bars.

The parts, one job each: names (file names, captions), rundata (loading a run folder), plot
(shared plot helpers), tracking_figures (Figs. 3-6), disturbance_figures (Figs. 7 and 8),
estimation_figures, run_report (a run folder's report.md), table1_report (a table1
folder's) and chart (the Table I chart).

Figures are drawn on matplotlib's Agg canvas directly (never pyplot, never a screen); long
series are thinned to every bucket's first, minimum and maximum sample, so peaks survive.
"""
