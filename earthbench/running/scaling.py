"""How a planner's cost grows with the work: the ``scale`` table and the cost-growth figure.

A suite is a *size ladder* when its scenarios have at least three distinct target volumes, each
at least twice the one before (``scale``: 4, 16, 64, 256 m³ on maps growing with the target);
for such a suite the leaderboard adds, per planner and target, the median and interquartile
range over seeds of

* solve time (s) and solve time per m³ loaded — flat across the targets means the planner's
  cost is linear in the work; ``growth`` is its ratio to the smallest target's median;
* time per m³ (the plan's makespan per m³ loaded), the quality side of the same runs;

and a log–log figure of the last two against the target, one line per planner.

Solve times come from the harness, volumes and makespans from the referee, over the runs that
returned a valid plan that loaded something (a timeout has no solve time worth a median); how
many runs those are is in the ``valid`` column, next to the runs stored.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ..plotting import mpl_text, planner_colours, pyplot

#: Consecutive targets of a size ladder differ by at least this factor.
LADDER_STEP = 2.0
#: A ladder has at least this many target sizes.
LADDER_MIN_SIZES = 3


def is_size_ladder(runs: pd.DataFrame) -> bool:
    """Whether the runs' target volumes form a size ladder (see the module docstring)."""
    targets = np.sort(runs["target_volume"].dropna().unique()) if "target_volume" in runs else np.array([])
    return len(targets) >= LADDER_MIN_SIZES and bool(np.all(targets[1:] >= LADDER_STEP * targets[:-1] - 1e-9))


def _valid_loading(runs: pd.DataFrame) -> pd.DataFrame:
    ok = (runs["reason"] == "ok") & runs["valid"].fillna(False).astype(bool) & (runs["loaded_volume"] > 0)
    out = runs[ok].copy()
    out["solve_per_m3"] = out["solve_time_s"] / out["loaded_volume"]
    return out


def _quartiles(values: pd.Series) -> tuple[float, float, float]:
    if values.empty:
        return (np.nan, np.nan, np.nan)
    q = values.quantile([0.25, 0.5, 0.75])
    return float(q[0.25]), float(q[0.5]), float(q[0.75])


def scale_summary(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per planner (``solver`` label) and target volume: counts, medians and quartiles."""
    good = _valid_loading(runs)
    rows: list[dict[str, Any]] = []
    for (solver, target), g in runs.groupby(["solver", "target_volume"], sort=True):
        v = good[(good["solver"] == solver) & (good["target_volume"] == target)]
        row: dict[str, Any] = {"solver": solver, "target_volume": float(target), "runs": len(g), "valid": len(v),
                               "volume_ratio_median": float(v["volume_ratio"].median()) if len(v) else np.nan}
        for col in ("solve_time_s", "solve_per_m3", "time_per_m3"):
            row[f"{col}_q1"], row[f"{col}_median"], row[f"{col}_q3"] = _quartiles(v[col])
        rows.append(row)
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    smallest = out[out["target_volume"] == out["target_volume"].min()].set_index("solver")["solve_per_m3_median"]
    out["growth"] = out["solve_per_m3_median"] / out["solver"].map(smallest)
    return out


def _iqr(row: pd.Series, col: str, spec: str) -> tuple[str, str, float]:
    med = row[f"{col}_median"]
    if not np.isfinite(med):
        return ("–", "", np.nan)
    return (f"{med:{spec}}", f" [{row[f'{col}_q1']:{spec}}–{row[f'{col}_q3']:{spec}}]", float(med))


def scale_rows(summary: pd.DataFrame) -> list[dict[str, Any]]:
    """The ``scale`` table in :func:`earthbench.publishing.publish.html_table`'s row format (cells of
    heading, text and sort key): medians with their interquartile ranges, by target then planner."""
    rows = []
    for _, r in summary.sort_values(["target_volume", "solver"]).iterrows():
        cells: list[tuple[str, str, Any]] = [
            ("Target m³", f"{r['target_volume']:g}", r["target_volume"]),
            ("Planner", str(r["solver"]), None),
            ("Valid / runs", f"{r['valid']}/{r['runs']}", r["valid"]),
            ("Volume ratio (median)", "–" if not np.isfinite(r["volume_ratio_median"]) else f"{r['volume_ratio_median']:.3f}",
             r["volume_ratio_median"]),
        ]
        for col, head, spec in (("solve_time_s", "Solve s", ".3g"), ("solve_per_m3", "Solve s/m³", ".3g"),
                                ("time_per_m3", "Time per m³, s", ".1f")):
            med, iqr, key = _iqr(r, col, spec)
            cells.append((f"{head} (median [IQR])", med + iqr, key))
            if col == "solve_per_m3":
                g = r["growth"]
                cells.append(("Solve s/m³ ÷ smallest target's", "–" if not np.isfinite(g) else f"{g:.2f}×", g))
        rows.append({"cells": cells})
    return rows


def cost_growth_figure(runs: pd.DataFrame, title: str):
    """Log–log: solve time per m³ and time per m³ against the target, median and IQR over seeds."""

    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    plt = pyplot()
    summary = scale_summary(runs)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
    colours = planner_colours(runs["solver"].unique())
    panels = (("solve_per_m3", "solve time per m³ loaded, s/m³"), ("time_per_m3", "time per m³ (makespan / loaded), s/m³"))
    for ax, (col, label) in zip(axes, panels):
        for solver, g in summary.groupby("solver") if not summary.empty else ():
            g = g[np.isfinite(g[f"{col}_median"])]
            if g.empty:
                continue
            x, med = g["target_volume"].to_numpy(), g[f"{col}_median"].to_numpy()
            err = np.vstack([med - g[f"{col}_q1"].to_numpy(), g[f"{col}_q3"].to_numpy() - med])
            ax.errorbar(x, med, yerr=err, marker="o", ms=4, capsize=3, color=colours[solver], label=mpl_text(solver))
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        if not summary.empty:  # label the ladder's own targets and 1-2-5 steps, not powers of 2 and 10
            targets = sorted(summary["target_volume"].unique())
            ax.set_xticks(targets, [f"{t:g}" for t in targets])
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("target volume, m³")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
    if not summary.empty:
        axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(mpl_text(title) + " — median over seeds, bars: interquartile range; flat = cost linear in the work",
                 fontsize=10)
    return fig


#: Columns :func:`cost_growth_figure` reads (the frame shipped to a figure worker).
SCALE_COLUMNS = ["solver", "target_volume", "reason", "valid", "volume_ratio", "loaded_volume", "solve_time_s",
                 "time_per_m3"]
SCALE_CAPTION = "Cost growth: solve time per m³ and time per m³ against the target volume (log–log)"


def scale_section(runs: pd.DataFrame, figure_base: str, title: str) -> tuple[list[dict[str, Any]], tuple | None]:
    """For a size ladder: the ``scale`` table's rows and the cost-growth figure job for
    :class:`earthbench.publishing.publish.Renderer`; for any other suite, ``([], None)``."""
    if not is_size_ladder(runs):
        return [], None
    return scale_rows(scale_summary(runs)), ("cost-growth", figure_base, (runs[SCALE_COLUMNS], title))


__all__ = ["SCALE_CAPTION", "SCALE_COLUMNS", "cost_growth_figure", "is_size_ladder", "scale_rows", "scale_section",
           "scale_summary"]
