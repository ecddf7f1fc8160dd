"""The board's figures (docs/DESIGN.md §9): loaded volume against time, performance profiles (per CPU
model and per family), version histories and terrain before and after (a stored plan judged again),
each saved as PNG and SVG by a pool of worker processes while the tables are made."""

from __future__ import annotations

import io
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...results.aggregate import PRIMARY
from ...plotting import mpl_text, planner_colours, pyplot
from ...profiles import cost_matrix, profile
from ...running.scaling import cost_growth_figure
from ...results.store import Store
from .selection import sample_runs
from .tables import slug


def volume_time_figure(runs: pd.DataFrame, title: str):
    """Loaded volume against total execution time (the plan's makespan) per run and planner."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.8), constrained_layout=True)
    have = runs[runs["reason"].isin(["ok", "invalid"]) & runs["makespan_s"].notna()] if "makespan_s" in runs else runs.iloc[:0]
    colours = planner_colours(runs["solver"].unique())
    from matplotlib.lines import Line2D

    handles = []
    for solver, g in have.groupby("solver"):
        c = colours[solver]
        ok = g["reason"] == "ok"
        succ = ok & g["success"].astype(bool)
        ax.scatter(g.loc[succ, "makespan_s"], g.loc[succ, "loaded_volume"], s=18, color=c, zorder=2)
        ax.scatter(g.loc[ok & ~succ, "makespan_s"], g.loc[ok & ~succ, "loaded_volume"], s=18, facecolors="none", edgecolors=c, zorder=2)
        # invalid runs: large, drawn over every valid point so none hides under them
        ax.scatter(g.loc[~ok, "makespan_s"], g.loc[~ok, "loaded_volume"], s=70, color=c, marker="X", edgecolors="k",
                   linewidths=0.6, zorder=4)
        # the legend marker says what the planner has: a filled dot only when some run succeeded
        counts = {"success": int(succ.sum()), "below threshold": int((ok & ~succ).sum()), "invalid": int((~ok).sum())}
        kinds = [k for k, n in counts.items() if n]
        marker = {"success": dict(marker="o", color=c), "below threshold": dict(marker="o", mfc="none", mec=c, color=c),
                  "invalid": dict(marker="X", color=c, mec="k")}[kinds[0]]
        handles.append(Line2D([], [], ls="none", ms=7, **marker,
                              label=mpl_text(f"{solver} ({', '.join(f'{counts[k]} {k}' for k in kinds)})")))
    ax.set_xlabel("total time of the plan (makespan), s")
    ax.set_ylabel("loaded volume, m³")
    ax.set_title(mpl_text(title) + "\nfilled: success; hollow: valid, below threshold; ✕: invalid (drawn on top)", fontsize=9)
    ax.grid(alpha=0.3)
    if len(have):
        ax.legend(handles=handles, fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no plans stored", ha="center", va="center", transform=ax.transAxes)
    return fig


def _draw_profile(ax, rho: pd.DataFrame, colours: dict[str, Any], xlabel: str, title: str) -> None:
    taus = rho.index.to_numpy()
    right = max(2.0, float(taus.max()) * 1.5) if len(taus) else 2.0
    for solver in rho.columns:
        x = np.append(taus, right)
        y = np.append(rho[solver].to_numpy(), rho[solver].to_numpy()[-1] if len(taus) else 0.0)
        ax.step(x, y, where="post", color=colours.get(solver), label=mpl_text(solver))
    ax.set_xscale("log", base=2)
    from matplotlib.ticker import FuncFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # τ = 1, 2, 4, … rather than 2⁰, 2¹, 2²
    ax.set_xlim(1, right)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("fraction of scenarios ρ(τ)")
    ax.set_title(mpl_text(title), fontsize=9)
    ax.grid(alpha=0.3)


def profiles_figure(runs: pd.DataFrame, title: str):
    """Performance profiles over time per target m³ and over solve time (one panel per CPU model)."""
    plt = pyplot()
    colours = planner_colours(runs["solver"].unique())
    models = sorted(runs["cpu_model"].fillna("unknown CPU").unique()) if "cpu_model" in runs else ["unknown CPU"]
    fig, axes = plt.subplots(1, 1 + len(models), figsize=(5.2 * (1 + len(models)), 4.2), constrained_layout=True, squeeze=False)
    axes = axes[0]
    solvers = sorted(runs["solver"].unique())
    c = cost_matrix(runs, PRIMARY).reindex(columns=solvers, fill_value=np.inf)
    _draw_profile(axes[0], profile(c), colours, "τ (time per target m³ within τ × the best)", "time per target m³")
    cpu = runs["cpu_model"].fillna("unknown CPU") if "cpu_model" in runs else pd.Series("unknown CPU", index=runs.index)
    for ax, model in zip(axes[1:], models):
        sub = runs[cpu == model]  # only the planners that ran on this CPU model are compared here
        # the ranked solve-time figure, CPU time, where the runs have it (wall time in stores without it)
        col = "solve_cpu_s" if "solve_cpu_s" in sub and sub["solve_cpu_s"].notna().any() else "solve_time_s"
        word = "solve CPU time" if col == "solve_cpu_s" else "solve time"
        c = cost_matrix(sub, col).reindex(columns=sorted(sub["solver"].unique()), fill_value=np.inf)
        label = word + (f" — only runs on {model}" if len(models) > 1 else "")
        _draw_profile(ax, profile(c), colours, f"τ ({word} within τ × the best)", label)
    axes[0].legend(fontsize=7, loc="lower right")
    fig.suptitle(mpl_text(title) + " — failures count as never solved", fontsize=10)
    return fig


def families_figure(runs: pd.DataFrame, title: str):
    """One performance-profile panel per family over time per target m³ (families differ twofold in scale)."""
    plt = pyplot()
    colours = planner_colours(runs["solver"].unique())
    solvers = sorted(runs["solver"].unique())
    families = sorted(runs["family"].fillna("?").astype(str).unique())
    fig, axes = plt.subplots(1, len(families), figsize=(4.6 * len(families), 4.0), constrained_layout=True, squeeze=False)
    for ax, fam in zip(axes[0], families):
        sub = runs[runs["family"].fillna("?").astype(str) == fam]
        c = cost_matrix(sub, PRIMARY).reindex(columns=solvers, fill_value=np.inf)
        _draw_profile(ax, profile(c), colours, "τ (within τ × the best)", f"{fam} ({sub['scenario_digest'].nunique()} scenarios)")
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.suptitle(mpl_text(title) + " — time per target m³ by family; failures count as never solved", fontsize=10)
    return fig


def history_figure(rows: pd.DataFrame, title: str):
    """Success rate and median time per target m³ (95 % intervals) across one planner's versions."""
    from ...results.aggregate import version_key

    plt = pyplot()
    rows = rows.assign(_k=rows["planner_version"].map(version_key)).sort_values(["_k", "config_hash"], kind="mergesort")
    labels = [f"{v}" + (f"\n[{str(h)[:8]}]" if (rows["planner_version"] == v).sum() > 1 else "")
              for v, h in zip(rows["planner_version"], rows["config_hash"])]
    x = np.arange(len(rows))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    for ax, (col, lo, hi, scale, ylabel) in zip(axes, (
            ("success_rate", "success_rate_lo", "success_rate_hi", 100.0, "success rate, %"),
            ("time_per_target_m3_median", "time_per_target_m3_lo", "time_per_target_m3_hi", 1.0, "time per target m³, s (median)"))):
        y = rows[col].to_numpy(dtype=float) * scale
        with np.errstate(invalid="ignore"):
            err = np.vstack([y - rows[lo].to_numpy(dtype=float) * scale, rows[hi].to_numpy(dtype=float) * scale - y])
        y = np.where(np.isfinite(y), y, np.nan)  # a median short of the target (∞) is not drawn
        err = np.where(np.isfinite(err), np.abs(err), 0.0)  # nor an interval without an end (none at small n, or ∞)
        ax.errorbar(x, y, yerr=err, fmt="o-", capsize=3)
        ax.set_xticks(x, [mpl_text(t) for t in labels], fontsize=8)
        ax.set_xlabel("version")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    fig.suptitle(mpl_text(title) + " — by version, 95 % intervals (exact for rates, order statistics for medians)", fontsize=10)
    return fig


