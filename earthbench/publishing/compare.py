"""Paired comparison of two planner configurations on shared scenarios (``earthbench compare``).

For a planner author checking a change, or CI guarding one: runs of configuration A and of
configuration B are paired by scenario digest (same terrain, task and budget). For each
metric, over the pairs where both values are known (infinite counts: a run short of the target
has an infinite time per target m³, and ranks after every finite one), the table gives both
medians, the effect size — the median of the differences ``B − A`` with its distribution-free
95 % interval (:func:`earthbench.stats.median_ci`; none below 6 pairs) — the mean
difference, and the two-sided Wilcoxon signed-rank test (:func:`earthbench.stats.wilcoxon_p`,
zero differences dropped). The p-values are Holm-adjusted across the metrics of the table
(family-wise error ≤ alpha), and the verdict uses the adjusted value. Success is compared
with an exact McNemar test (not part of the Holm family: it is its own question).

A verdict says whether B is better or worse at the chosen level, by the metric's direction
(:data:`DIRECTION`). When n pairs cannot reach alpha at all (the exact signed-rank test's
smallest two-sided p is 2 / 2ⁿ: 0.125 for 4 pairs), the report says so rather than leaving
"no significant difference" to be read as "no difference". Solve times from different CPU
models are flagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..errors import EarthbenchError
from ..stats import (INTERVAL_NOTE, holm, mcnemar_p, median_ci, min_separating_n, min_wilcoxon_p, paired_differences,
                    separation_note, wilcoxon_p)

#: +1 where higher is better, −1 where lower is better.
DIRECTION = {
    "volume_ratio": +1, "loaded_volume": +1, "mean_bucket_fill": +1,
    "time_per_target_m3": -1, "time_per_target_m3_ratio": -1, "time_to_target_s": -1, "overshoot_m3": -1,
    "time_per_m3": -1, "time_per_m3_ratio": -1, "makespan_s": -1, "solve_time_s": -1, "solve_cpu_s": -1,
    "travel_m": -1, "digs": -1, "peak_rss_mb": -1,
}
DEFAULT_METRICS = ("volume_ratio", "time_per_target_m3", "time_per_target_m3_ratio", "time_per_m3", "overshoot_m3",
                   "makespan_s", "solve_time_s", "solve_cpu_s", "digs", "mean_bucket_fill", "travel_m")
#: The name ``--fail-on-regression`` takes for the McNemar comparison of success.
SUCCESS = "success"


class CompareError(EarthbenchError):
    """The two sides cannot be compared (unknown planner, ambiguous selection, no shared scenario)."""


@dataclass(frozen=True)
class Selector:
    """``PLANNER[@VERSION][#CONFIG_HASH_PREFIX]`` or ``LABEL[@VERSION]`` (e.g. ``greedy[closed_loop]@1.1``,
    :mod:`earthbench.results.labels`); None parts match anything. A planner name that is also the label of one
    of its configurations (the one at its defaults) names that configuration."""

    planner: str | None = None
    version: str | None = None
    config: str | None = None

    @classmethod
    def parse(cls, text: str | None) -> Selector:
        if not text:
            return cls()
        rest, _, config = text.partition("#")
        planner, _, version = rest.rpartition("@") if "@" in rest.rpartition("]")[2] else (rest, "", "")
        return cls(planner or None, version or None, config or None)

    def pick(self, runs: pd.DataFrame, side: str) -> pd.DataFrame:
        """The runs of exactly one (planner, version, config); with no version named, each
        configuration's latest (as boards rank); an error lists the choices otherwise."""
        from ..results.labels import config_labels

        names = config_labels(runs)
        label = pd.Series([names.get((str(p), str(c)), str(p)) for p, c in zip(runs["planner"], runs["config_hash"])],
                          index=runs.index, dtype=object)
        m = pd.Series(True, index=runs.index)
        if self.planner is not None:
            m &= (runs["planner"] == self.planner) | (label == self.planner)
        if self.version is not None:
            m &= runs["planner_version"].astype(str) == self.version
        if self.config is not None:
            m &= runs["config_hash"].astype(str).str.startswith(self.config)

        def keys_of(mask: pd.Series) -> list[tuple[str, str, str, str]]:
            sub = runs[mask]
            return sorted({(str(p), str(v), str(c), str(lab)) for p, v, c, lab
                           in zip(sub["planner"], sub["planner_version"], sub["config_hash"], label[mask])})

        keys = keys_of(m)
        if len(keys) > 1 and self.planner is not None and (m & (label == self.planner)).any():
            m &= label == self.planner  # the name is also a configuration's label: that configuration
            keys = keys_of(m)
        if len(keys) > 1 and self.version is None:
            m &= _latest_versions(runs, m)  # no version named: each configuration's latest, as boards rank
            keys = keys_of(m)
        if not keys:
            choices = ", ".join(_choice(k) for k in keys_of(pd.Series(True, index=runs.index))) or "(none)"
            raise CompareError(f"side {side}: no runs match {self}; stored configurations: {choices}")
        if len(keys) > 1:
            raise CompareError(f"side {side}: {self} matches several configurations: {', '.join(_choice(k) for k in keys)}; "
                               f"name one with --{side.lower()} LABEL@VERSION or PLANNER@VERSION#CONFIG")
        return runs[m].assign(config_label=keys[0][3])

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
    alpha: float = 0.05
    notes: list[str] = field(default_factory=list)

    def regressions(self, metrics: tuple[str, ...]) -> list[str]:
        """The metrics among ``metrics`` (``success`` included) on which B is significantly worse."""
        worse = set(self.table.loc[self.table["verdict"] == "B worse", "metric"]) if len(self.table) else set()
        s = self.success
        if s["p_value"] < self.alpha and s["rate_b"] < s["rate_a"]:
            worse.add(SUCCESS)
        return [m for m in metrics if m in worse]


