"""Merging results stores from several machines into one (``earthbench merge``), and the
submission bundle that carries one planner's runs to another machine (``earthbench export``).

Every input is checked before anything is written, and the merge is refused (nothing is
written; a new output is not even created) when:

* a run's key (scenario digest, planner, version, config hash) is already in the output or
  occurs in two inputs — a duplicate run would be counted twice;
* a suite name has more than one digest across the output and the inputs (the suite file
  changed between machines), or a run is labelled with a suite digest that its store does
  not know — those rows would be published under the wrong suite;
* a suite name is a registered suite's but its digest is not (:mod:`earthbench.results.identity`):
  a different world under a known name (``as_variant`` stores it as ``NAME~variant-D``);
* :func:`earthbench.publishing.verify.audit` finds a run that does not hold: its plan re-judged against
  its stored scenario document gives other referee figures (unless ``rescore``, which merges
  the re-judged figures instead), it claims a verdict without a plan, its scenario document
  or suite does not reproduce its digest, or its threshold is not its suite's.

Runs without a plan (timeout, memory, crashed, error) are merged with the reason the harness
that ran them gave; nothing in a store can re-check it, and the merge counts them apart.
Solve times, CPU times and memory are carried as measured, with the environment stamp of the
machine that measured them.

Rows are copied through the store's own API (:meth:`Store.register_suite`,
:meth:`Store.record`), one transaction per run, so the output has the same schema, the same
deduplicated environments, configurations and scenarios as a store written by
``earthbench run``. What is not carried: ``rescored_at`` (the merged run counts as freshly
recorded).
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..results import identity
from ..errors import StoreError, not_stored
from ..results.records import Case, CaseResult, PlannerRef
from ..results.store import LOAD_COLUMNS, Store, decompress, stored_steps
from .verify import Judgement, audit


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
    sealed_from: str | None = None
    public_digest: str | None = None
    commitment: str | None = None

    def version(self, where: str) -> identity.Version:
        return identity.Version(self.name, self.digest, where, self.sealed_from, self.public_digest, self.commitment)


@dataclass
class MergeReport:
    runs: int = 0                                              #: runs written
    suites: int = 0                                            #: suite versions new to the output
    per_input: dict[str, int] = field(default_factory=dict)    #: runs written per input
    agreed: int = 0                                            #: re-judged and equal to what was stored
    rescored: int = 0                                          #: re-judged, differed, merged with the new figures
    unjudged: Counter = field(default_factory=Counter)         #: runs without a plan, by reason (not re-checkable)
    changes: list[str] = field(default_factory=list)           #: with rescore: each re-scored run and what differed
    duplicates: int = 0                                        #: with skip_duplicates: identical runs left out
    #: runs stored as judged under other rules than this referee's, by version (all merged as judged under its rules)
    other_rules: Counter = field(default_factory=Counter)


def _suites(store: Store) -> list[_SuiteRecord]:
    out = []
    for s in store.suite_versions():
        members = tuple(
            _SuiteScenario(m["scenario_id"], m["scenario_digest"], {"family": m["family"], "seed": m["seed"]})
            for m in store.suite_members(s["id"])
        )
        keys = s.keys()
        seal = tuple(s[k] if k in keys else None for k in ("sealed_from", "public_digest", "commitment"))
        out.append(_SuiteRecord(s["name"], s["digest"], s["track"], s["threshold"], s["description"] or "", members, *seal))
    return out


def _renames(inputs: Sequence[Store]) -> dict[tuple[str, str], str]:
    """(name, digest) → the variant name ``as_variant`` stores it under, for every known name with another world."""
    out = {}
    for st in inputs:
        for s in _suites(st):
            new = identity.renamed(s.version(str(st.path)))
            if new != s.name:
                out[(s.name, s.digest)] = new
    return out


def _relabel(suites: Sequence[_SuiteRecord], renames: dict[tuple[str, str], str]) -> list[_SuiteRecord]:
    return [replace(s, name=renames.get((s.name, s.digest), s.name)) for s in suites]


def check(out: Store | None, inputs: Sequence[Store], renames: dict[tuple[str, str], str] | None = None,
          skip: set[tuple[str, int]] | None = None) -> list[str]:
    """Every reason the merge must be refused (empty when it may go ahead); ``renames``: the
    variant names ``as_variant`` gives (:func:`_renames`).

    With ``skip`` (a set, filled here), a run already in an earlier store (or in ``out``) with
    the same plan and outcome is not a problem: its (store path, run id) is added to ``skip``.
    """
    problems: list[str] = []
    digests: dict[str, dict[str, list[str]]] = {}
    stores = ([out] if out is not None else []) + list(inputs)
    for st in stores:
        for s in _relabel(_suites(st), renames or {}):
            problems += identity.problems([s.version(str(st.path))])
            digests.setdefault(s.name, {}).setdefault(s.digest, []).append(str(st.path))
        known = {(s.name, s.digest) for s in _suites(st)}
        for name, digest, n in st.run_labels():
            if (name, digest) not in known:
                problems.append(
                    f"{st.path}: {n} run(s) labelled suite {name!r} digest {digest[:12]}…, a suite version that store does not list"
                )
    for name, by_digest in sorted(digests.items()):
        if len(by_digest) > 1:
            where = "; ".join(f"{d[:12]}… in {', '.join(sorted(set(p)))}" for d, p in by_digest.items())
            problems.append(f"suite {name!r} has different digests ({where}): the suite changed between runs; "
                            "publish each version from its own store, or rerun one side")
    seen: dict[tuple[str, str, str, str], tuple[Store, int]] = {}
    dups: list[str] = []
    for st in stores:
        for run_id, k in st.run_keys():
            if k not in seen:
                seen[k] = (st, run_id)
                continue
            first, first_id = seen[k]
            if skip is not None and st is not out and _same_run(first, first_id, st, run_id):
                skip.add((str(st.path), run_id))
            else:
                dups.append(f"{k[1]} {k[2]} [{k[3][:8]}] on scenario {k[0][:12]}… is in both {first.path} and {st.path}"
                            + (" with a different plan or outcome" if skip is not None else ""))
    if dups:
        problems.append(f"{len(dups)} duplicate run(s), e.g.: " + "; ".join(dups[:5])
                        + ("" if skip is not None else
                           " (runs identical in both, as a deterministic baseline's, merge once with --skip-duplicates)"))
    return problems


def _same_run(a: Store, a_id: int, b: Store, b_id: int) -> bool:
    """Two stored runs of one case that the referee cannot tell apart: the same plan (so the same
    re-judged figures, which the audit checks against each one's stored figures) or, without a
    plan, the same termination reason."""
    ra, rb = a.run_outcome(a_id), b.run_outcome(b_id)
    if ra[1] is None or rb[1] is None:
        return ra[1] is None and rb[1] is None and ra[0] == rb[0]
    try:
        return bool(ra[0] == rb[0] and json.loads(decompress(ra[1])) == json.loads(decompress(rb[1])))
    except ValueError:
        return False


def _case_and_result(src: Store, row: Any, scenarios: dict[str, Any],
                     renames: dict[tuple[str, str], str] | None = None) -> tuple[Case, CaseResult]:
    digest = row["scenario_digest"]
    if digest not in scenarios:
        sc = src.scenario(digest)
        if sc.digest != digest:
            raise MergeError(f"{src.path}: the stored scenario {row['scenario_id']} no longer reproduces its digest "
                             f"{digest[:12]}… (got {sc.digest[:12]}…); it cannot be merged safely")
        scenarios[digest] = sc
    sc = scenarios[digest]
    cfg = src.planner_config(row["planner_config_id"])
    ref = PlannerRef(name=row["planner"], version=row["planner_version"], source=(cfg["source"] if cfg else "") or "",
                     config=json.loads(cfg["config"]) if cfg else {}, config_hash=row["config_hash"])
    suite = (renames or {}).get((row["suite"], row["suite_digest"]), row["suite"])
    case = Case(suite, row["suite_digest"], row["threshold"], sc, ref)
    env: dict[str, Any] = {}
    e = src.environment(row["environment_id"]) if row["environment_id"] else None
    if e is not None:
        env = {"hostname": e["hostname"], "cpu_model": e["cpu_model"], "cores": e["cores"], "os": e["os"],
               "python": e["python"], "packages": json.loads(e["packages"] or "{}"),
               "project_commit": e["project_commit"], "plugin_commit": e["plugin_commit"]}
        keys = e.keys()
        if "earthbench_version" in keys:  # schema 5: the build of the code and the plugin's distribution
            env["earthbench_version"] = e["earthbench_version"]
            env["plugin"] = json.loads(e["plugin"]) if e["plugin"] else None
    metrics = json.loads(row["metrics"]) if row["metrics"] else None
    res = CaseResult(
        key=case.key, scenario_id=row["scenario_id"], reason=row["reason"], solve_time_s=row["solve_time_s"],
        solve_cpu_s=row["solve_cpu_s"], startup_s=row["startup_s"], peak_rss_mb=row["peak_rss_mb"], metrics=metrics,
        violations=tuple(json.loads(row["violations"] or "[]")), plan_json=decompress(row["plan"]),
        error=row["error"] or "", log_tail=row["log_tail"] or "", exit_status=row["exit_status"],
        cores=tuple(int(c) for c in (row["cores"] or "").split(",") if c.strip()), started_at=row["started_at"] or "",
        finished_at=row["finished_at"] or "", environment=env, steps=stored_steps(row),
        isolation=(row["isolation"] if "isolation" in row.keys() else None) or "none",
        processes=row["processes"] if "processes" in row.keys() else None,
        machine_load={c: row[c] for c in LOAD_COLUMNS if c in row.keys()},
        **{k: row[k] for k in ("prepare_s", "prepare_cpu_s") if k in row.keys()},
    )
    return case, res


@contextmanager
def _new_store(path: Path) -> Iterator[Store]:
    """A store that appears at ``path`` only once it is complete: built beside it, then renamed.

    A refusal or a failure half-way leaves no file behind (no empty database). Nobody reads
    the file before it is complete, so its per-run transactions skip the disk sync; one
    synced checkpoint makes it durable before the rename.
    """
    if not path.parent.is_dir():
        raise MergeError(f"the folder {str(path.parent)!r} for {str(path)!r} does not exist; create it first")
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        with Store(tmp) as st, st.unsynced():
            yield st
        os.replace(tmp, path)
    finally:
        for p in (tmp, Path(f"{tmp}-wal"), Path(f"{tmp}-shm")):
            p.unlink(missing_ok=True)


def _copy(src: Store, rows: Sequence[Any], out: Store, judgements: dict[int, Judgement] | None = None,
          scenarios: dict[str, Any] | None = None, renames: dict[tuple[str, str], str] | None = None) -> int:
    """Copy ``rows`` of ``src`` into ``out`` through :meth:`Store.record`; a run in ``judgements`` takes the re-judged figures.

    ``scenarios``: the stored scenarios already read (and checked) by digest.
    """
    scenarios = dict(scenarios or {})
    out.copy_scenarios(src, dict.fromkeys(r["scenario_digest"] for r in rows))
    n = 0
    for row in rows:
        case, res = _case_and_result(src, row, scenarios, renames)
        j = (judgements or {}).get(row["id"])
        if j is not None:
            res = replace(res, reason=j.reason, metrics=j.metrics, violations=j.violations, error=j.error)
        if out.record(case, res, plan_blob=row["plan"] if res.plan_json is not None else None):
            n += 1
    return n


def _register(out: Store, suites: Sequence[_SuiteRecord]) -> int:
    new = 0
    for s in suites:
        ver = out.suite_version(s.name)
        if ver is None or ver["digest"] != s.digest:
            new += 1
        out.register_suite(s)
    return new


def merge(out_path: str | Path, in_paths: Sequence[str | Path], *, rescore: bool = False, as_variant: bool = False,
          skip_duplicates: bool = False) -> MergeReport:
    """Merge the stores ``in_paths`` into ``out_path`` (created if missing); see the module doc.

    Every incoming run is re-judged first; with ``rescore``, runs whose stored figures differ
    are merged with the re-judged ones (counted in ``rescored``) instead of refusing the merge.
    With ``as_variant``, an input's suite under a registered name with another digest is
    stored as ``NAME~variant-D`` (:func:`earthbench.results.identity.variant_name`) instead of refused.
    With ``skip_duplicates``, a run that is already in the output or an earlier input with the
    same plan and outcome (two machines' runs of a deterministic baseline) is left out, counted
    in ``duplicates``; a duplicate that differs still refuses the merge.
    """
    if not in_paths:
        raise MergeError("name at least one input database")
    out_path = Path(out_path)
    resolved = [Path(p).resolve() for p in in_paths]
    if out_path.resolve() in resolved:
        raise MergeError(f"the output {str(out_path)!r} is also an input")
    if len(set(resolved)) != len(resolved):
        raise MergeError("an input database is named twice")
    if out_path.is_dir():
        raise MergeError(f"the output {str(out_path)!r} is a directory, not a results database file")
    inputs = [Store(p, read_only=True) for p in in_paths]
    try:
        existing = Store(out_path, create=False) if out_path.exists() else None
        try:
            if existing is not None:
                existing.check_writable()
            renames = _renames(inputs) if as_variant else {}
            skip: set[tuple[str, int]] | None = set() if skip_duplicates else None
            problems = check(existing, inputs, renames, skip)
            audits = [audit(src) for src in inputs]
            for a in audits:
                problems += a.problems(rescore=rescore)
            if problems:
                shown = problems[:20] + ([f"… and {len(problems) - 20} more"] if len(problems) > 20 else [])
                raise MergeError("merge refused, nothing was written:\n  " + "\n  ".join(shown)
                                 + "".join(f"\n  {a.rules_note()}" for a in audits if a.other_rules and a.differ)
                                 + ("" if rescore or not any(a.differ for a in audits) else
                                    "\n  (runs whose stored figures differ from the re-judged ones merge with --rescore, "
                                    "which replaces them)"))
            report = MergeReport()
            for a in audits:
                report.agreed += a.agreed
                report.rescored += len(a.differ)
                report.changes += [f"{a.path}: {f}" for f in a.differ]
                report.unjudged.update(a.unjudged)
                report.other_rules.update(a.other_rules)

            def fill(out: Store) -> None:
                for src, a in zip(inputs, audits):
                    report.suites += _register(out, _relabel(_suites(src), renames))
                    rows = [r for r in src.runs() if (str(src.path), r["id"]) not in (skip or ())]
                    report.duplicates += sum(1 for s in (skip or ()) if s[0] == str(src.path))
                    changed = {f.run_id: a.judgements[f.run_id] for f in a.differ if f.run_id in a.judgements}
                    n = _copy(src, rows, out, changed, a.scenarios, renames)
                    report.per_input[str(src.path)] = n
                    report.runs += n

            if existing is not None:
                fill(existing)
            else:
                with _new_store(out_path) as out:
                    fill(out)
            return report
        finally:
            if existing is not None:
                existing.close()
    finally:
        for s in inputs:
            s.close()


def export(db: str | Path, out_path: str | Path, suite: str, planners: Sequence[str]) -> MergeReport:
    """Write a submission bundle: the runs of ``planners`` on ``suite`` with what verifying them needs.

    The bundle is a new results store (runs with their plans, the scenario documents, the
    planner configurations, the environments and the suite versions the runs are labelled
    with), so ``merge`` takes it like any store and re-judges every plan in it.
    """
    out_path = Path(out_path)
    if out_path.exists():
        raise MergeError(f"{str(out_path)!r} already exists; export writes a new bundle (choose another name or remove it)")
    if not planners:
        raise MergeError("name the planner(s) to export with --planner")
    with Store(db, read_only=True) as src:
        ver = src.suite_version(suite)
        if ver is None:
            raise MergeError(not_stored("suite", suite, src.suite_names(), db))
        stored = src.planner_names()
        for p in planners:
            if p not in stored:
                raise MergeError(not_stored("planner", p, stored, db))
        members = {r["scenario_digest"] for r in src.suite_members(ver["id"])}
        rows = [r for r in sorted(src.query(planner=planners), key=lambda r: r["id"]) if r["scenario_digest"] in members]
        if not rows:
            raise MergeError(f"no runs of {', '.join(planners)} on suite {suite!r} (digest {ver['digest'][:12]}…) in {str(db)!r}")
        labels = {(r["suite"], r["suite_digest"]) for r in rows} | {(ver["name"], ver["digest"])}
        report = MergeReport()
        with _new_store(out_path) as out:
            report.suites = _register(out, [s for s in _suites(src) if (s.name, s.digest) in labels])
            report.runs = _copy(src, rows, out)
        report.per_input[str(db)] = report.runs
        return report
