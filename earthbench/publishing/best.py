"""The best known plan of every scenario of a suite (docs/publishing.md "Best known plans").

One compressed JSON file per scenario, ``DIR/<suite>/<scenario digest>.json.gz``, holds the
fastest valid plan anyone has produced for it — any planner, any run, or a constructive
witness — with its time to the target and time per target m³ as the referee judged it, the
target bound beside it (the scenario's bracket [bound, best known]), the referee's rules
version, who produced it and when. Nothing is kept by hand: :func:`update` re-judges every
candidate (a store's plans or plan files) on the suite's own scenarios, matched by digest, and
keeps one only when it is valid under this earthbench's rules, reaches the target, and is
strictly faster; :func:`check` re-judges every kept plan. As OR instance libraries (MIPLIB,
TSPLIB) keep their best known solutions, so a newcomer sees how far from the best anything is.

A candidate file is a JSON object (optionally gzip-compressed) with ``scenario_digest`` and
``plan`` (the plan document); ``producer`` names who made it. A kept file is a candidate file
too. Figures a candidate states (``time_to_target_s``, ``time_per_target_m3``, ``rules``) must
be what re-judging gives under today's rules, or it is refused as tampered or stale.
"""

from __future__ import annotations

import gzip
import json
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, UTC
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import EarthbenchError
from ..results.store import Store
from ..results.suite import Suite
from .verify import rejudge, same
from ..world import Scenario

#: The format tag of a kept file.
FORMAT = "earthbench-best/1"
#: Where the committed best known plans live, relative to the project's root.
DEFAULT_DIR = Path("leaderboard") / "best"
#: The figures a kept file records as the referee judged them (checked by :func:`check`).
FIGURES = ("time_to_target_s", "time_per_target_m3", "time_per_target_m3_lower_bound")


class BestError(EarthbenchError):
    """A best-known folder or candidate that cannot be read."""


@dataclass(frozen=True)
class Candidate:
    """A plan offered as the best known of one scenario, with what it claims (``stated``) and who made it."""

    scenario_digest: str
    plan_json: str
    producer: dict[str, Any]
    stated: dict[str, Any] = field(default_factory=dict)
    source: str = ""  #: where it came from (a file, a store's run), for the report


@dataclass
class Outcome:
    """What :func:`update` did: kept candidates, refusals (with why), entries dropped as stale or refreshed."""

    accepted: list[str] = field(default_factory=list)
    refused: list[tuple[Candidate, str]] = field(default_factory=list)
    not_better: int = 0
    dropped: list[str] = field(default_factory=list)
    refreshed: list[str] = field(default_factory=list)  #: kept entries whose target bound was re-recorded
    judged: int = 0


def _rules() -> int:
    from ..referee import RULES_VERSION

    return RULES_VERSION


def entry_path(root: str | Path, suite: str, digest: str) -> Path:
    return Path(root) / suite / f"{digest}.json.gz"


def read_doc(path: Path) -> dict[str, Any]:
    """A kept or candidate file's JSON object (gzip or plain)."""
    try:
        raw = path.read_bytes()
        text = gzip.decompress(raw).decode() if raw[:2] == b"\x1f\x8b" else raw.decode()
        doc = json.loads(text)
    except (OSError, ValueError, EOFError) as exc:
        raise BestError(f"{path}: cannot read a best-known or candidate file: {exc}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("scenario_digest"), str) or "plan" not in doc:
        raise BestError(f"{path}: not a candidate file (a JSON object with scenario_digest and plan)")
    return doc


def write_doc(path: Path, doc: dict[str, Any]) -> None:
    """Compressed, byte-for-byte reproducible (no timestamp in the gzip header): small diffs in git."""
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)
    path.write_bytes(gzip.compress(text.encode(), compresslevel=9, mtime=0))


def kept(root: str | Path, suite: str) -> dict[str, dict[str, Any]]:
    """The kept entries of one suite, by scenario digest (empty when the folder does not exist)."""
    folder = Path(root) / suite
    out = {}
    for path in sorted(folder.glob("*.json.gz")) if folder.is_dir() else ():
        doc = read_doc(path)
        if path.name != f"{doc['scenario_digest']}.json.gz":
            raise BestError(f"{path}: holds the plan of scenario {doc['scenario_digest'][:12]}…; a kept file is named by its digest")
        out[doc["scenario_digest"]] = doc
    return out


