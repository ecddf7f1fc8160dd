"""Paired comparison of two planner configurations on shared scenarios (``earthbench compare``).

For a planner author checking a change: runs of configuration A and of configuration B are
paired by scenario digest (same terrain, task and budget). For each metric, over the pairs
where both values are finite, the table gives both medians, the median and mean of the
differences ``B − A``, and the two-sided Wilcoxon signed-rank test (``scipy.stats.wilcoxon``,
zero differences dropped; p = 1 when every difference is zero). Success is compared with an
exact McNemar test (a binomial test on the pairs where exactly one of the two succeeded).

A verdict says whether B is better or worse at the chosen significance level, by the
metric's direction (:data:`DIRECTION`). Solve times from different CPU models are flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .errors import EarthbenchError

#: +1 where higher is better, −1 where lower is better.
DIRECTION = {
    "volume_ratio": +1, "loaded_volume": +1, "mean_bucket_fill": +1,
    "time_per_m3": -1, "time_per_m3_ratio": -1, "makespan_s": -1, "solve_time_s": -1, "solve_cpu_s": -1,
    "travel_m": -1, "digs": -1, "peak_rss_mb": -1,
}
DEFAULT_METRICS = ("volume_ratio", "time_per_m3", "time_per_m3_ratio", "makespan_s", "solve_time_s", "solve_cpu_s",
                   "digs", "mean_bucket_fill", "travel_m")


class CompareError(EarthbenchError):
    """The two sides cannot be compared (unknown planner, ambiguous selection, no shared scenario)."""


@dataclass(frozen=True)
class Selector:
    """``PLANNER[@VERSION][#CONFIG_HASH_PREFIX]``; None parts match anything."""

    planner: str | None = None
    version: str | None = None
    config: str | None = None

    @classmethod
    def parse(cls, text: str | None) -> Selector:
        if not text:
            return cls()
        rest, _, config = text.partition("#")
        planner, _, version = rest.rpartition("@") if "@" in rest else (rest, "", "")
        return cls(planner or None, version or None, config or None)

    def pick(self, runs: pd.DataFrame, side: str) -> pd.DataFrame:
        """The runs of exactly one (planner, version, config); an error lists the choices otherwise."""
        m = pd.Series(True, index=runs.index)
        if self.planner is not None:
            m &= runs["planner"] == self.planner
        if self.version is not None:
            m &= runs["planner_version"].astype(str) == self.version
        if self.config is not None:
            m &= runs["config_hash"].astype(str).str.startswith(self.config)
        sel = runs[m]
        keys = sorted({(r.planner, str(r.planner_version), r.config_hash) for r in sel[["planner", "planner_version", "config_hash"]].itertuples()})
        choices = sorted({f"{p}@{v}#{c[:8]}" for p, v, c in runs[["planner", "planner_version", "config_hash"]].itertuples(index=False)})
        if not keys:
            raise CompareError(f"side {side}: no runs match {self}; stored configurations: {', '.join(choices) or '(none)'}")
        if len(keys) > 1:
            found = ", ".join(f"{p}@{v}#{c[:8]}" for p, v, c in keys)
            raise CompareError(f"side {side}: {self} matches several configurations ({found}); "
                               f"name one as PLANNER@VERSION#CONFIG with --{side.lower()}")
        return sel

    def __str__(self) -> str:
        s = self.planner or "*"
        if self.version:
            s += f"@{self.version}"
        if self.config:
            s += f"#{self.config}"
        return s


@dataclass
class Comparison:
    """The per-metric table (:attr:`table`) and what was compared."""

    label_a: str
    label_b: str
    pairs: int
    only_a: int
    only_b: int
    table: pd.DataFrame
    success: dict[str, float]
    cpu_note: str = ""


def _label(runs: pd.DataFrame) -> str:
    r = runs.iloc[0]
    return f"{r['planner']} {r['planner_version']} [{str(r['config_hash'])[:8]}]"


def _wilcoxon(d: np.ndarray) -> tuple[float, float]:
    from scipy.stats import wilcoxon

    nz = d[d != 0]
    if len(nz) == 0:
        return 0.0, 1.0
    res = wilcoxon(nz, zero_method="wilcox", alternative="two-sided")
    return float(res.statistic), float(res.pvalue)


def compare(a: pd.DataFrame, b: pd.DataFrame, metrics: tuple[str, ...] = DEFAULT_METRICS, alpha: float = 0.05) -> Comparison:
    """Compare the runs of one configuration (``a``) with those of another (``b``), paired by scenario."""
    if a.empty or b.empty:
        raise CompareError("one side has no runs")
    a1 = a.drop_duplicates("scenario_digest").set_index("scenario_digest")
    b1 = b.drop_duplicates("scenario_digest").set_index("scenario_digest")
    shared = a1.index.intersection(b1.index)
    if len(shared) == 0:
        raise CompareError("the two sides share no scenario (same terrain, task and budget); run them on the same suite")
    a1, b1 = a1.loc[shared], b1.loc[shared]
    rows = []
    for m in metrics:
        if m not in a1 or m not in b1:
            continue
        x = pd.to_numeric(a1[m], errors="coerce").to_numpy(dtype=float)
        y = pd.to_numeric(b1[m], errors="coerce").to_numpy(dtype=float)
        ok = np.isfinite(x) & np.isfinite(y)
        n = int(ok.sum())
        d = y[ok] - x[ok]
        stat, p = _wilcoxon(d) if n else (math.nan, math.nan)
        sign = DIRECTION.get(m, 0)
        med = float(np.median(d)) if n else math.nan
        if not n or math.isnan(p):
            verdict = "no pairs"
        elif p >= alpha:
            verdict = "no significant difference"
        elif sign == 0:
            verdict = "B higher" if med > 0 or (med == 0 and d.mean() > 0) else "B lower"
        else:
            better = (np.sign(med if med != 0 else d.mean()) * sign) > 0
            verdict = "B better" if better else "B worse"
        rows.append({
            "metric": m, "pairs": n, "dropped": int(len(shared) - n),
            "median_a": float(np.median(x[ok])) if n else math.nan, "median_b": float(np.median(y[ok])) if n else math.nan,
            "median_diff": med, "mean_diff": float(d.mean()) if n else math.nan,
            "wilcoxon_w": stat, "p_value": p, "verdict": verdict,
        })
    sa = a1["success"].fillna(False).astype(bool).to_numpy()
    sb = b1["success"].fillna(False).astype(bool).to_numpy()
    only_a, only_b = int((sa & ~sb).sum()), int((~sa & sb).sum())
    if only_a + only_b:
        from scipy.stats import binomtest

        p_s = float(binomtest(only_b, only_a + only_b, 0.5).pvalue)
    else:
        p_s = 1.0
    success = {"both": int((sa & sb).sum()), "only_a": only_a, "only_b": only_b, "neither": int((~sa & ~sb).sum()),
               "rate_a": float(sa.mean()), "rate_b": float(sb.mean()), "p_value": p_s}
    note = ""
    if "cpu_model" in a1 and "cpu_model" in b1:
        ca, cb = set(a1["cpu_model"].dropna()), set(b1["cpu_model"].dropna())
        if ca != cb or len(ca) > 1:
            note = (f"solve times come from different CPU models (A: {', '.join(sorted(ca)) or '?'}; "
                    f"B: {', '.join(sorted(cb)) or '?'}): their differences mix planner and machine")
    return Comparison(_label(a), _label(b), len(shared), int(a["scenario_digest"].nunique() - len(shared)),
                      int(b["scenario_digest"].nunique() - len(shared)), pd.DataFrame(rows), success, note)


def format_comparison(c: Comparison, alpha: float = 0.05) -> str:
    """A plain-text report of a :class:`Comparison`."""
    def f(v: float) -> str:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return "–"
        return f"{v:.4g}"

    lines = [f"A: {c.label_a}", f"B: {c.label_b}",
             f"{c.pairs} shared scenario(s); {c.only_a} only in A, {c.only_b} only in B (not compared)", ""]
    s = c.success
    lines.append(f"success: A {100 * s['rate_a']:.0f}%, B {100 * s['rate_b']:.0f}% — both {s['both']}, only A {s['only_a']}, "
                 f"only B {s['only_b']}, neither {s['neither']}; exact McNemar p = {s['p_value']:.3g}")
    lines.append("")
    head = ["metric", "pairs", "median A", "median B", "median B−A", "mean B−A", "Wilcoxon p", f"verdict (α = {alpha:g})"]
    table = [head]
    for r in c.table.itertuples():
        table.append([r.metric, f"{r.pairs}" + (f" (−{r.dropped})" if r.dropped else ""), f(r.median_a), f(r.median_b),
                      f(r.median_diff), f(r.mean_diff), f(r.p_value), r.verdict])
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    for n, row in enumerate(table):
        lines.append("  ".join(cell.ljust(w) if i in (0, 7) else cell.rjust(w) for i, (cell, w) in enumerate(zip(row, widths))).rstrip())
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    lines.append("(−n: pairs dropped because a value is missing or infinite, e.g. no plan or nothing loaded)")
    if c.cpu_note:
        lines.append(f"note: {c.cpu_note}")
    return "\n".join(lines)
