"""The Table I chart: position and attitude RMSE, ours beside the paper, as grouped bars."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.patches import Patch

from gcs.report.plot import new_figure, save_figure
from gcs.report.table1 import CASES, CONTROLLERS, PAPER


def table1_chart(table: dict[str, Any], out_png: Path) -> Path:
    """Grouped bars (log y) of position and attitude RMSE, ours vs the paper, PID and PD, for
    the four cases of `gcs.report.table1.table_json` output; diverged runs hatched and labelled."""
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    rows = {(r["scenario"], r["controller"]): r for r in table.get("rows", [])}
    fig = new_figure(9.0)
    axes = fig.subplots(2, 1)
    colors = {"pid": "tab:blue", "pd": "tab:orange"}
    series = [(ctrl, src) for ctrl in CONTROLLERS for src in ("ours", "paper")]
    width = 0.2
    x = np.arange(len(CASES))
    for ax, metric, unit in ((axes[0], "position_error_m", "m"),
                             (axes[1], "attitude_error_rad", "rad")):
        values = []
        for s, (ctrl, src) in enumerate(series):
            offset = (s - (len(series) - 1) / 2) * width
            for c, (_, scen) in enumerate(CASES):
                row = rows.get((scen, ctrl))
                if src == "paper":
                    val = row["paper"][metric]["rmse"] if row else \
                        PAPER[scen][ctrl][0 if metric == "position_error_m" else 1][2]
                    status = "completed"
                elif row is None:
                    xpos = x[c] + offset
                    ax.text(xpos, 0.02, "n/a", transform=ax.get_xaxis_transform(),
                            ha="center", fontsize=8, color="0.4")
                    continue
                else:
                    val, status = row["ours"][metric]["rmse"], row["status"]
                    if status == "diverged" and row.get("divergence_t_s") is not None:
                        status = f"diverged\nat {row['divergence_t_s']:.3g} s"
                if not (isinstance(val, int | float) and math.isfinite(val) and val > 0):
                    continue
                values.append(val)
                diverged = status != "completed"
                ax.bar(x[c] + offset, val, width * 0.92, color=colors[ctrl],
                       alpha=1.0 if src == "ours" else 0.38,
                       edgecolor="red" if diverged else colors[ctrl],
                       hatch="///" if diverged else None, lw=1.6 if diverged else 0.8)
                text = f"{val:.2g}" + (f"\n{status}" if diverged else "")
                ax.annotate(text, (x[c] + offset, val), xytext=(0, 2),
                            textcoords="offset points", ha="center", va="bottom",
                            fontsize=7.5, color="red" if diverged else "0.15",
                            fontweight="bold" if diverged else "normal")
        ax.set_yscale("log")
        if values:
            ax.set_ylim(min(values) / 3.0, max(values) * 8.0)
        ax.set_xticks(x, [f"Case {label}" for label, _ in CASES])
        ax.set_xlim(-0.6, len(CASES) - 0.4)
        name = "position error RMSE" if unit == "m" else "attitude error RMSE"
        ax.set_ylabel(f"{name} ({unit})")
        ax.set_title(f"({'ab'[unit == 'rad']}) {name}, log scale")
        ax.grid(True, axis="y", which="major", alpha=0.3)
    handles = [Patch(facecolor=colors[ctrl], alpha=1.0 if src == "ours" else 0.38,
                     edgecolor=colors[ctrl], label=f"{ctrl.upper()} {src}")
               for ctrl, src in series]
    handles.append(Patch(facecolor="white", edgecolor="red", hatch="///",
                         label="ours, diverged\n(RMSE up to the divergence)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=5, fontsize=9.5)
    fig.suptitle("Table I – RMSE, ours vs the paper (PID and PD)")
    return save_figure(fig, out_png)