def all_kept(root: str | Path) -> dict[str, dict[str, Any]]:
    """Every kept entry of every suite folder, by scenario digest (a scenario in two suites is one problem)."""
    out: dict[str, dict[str, Any]] = {}
    if Path(root).is_dir():
        for folder in sorted(p for p in Path(root).iterdir() if p.is_dir()):
            for digest, doc in kept(root, folder.name).items():
                if digest not in out or doc["time_per_target_m3"] < out[digest]["time_per_target_m3"]:
                    out[digest] = doc
    return out


def _candidate(doc: dict[str, Any], source: str) -> Candidate:
    plan = doc["plan"]
    plan_json = plan if isinstance(plan, str) else json.dumps(plan)
    stated = {k: doc[k] for k in (*FIGURES[:2], "rules") if k in doc}
    given = doc.get("producer")
    producer: dict[str, Any] = given if isinstance(given, dict) else {"name": str(given or "unknown")}
    return Candidate(doc["scenario_digest"], plan_json, producer, stated, source)


def file_candidates(paths: Iterable[str | Path]) -> Iterator[Candidate]:
    """Candidates from plan files (``*.json`` or ``*.json.gz``), or every such file of a folder."""
    for p in map(Path, paths):
        files = sorted([*p.rglob("*.json"), *p.rglob("*.json.gz")]) if p.is_dir() else [p]
        for f in files:
            yield _candidate(read_doc(f), str(f))


def store_candidates(store: Store, digests: set[str]) -> Iterator[Candidate]:
    """Every stored plan of these scenarios: its figures are never read, only its rules version and producer."""
    for row in store.runs():
        if row["scenario_digest"] not in digests or row["plan"] is None:
            continue
        plan_json = store.plan_json(int(row["id"]))
        if plan_json is None:
            continue
        producer = {"kind": "planner", "planner": row["planner"], "version": row["planner_version"],
                    "config_hash": row["config_hash"], "config": _config(store, row["planner_config_id"])}
        yield Candidate(row["scenario_digest"], plan_json, producer, {"rules": row["rules"]},
                        f"{store.path} run {row['id']} ({row['planner']} {row['planner_version']})")


def _config(store: Store, config_id: int | None) -> dict[str, Any]:
    row = store.planner_config(config_id)
    try:
        return json.loads(row["config"]) if row is not None else {}
    except ValueError:
        return {}


def judged_figures(scenario: Scenario, plan_json: str, threshold: float) -> tuple[dict[str, Any] | None, str]:
    """The kept figures of a plan re-judged now, or None and why it cannot be a best known plan."""
    j = rejudge(scenario, plan_json, threshold)
    if j.reason != "ok" or j.metrics is None:
        rules = sorted({v["rule"] for v in j.violations})
        return None, f"{j.reason}" + (f" ({', '.join(rules)})" if rules else "")
    if not math.isfinite(float(j.metrics["time_to_target_s"])):
        return None, "short of the target"
    return {k: float(j.metrics[k]) for k in FIGURES}, ""


def _refusal(c: Candidate, scenarios: dict[str, Scenario], threshold: float) -> tuple[dict[str, Any] | None, str]:
    """The candidate's figures re-judged, or why it is refused (another scenario, older rules, invalid, tampered)."""
    if c.scenario_digest not in scenarios:
        return None, f"scenario {c.scenario_digest[:12]}… is not one of the suite's"
    if "rules" in c.stated and c.stated["rules"] != _rules():
        return None, f"judged under rules {c.stated['rules']}, this earthbench judges under {_rules()}"
    figures, why = judged_figures(scenarios[c.scenario_digest], c.plan_json, threshold)
    if figures is None:
        return None, why
    wrong = [k for k, v in c.stated.items() if k != "rules" and not same(v, figures[k])]
    if wrong:
        return None, "figures that re-judging does not give: " + ", ".join(f"{k} {c.stated[k]} (re-judged {figures[k]:.6g})" for k in wrong)
    return figures, ""