def _latest_versions(runs: pd.DataFrame, mask: pd.Series) -> pd.Series:
    """Rows of ``mask`` whose version is the latest of their planner and settings among ``mask``
    (the settings as stored, so that a hash that also covers the version still groups them)."""
    from ..results.aggregate import version_key

    settings = runs["config" if "config" in runs else "config_hash"].fillna("").astype(str)
    sub = runs[mask].assign(settings=settings[mask])
    latest = sub.groupby(["planner", "settings"])["planner_version"].agg(lambda v: max(map(str, v.unique()), key=version_key))
    want = pd.Series([latest.get((p, c)) for p, c in zip(runs["planner"], settings)], index=runs.index)
    return mask & (runs["planner_version"].astype(str) == want)


def _choice(key: tuple[str, str, str, str]) -> str:
    planner, version, config, label = key
    return f"{label}@{version} (#{config[:8]})"


def _label(runs: pd.DataFrame) -> str:
    r = runs.iloc[0]
    name = r["config_label"] if "config_label" in runs else r["planner"]
    return f"{name} {r['planner_version']} (#{str(r['config_hash'])[:8]})"


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
        ok = ~np.isnan(x) & ~np.isnan(y)
        n = int(ok.sum())
        d = paired_differences(x[ok], y[ok])
        stat, p = wilcoxon_p(d) if n else (math.nan, math.nan)
        lo, hi = median_ci(d) if n else (math.nan, math.nan)
        rows.append({
            "metric": m, "pairs": n, "nonzero": int((d != 0).sum()), "dropped": int(len(shared) - n),
            "median_a": float(np.median(x[ok])) if n else math.nan, "median_b": float(np.median(y[ok])) if n else math.nan,
            "median_diff": float(np.median(d)) if n else math.nan, "median_diff_lo": lo, "median_diff_hi": hi,
            "mean_diff": _mean(d) if n else math.nan, "wilcoxon_w": stat, "p_value": p,
        })
    table = pd.DataFrame(rows, columns=["metric", "pairs", "nonzero", "dropped", "median_a", "median_b", "median_diff",
                                        "median_diff_lo", "median_diff_hi", "mean_diff", "wilcoxon_w", "p_value"])
    table["p_holm"] = holm(table["p_value"].tolist()) if len(table) else []
    table["verdict"] = [_verdict(r, alpha) for r in table.itertuples()]
    sa = a1["success"].fillna(False).astype(bool).to_numpy()
    sb = b1["success"].fillna(False).astype(bool).to_numpy()
    success = {"both": int((sa & sb).sum()), "only_a": int((sa & ~sb).sum()), "only_b": int((~sa & sb).sum()),
               "neither": int((~sa & ~sb).sum()), "rate_a": float(sa.mean()), "rate_b": float(sb.mean()),
               "p_value": mcnemar_p(sa, sb)}
    note = ""
    if "cpu_model" in a1 and "cpu_model" in b1:
        ca, cb = set(a1["cpu_model"].dropna()), set(b1["cpu_model"].dropna())
        if ca != cb or len(ca) > 1:
            note = (f"solve times come from different CPU models (A: {', '.join(sorted(ca)) or '?'}; "
                    f"B: {', '.join(sorted(cb)) or '?'}): their differences mix planner and machine")
    notes = _power_notes(table, alpha)
    if len(shared) < min_separating_n(alpha):
        notes.insert(0, separation_note(len(shared), alpha))
    return Comparison(_label(a), _label(b), len(shared), int(a["scenario_digest"].nunique() - len(shared)),
                      int(b["scenario_digest"].nunique() - len(shared)), table, success, note, alpha, notes)