def terrain_figure(scenario_json: str, plan_json: str, title: str):
    """Judge a stored plan again on its scenario and draw :func:`earthbench.running.figures.terrain_before_after`."""
    from ...running.figures import terrain_before_after
    from ...plan import Plan
    from ...referee import judge
    from ...world import Scenario

    scenario = Scenario.from_text(scenario_json)
    plan = Plan.from_json(plan_json)
    verdict = judge(scenario, plan)
    fig = terrain_before_after(scenario, plan, verdict)
    fig.suptitle(mpl_text(title), fontsize=10)
    return fig


#: Columns the run figures read (the frame shipped to a figure worker).
FIGURE_COLUMNS = ["scenario_digest", "family", "solver", "reason", "success", "makespan_s", "loaded_volume", "time_per_m3",
                  PRIMARY, "solve_time_s", "solve_cpu_s", "cpu_model"]


def _render(job: tuple[str, str, tuple[Any, ...]]) -> bytes:
    """Draw one figure and save it as PNG and SVG; return the PNG (runs in a worker process)."""
    kind, base, args = job
    makers: dict[str, Callable[..., Any]] = {
        "volume-time": volume_time_figure, "profiles": profiles_figure, "families": families_figure,
        "history": history_figure, "terrain": terrain_figure, "cost-growth": cost_growth_figure}
    return _save(makers[kind](*args), Path(base))[2]


#: The figure kinds in the order the workers take them: the costliest first (a terrain figure holds two
#: heightmaps, a colour bar and every action of a plan), so no long job is left to run alone at the end.
_HEAVY_FIRST = {"terrain": 0, "profiles": 1, "families": 1, "volume-time": 2, "cost-growth": 3, "history": 4}