def update(root: str | Path, suite: Suite, candidates: Iterable[Candidate], *, now: str | None = None) -> Outcome:
    """Keep each candidate that is valid under today's rules, reaches the target and beats the kept plan.

    The kept entries are judged again first (:func:`_settle`): those no longer known valid are
    dropped, and a changed target bound is re-recorded.
    """
    now = now or datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    scenarios = {sc.digest: sc for sc in suite.scenarios}
    out = Outcome()
    best = _settle(root, suite, scenarios, out)
    for c in candidates:
        out.judged += 1
        figures, why = _refusal(c, scenarios, suite.success_threshold)
        if figures is None:
            out.refused.append((c, why))
            continue
        old = best.get(c.scenario_digest)
        if old is not None and not figures["time_to_target_s"] < float(old["time_to_target_s"]):
            out.not_better += 1
            continue
        sc = scenarios[c.scenario_digest]
        doc = {"format": FORMAT, "suite": suite.name, "scenario_digest": sc.digest, "scenario_id": sc.id,
               "family": sc.meta.get("family"), "seed": sc.meta.get("seed"), "target_volume": sc.task.target_volume,
               **figures, "rules": _rules(), "producer": c.producer, "recorded": now, "plan": json.loads(c.plan_json)}
        write_doc(entry_path(root, suite.name, sc.digest), doc)
        best[sc.digest] = doc
        out.accepted.append(f"{sc.id}: {figures['time_per_target_m3']:.3f} s/m³"
                            + (f" (was {float(old['time_per_target_m3']):.3f})" if old is not None else "") + f" from {c.source}")
    return out


def _settle(root: str | Path, suite: Suite, scenarios: dict[str, Scenario], out: Outcome) -> dict[str, dict[str, Any]]:
    """The kept entries that still hold: one for another scenario, judged under other rules, or that
    re-judges invalid or with other times is dropped (deleted); one whose target bound moved (a
    metric's change, not the plan's) is written again with the new bound."""
    best = kept(root, suite.name)
    for digest, doc in list(best.items()):
        path = entry_path(root, suite.name, digest)
        figures, why = _refusal(_candidate(doc, path.name), scenarios, suite.success_threshold)
        if figures is None or doc.get("rules") != _rules():
            path.unlink()
            del best[digest]
            out.dropped.append(f"{doc.get('scenario_id') or digest[:12]}: {why or 'no rules version recorded'}")
        elif not same(doc.get("time_per_target_m3_lower_bound"), figures["time_per_target_m3_lower_bound"]):
            best[digest] = {**doc, "time_per_target_m3_lower_bound": figures["time_per_target_m3_lower_bound"]}
            write_doc(path, best[digest])
            out.refreshed.append(f"{doc.get('scenario_id')}: target bound {doc.get('time_per_target_m3_lower_bound')} → "
                                 f"{figures['time_per_target_m3_lower_bound']:.6g}")
    return best


def check(root: str | Path, suite: Suite) -> tuple[int, list[str]]:
    """Re-judge every kept plan of ``suite``: how many were checked, and one line per entry that does not hold."""
    scenarios = {sc.digest: sc for sc in suite.scenarios}
    problems = []
    entries = kept(root, suite.name)
    for digest, doc in entries.items():
        where = entry_path(root, suite.name, digest).name
        c = _candidate(doc, where)
        figures, why = _refusal(c, scenarios, suite.success_threshold)
        if figures is None:
            problems.append(f"{where}: {why}")
        elif not same(doc.get("time_per_target_m3_lower_bound"), figures["time_per_target_m3_lower_bound"]):
            problems.append(f"{where}: target bound {doc.get('time_per_target_m3_lower_bound')} "
                            f"(re-judged {figures['time_per_target_m3_lower_bound']:.6g})")
        elif doc.get("rules") is None:
            problems.append(f"{where}: no rules version recorded")
    return len(entries), problems


def producer_text(producer: dict[str, Any]) -> str:
    """Who produced a kept plan, in one line: ``greedy 1.3 (config 1a2b3c4d)`` or the witness's name."""
    if producer.get("kind") == "planner":
        return f"{producer.get('planner')} {producer.get('version')} (config {str(producer.get('config_hash', ''))[:8]})"
    return str(producer.get("name") or producer.get("kind") or "unknown")




# -- on the boards (earthbench.publishing.publish) ---------------------------------------------------------

#: The per-run column of the boards: time per target m³ over the scenario's best known one.
BEST_RATIO = "time_per_target_m3_best_ratio"