def _mean(d: np.ndarray) -> float:
    """Mean difference; NaN where infinities of both signs meet (no mean exists)."""
    with np.errstate(invalid="ignore"):
        return float(d.mean())


def _verdict(r: Any, alpha: float) -> str:
    if not r.pairs or math.isnan(r.p_holm):
        return "no pairs"
    if r.p_holm >= alpha:
        return "no significant difference"
    sign = DIRECTION.get(r.metric, 0)
    toward = r.median_diff if r.median_diff != 0 else r.mean_diff
    if math.isnan(toward):
        return "no direction"
    if sign == 0:
        return "B higher" if toward > 0 else "B lower"
    return "B better" if toward * sign > 0 else "B worse"


def _power_notes(table: pd.DataFrame, alpha: float) -> list[str]:
    """Say where n pairs can never reach alpha (after the Holm factor of the table's size)."""
    m = max(int(table["p_value"].notna().sum()), 1)
    by_n: dict[int, list[str]] = {}
    for r in table.itertuples():
        if r.pairs and min_wilcoxon_p(int(r.nonzero)) * m >= alpha:
            by_n.setdefault(int(r.nonzero), []).append(str(r.metric))
    return [f"{', '.join(names)}: with {n} non-zero pair(s) the smallest possible p is {min_wilcoxon_p(n):.3g}"
            + (f" (× {m} metrics for Holm)" if m > 1 else "")
            + f", never below α = {alpha:g}: no difference can be significant here; compare on more scenarios"
            for n, names in sorted(by_n.items())]


def _cells(c: Comparison) -> tuple[list[str], list[list[str]]]:
    def f(v: float) -> str:
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return "–"
        return f"{v:.4g}"

    head = ["metric", "pairs", "median A", "median B", "median B−A [95% CI]", "mean B−A", "Wilcoxon p", "Holm p",
            f"verdict (α = {c.alpha:g})"]
    body = []
    for r in c.table.itertuples():
        effect = f(r.median_diff) + ("" if math.isnan(r.median_diff_lo) else f" [{f(r.median_diff_lo)}, {f(r.median_diff_hi)}]")
        body.append([r.metric, f"{r.pairs}" + (f" (−{r.dropped})" if r.dropped else ""), f(r.median_a), f(r.median_b),
                     effect, f(r.mean_diff), f(r.p_value), f(r.p_holm), r.verdict])
    return head, body


def _lines(c: Comparison) -> tuple[list[str], str, list[str]]:
    s = c.success
    head = [f"A: {c.label_a}", f"B: {c.label_b}",
            f"{c.pairs} shared scenario(s); {c.only_a} only in A, {c.only_b} only in B (not compared)"]
    succ = (f"success: A {100 * s['rate_a']:.0f}%, B {100 * s['rate_b']:.0f}% — both {s['both']}, only A {s['only_a']}, "
            f"only B {s['only_b']}, neither {s['neither']}; exact McNemar p = {s['p_value']:.3g}")
    tail = ["(−n: pairs dropped because a value is missing, e.g. no plan; an infinite time (short of the target, or nothing "
            "loaded) is kept and ranks last; p-values Holm-adjusted across the metrics of the table; "
            f"{INTERVAL_NOTE}: here of the median difference)"]
    tail += [f"warning: {n}" for n in c.notes]
    if c.cpu_note:
        tail.append(f"note: {c.cpu_note}")
    return head, succ, tail


def format_comparison(c: Comparison, alpha: float | None = None, fmt: str = "text") -> str:
    """A report of a :class:`Comparison`: plain text, or Markdown (``fmt="markdown"``, e.g. for a CI comment)."""
    if alpha is not None:
        c.alpha = alpha
    head, body = _cells(c)
    top, succ, tail = _lines(c)
    if fmt == "markdown":
        from .board.tables import md_escape

        lines = [f"- {md_escape(t)}" for t in top] + ["", md_escape(succ), "",
                 "| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 2) + "---|"]
        lines += ["| " + " | ".join(md_escape(x) for x in row) + " |" for row in body]
        return "\n".join(lines + [""] + [md_escape(t) for t in tail])
    table = [head, *body]
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    lines = [*top, "", succ, ""]
    for n, row in enumerate(table):
        lines.append("  ".join(cell.ljust(w) if i in (0, len(head) - 1) else cell.rjust(w)
                               for i, (cell, w) in enumerate(zip(row, widths))).rstrip())
        if n == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines + tail)