class Renderer:
    """Figure jobs drawn in parallel worker processes (fork on Linux) while the caller goes on, e.g.
    computing the tables' intervals and paired tests; in this process when there is one core.

    :meth:`add` queues a job, :meth:`start` hands the queued ones to the workers (heaviest first);
    :meth:`results` draws in this process every job no worker has taken yet, so the caller's core
    is not idle while the workers finish."""

    def __init__(self, workers: int | None = None):
        import multiprocessing as mp
        import os

        n = workers if workers else len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1
        self._jobs: list[tuple[str, str, tuple[Any, ...]]] = []
        self._futures: dict[int, Any] = {}
        self._pool = None
        if n > 1 and "fork" in mp.get_all_start_methods():
            from concurrent.futures import ProcessPoolExecutor

            plt = pyplot()  # load fonts and the mathtext parser once, before the workers fork
            warm = plt.figure()
            warm.text(0.5, 0.5, "m³ τ ρ")
            warm.canvas.draw()
            plt.close(warm)
            self._pool = ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("fork"))

    def add(self, job: tuple[str, str, tuple[Any, ...]]) -> None:
        self._jobs.append(job)

    def start(self) -> None:
        """Give the workers every job queued since the last call, the costliest kinds first."""
        if self._pool is None:
            return
        waiting = [i for i in range(len(self._jobs)) if i not in self._futures]
        for i in sorted(waiting, key=lambda i: _HEAVY_FIRST.get(self._jobs[i][0], 9)):
            self._futures[i] = self._pool.submit(_render, self._jobs[i])

    def results(self) -> list[bytes]:
        """The PNG of every job, in the order added (waits for the workers, then shuts them down)."""
        if self._pool is None:
            return [_render(j) for j in self._jobs]
        self.start()
        try:
            done: dict[int, bytes] = {}
            # one at a time, the last job handed out that no worker has taken yet is drawn here
            while (i := next((i for i, f in reversed(self._futures.items()) if i not in done and f.cancel()), None)) is not None:
                done[i] = _render(self._jobs[i])
            return [done[i] if i in done else self._futures[i].result() for i in range(len(self._jobs))]
        finally:
            self._pool.shutdown()


def _save(fig, base: Path) -> tuple[Path, Path, bytes]:
    """Write ``base.png`` and ``base.svg``; return the paths and the PNG bytes."""
    plt = pyplot()
    engine = fig.get_layout_engine()
    if engine is not None:  # lay out once, not once per format (the same pixels, a fifth less time)
        engine.execute(fig)
        fig.set_layout_engine("none")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    png = buf.getvalue()
    png_path, svg_path = base.parent / (base.name + ".png"), base.parent / (base.name + ".svg")
    png_path.write_bytes(png)
    fig.savefig(svg_path, format="svg", metadata={"Date": None})
    plt.close(fig)
    return png_path, svg_path, png


#: The figures of every table's runs: (kind, caption); ``families`` only when the table has several.
RUN_FIGURES = [("volume-time", "Loaded volume against total time per run (as in the STL-TAMP paper, Fig. 7a)"),
               ("profiles", "Performance profiles: time per target m³ and solve time (failures never solved)"),
               ("families", "Performance profiles of time per target m³, one panel per family")]


def figure_jobs(store: Store, shown: pd.DataFrame, base: Path, title: str, terrain: bool = True,
                scenarios: dict[str, str] | None = None) -> list[tuple[str, tuple[str, str, tuple[Any, ...]]]]:
    """(caption, :class:`Renderer` job) of every figure of one table's ``shown`` runs, files named ``base-KIND``;
    with ``terrain``, one terrain figure per planner (its scenario read from ``store``, cached in ``scenarios``)."""
    scenarios = {} if scenarios is None else scenarios
    cols = shown[[c for c in FIGURE_COLUMNS if c in shown]]
    several = shown["family"].nunique() > 1
    out: list[tuple[str, tuple[str, str, tuple[Any, ...]]]] = [
        (cap, (kind, str(base.parent / f"{base.name}-{kind}"), (cols, title)))
        for kind, cap in RUN_FIGURES if kind != "families" or several]
    if not terrain:
        return out
    for _, run in sample_runs(shown).iterrows():
        digest = run["scenario_digest"]
        if digest not in scenarios:
            sc = store.scenario(digest)
            if sc.digest != digest:  # never draw a plan on a terrain it was not made for
                warnings.warn(f"stored scenario {run['scenario_id']} does not reproduce its digest; "
                              "no terrain figure for it", stacklevel=4)  # the caller of publish()
                continue
            scenarios[digest] = sc.to_json()
        plan = store.plan_json(int(run["id"]))
        path = base.parent / f"{base.name}-terrain-{slug(str(run['solver']))}"
        out.append((f"Terrain before and after: {run['solver']} on {run['scenario_id']} (run {run['id']})",
                    ("terrain", str(path), (scenarios[digest], plan, f"{run['solver']} on {run['scenario_id']}"))))
    return out


__all__ = ["FIGURE_COLUMNS", "RUN_FIGURES", "Renderer", "families_figure", "figure_jobs", "history_figure", "profiles_figure",
           "terrain_figure", "volume_time_figure"]