def with_best_known(runs: pd.DataFrame, root: str | Path | None) -> pd.DataFrame:
    """``runs`` with each scenario's best known time per target m³ (``best_known_s_per_m3``) and each
    run's ratio to it (:data:`BEST_RATIO`); NaN where none is kept, unchanged without ``root``."""
    if root is None or not len(runs):
        return runs
    best = {d: float(doc["time_per_target_m3"]) for d, doc in all_kept(root).items()}
    known = runs["scenario_digest"].map(best).astype(float)
    tpt = pd.to_numeric(runs["time_per_target_m3"], errors="coerce") if "time_per_target_m3" in runs else math.nan
    return runs.assign(best_known_s_per_m3=known, **{BEST_RATIO: tpt / known})


def bracket_table(root: str | Path | None, scenarios: pd.DataFrame) -> pd.DataFrame:
    """Each scenario's bracket [target bound, best known] per target m³ (``best.csv``), for the
    ``scenarios`` (columns ``suite``, ``scenario_id``, ``scenario_digest``, ``family``,
    ``target_volume``) that have a kept plan in any suite folder: a scenario is one problem by its
    digest, so a board of ``bench`` reads the plans kept for ``standard``, which includes it."""
    best = all_kept(root) if root is not None else {}
    rows = []
    if not best or not len(scenarios):
        return pd.DataFrame(columns=BRACKET_COLUMNS)
    for r in scenarios.drop_duplicates(["suite", "scenario_digest"]).itertuples(index=False):
        doc = best.get(str(r.scenario_digest))
        if doc is None:
            continue
        bound, known = float(doc["time_per_target_m3_lower_bound"]), float(doc["time_per_target_m3"])
        rows.append({"suite": r.suite, "scenario_id": r.scenario_id, "family": r.family, "target_volume": r.target_volume,
                     "scenario_digest": r.scenario_digest, "bound_s_per_m3": bound, "best_known_s_per_m3": known,
                     "best_over_bound": known / bound, "best_time_to_target_s": float(doc["time_to_target_s"]),
                     "rules": doc.get("rules"), "producer": producer_text(doc.get("producer") or {}),
                     "kept_in": doc.get("suite"), "recorded": doc.get("recorded")})
    return pd.DataFrame.from_records(sorted(rows, key=lambda r: (str(r["suite"]), str(r["scenario_id"]))), columns=BRACKET_COLUMNS)


BRACKET_COLUMNS = ["suite", "scenario_id", "family", "target_volume", "scenario_digest", "bound_s_per_m3",
                   "best_known_s_per_m3", "best_over_bound", "best_time_to_target_s", "rules", "producer", "kept_in", "recorded"]


def bracket_lines(table: pd.DataFrame, sizes: dict[str, int]) -> dict[str, str]:
    """Per suite, one line: how many scenarios have a best known plan and the median best known /
    target bound per family (the README's section and the page say it under each suite)."""
    out = {}
    for suite, g in table.groupby("suite", sort=True):
        fams = "; ".join(f"{f} {np.median(h['best_over_bound']):.2f} ({len(h)})" for f, h in g.groupby("family", sort=True))
        out[str(suite)] = (f"{len(g)} of {sizes.get(str(suite), len(g))} scenarios have a best known plan; "
                           f"median best known / target bound by family (scenarios): {fams}")
    return out


#: What the board says of its best known plans (README section and page).
BRACKET_NOTE = ("Each scenario's bracket [target bound, best known time per target m³]: the fastest valid plan anyone has "
                "produced (any planner, any run, or a constructive witness), re-judged by `earthbench best check` and "
                "replaced only through `earthbench best update` (docs/publishing.md). The tables' \"× best known\" is a "
                "planner's median time per target m³ over it.")


def bracket_markdown(table: pd.DataFrame, sizes: dict[str, int]) -> str:
    """The README's section on best known plans (every bracket: ``best.csv``)."""
    if not len(table):
        return ""
    lines = ["## Best known plans", "", BRACKET_NOTE + " Every bracket: [best.csv](best.csv).", ""]
    lines += [f"- suite {suite}: {line}" for suite, line in bracket_lines(table, sizes).items()]
    return "\n".join(lines) + "\n\n"

__all__ = [
    "BEST_RATIO", "BRACKET_COLUMNS", "BRACKET_NOTE", "DEFAULT_DIR", "FIGURES", "FORMAT", "BestError", "Candidate",
    "Outcome", "all_kept", "bracket_lines", "bracket_markdown", "bracket_table", "check", "entry_path",
    "file_candidates", "judged_figures", "kept", "producer_text", "read_doc", "store_candidates", "update",
    "with_best_known", "write_doc",
]
