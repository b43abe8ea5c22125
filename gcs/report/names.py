"""The report's file names, the figures' captions and the paper's case names in a run or
table1 folder (`gcs report` writes them; tests and the CLI read them)."""

from __future__ import annotations

FIG_DIR = "figures"
FIG3 = "fig3_tilt_unwrapping.png"
FIG4 = "fig4_tracking.png"
FIG5 = "fig5_pd_tracking_errors.png"
FIG6 = "fig6_path_3d.png"
FIG7 = "fig7_disturbance_pid.png"
FIG8 = "fig8_disturbance_pd.png"
FIG78 = "fig7_8_disturbance.png"
FIG_ESTIMATION = "estimation.png"
FIG_INNOVATIONS = "innovations.png"
REPORT = "report.md"
TABLE1_JSON = "table1.json"  # what makes a folder a table1 folder
TABLE1_PNG = "table1.png"

CASE1 = "case1_figure8"
# The rows of Figs. 7 and 8, in the paper's order: (scenario, what the row shows).
CASE2_ROWS = (("case2_impulse", "impulse disturbance"),
              ("case2_sine", "sinusoidal (regular) disturbance"),
              ("case2_irregular", "irregular disturbance"))
FIG78_BY_CONTROLLER = {"pid": (7, FIG7), "pd": (8, FIG8)}  # figure number, file


SEVERITY = {0: "emergency", 1: "alert", 2: "critical", 3: "error", 4: "warning", 5: "notice",
            6: "info", 7: "debug"}


CAPTIONS = {FIG3: "Fig. 3: tilt angles before and after unwrapping",
            FIG4: "Fig. 4: attitude and position tracking",
            FIG5: "Fig. 5: Case I, tracking errors of the PD controller",
            FIG6: "Fig. 6: 3D path, desired vs flown",
            FIG7: "Fig. 7: Case II, robustness to disturbance, PID (impulse, sinusoidal, "
                  "irregular)",
            FIG8: "Fig. 8: Case II, robustness to disturbance, PD (impulse, sinusoidal, "
                  "irregular)",
            FIG78: "Fig. 7/8: response to the disturbances",
            FIG_ESTIMATION: "Estimation error: the estimate minus the truth",
            FIG_INNOVATIONS: "The pose's innovations and test ratios",
            TABLE1_PNG: "Table I: RMSE, ours vs the paper"}
