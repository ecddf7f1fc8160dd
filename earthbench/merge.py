"""Merging results stores from several machines into one (``earthbench merge``).

Every input is checked before anything is written, and the merge is refused (nothing is
written) when:

* a run's key (scenario digest, planner, version, config hash) is already in the output or
  occurs in two inputs — a duplicate run would be counted twice;
* a suite name has more than one digest across the output and the inputs (the suite file
  changed between machines), or a run is labelled with a suite digest that its store does
  not know — those rows would be published under the wrong suite.

Rows are then copied through the store's own API (:meth:`Store.register_suite`,
:meth:`Store.record`), one transaction per run, so the output has the same schema, the same
deduplicated environments, configurations and scenarios as a store written by
``earthbench run``. Each scenario document is checked to reproduce its digest. What is not
carried: ``rescored_at`` (the merged run counts as freshly recorded).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import StoreError
from .harness.cases import Case, CaseResult, PlannerRef
from .store import Store, _decompress


class MergeError(StoreError):
    """Inputs that cannot be merged: duplicate runs or mismatched suite digests."""


@dataclass(frozen=True)
class _SuiteScenario:
    id: str
    digest: str
    meta: dict[str, Any]


@dataclass(frozen=True)
class _SuiteRecord:
    """A stored suite version in the shape :meth:`Store.register_suite` reads."""

    name: str
    digest: str
    track: str
    success_threshold: float
    description: str
    scenarios: tuple[_SuiteScenario, ...] = field(default=())


@dataclass
class MergeReport:
    runs: int = 0
    suites: int = 0
    per_input: dict[str, int] = field(default_factory=dict)


def _suites(store: Store) -> list[_SuiteRecord]:
    out = []
    for s in store.db.execute("SELECT * FROM suites ORDER BY id"):
        members = tuple(
            _SuiteScenario(m["scenario_id"], m["scenario_digest"], {"family": m["family"], "seed": m["seed"]})
            for m in store.db.execute("SELECT * FROM suite_scenarios WHERE suite_id=? ORDER BY scenario_id", (s["id"],))
        )
        out.append(_SuiteRecord(s["name"], s["digest"], s["track"], s["threshold"], s["description"] or "", members))
    return out


def _keys(store: Store) -> list[tuple[str, str, str, str]]:
    return [tuple(r) for r in store.db.execute("SELECT scenario_digest, planner, planner_version, config_hash FROM runs")]  # type: ignore[misc]


def check(out: Store | None, inputs: Sequence[Store]) -> list[str]:
    """Every reason the merge must be refused (empty when it may go ahead)."""
    problems: list[str] = []
    digests: dict[str, dict[str, list[str]]] = {}
    stores = ([out] if out is not None else []) + list(inputs)
    for st in stores:
        for s in _suites(st):
            digests.setdefault(s.name, {}).setdefault(s.digest, []).append(str(st.path))
        known = {(s.name, s.digest) for s in _suites(st)}
        bad = st.db.execute("SELECT suite, suite_digest, COUNT(*) FROM runs GROUP BY suite, suite_digest").fetchall()
        for name, digest, n in bad:
            if (name, digest) not in known:
                problems.append(f"{st.path}: {n} run(s) labelled suite {name!r} digest {digest[:12]}…, a suite version that store does not list")
    for name, by_digest in sorted(digests.items()):
        if len(by_digest) > 1:
            where = "; ".join(f"{d[:12]}… in {', '.join(sorted(set(p)))}" for d, p in by_digest.items())
            problems.append(f"suite {name!r} has different digests ({where}): the suite changed between runs; "
                            "publish each version from its own store, or rerun one side")
    seen: dict[tuple[str, str, str, str], str] = {}
    dups: list[str] = []
    for st in stores:
        for k in _keys(st):
            if k in seen:
                dups.append(f"{k[1]} {k[2]} [{k[3][:8]}] on scenario {k[0][:12]}… is in both {seen[k]} and {st.path}")
            else:
                seen[k] = str(st.path)
    if dups:
        problems.append(f"{len(dups)} duplicate run(s), e.g.: " + "; ".join(dups[:5]))
    return problems


def _case_and_result(src: Store, row: Any, scenarios: dict[str, Any]) -> tuple[Case, CaseResult]:
    digest = row["scenario_digest"]
    if digest not in scenarios:
        sc = src.scenario(digest)
        if sc.digest != digest:
            raise MergeError(f"{src.path}: the stored scenario {row['scenario_id']} no longer reproduces its digest "
                             f"{digest[:12]}… (got {sc.digest[:12]}…); it cannot be merged safely")
        scenarios[digest] = sc
    sc = scenarios[digest]
    cfg = src.db.execute("SELECT config, source FROM planner_configs WHERE id=?", (row["planner_config_id"],)).fetchone()
    ref = PlannerRef(name=row["planner"], version=row["planner_version"], source=(cfg["source"] if cfg else "") or "",
                     config=json.loads(cfg["config"]) if cfg else {}, config_hash=row["config_hash"])
    case = Case(row["suite"], row["suite_digest"], row["threshold"], sc, ref)
    env: dict[str, Any] = {}
    e = src.db.execute("SELECT * FROM environments WHERE id=?", (row["environment_id"],)).fetchone() if row["environment_id"] else None
    if e is not None:
        env = {"hostname": e["hostname"], "cpu_model": e["cpu_model"], "cores": e["cores"], "os": e["os"],
               "python": e["python"], "packages": json.loads(e["packages"] or "{}"),
               "project_commit": e["project_commit"], "plugin_commit": e["plugin_commit"]}
    metrics = json.loads(row["metrics"]) if row["metrics"] else None
    res = CaseResult(
        key=case.key, scenario_id=row["scenario_id"], reason=row["reason"], solve_time_s=row["solve_time_s"],
        solve_cpu_s=row["solve_cpu_s"], startup_s=row["startup_s"], peak_rss_mb=row["peak_rss_mb"], metrics=metrics,
        violations=tuple(json.loads(row["violations"] or "[]")), plan_json=_decompress(row["plan"]),
        error=row["error"] or "", log_tail=row["log_tail"] or "", exit_status=row["exit_status"],
        cores=tuple(int(c) for c in (row["cores"] or "").split(",") if c.strip()), started_at=row["started_at"] or "",
        finished_at=row["finished_at"] or "", environment=env,
    )
    return case, res


def merge(out_path: str | Path, in_paths: Sequence[str | Path]) -> MergeReport:
    """Merge the stores ``in_paths`` into ``out_path`` (created if missing); see the module doc."""
    if not in_paths:
        raise MergeError("name at least one input database")
    resolved = [Path(p).resolve() for p in in_paths]
    if Path(out_path).resolve() in resolved:
        raise MergeError(f"the output {str(out_path)!r} is also an input")
    if len(set(resolved)) != len(resolved):
        raise MergeError("an input database is named twice")
    inputs = [Store(p, create=False) for p in in_paths]
    try:
        with Store(out_path) as out:
            out.check_writable()
            problems = check(out, inputs)
            if problems:
                raise MergeError("merge refused, nothing was written:\n  " + "\n  ".join(problems))
            report = MergeReport()
            for src in inputs:
                for s in _suites(src):
                    if out.suite_version(s.name) is None or out.suite_version(s.name)["digest"] != s.digest:
                        report.suites += 1
                    out.register_suite(s)
                scenarios: dict[str, Any] = {}
                n = 0
                for row in src.db.execute("SELECT * FROM runs ORDER BY id"):
                    case, res = _case_and_result(src, row, scenarios)
                    if out.record(case, res):
                        n += 1
                report.per_input[str(src.path)] = n
                report.runs += n
            return report
    finally:
        for s in inputs:
            s.close()
