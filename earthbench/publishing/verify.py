"""Checking a results store against the referee: re-judging, audits and spot re-timing.

A store is a file anyone can edit, so nothing in it is trusted because it is there. What can
be checked is checked:

* **Referee and metric figures** (reason ok/invalid, success, every metric, the violations)
  are recomputed from the stored plan and the stored scenario document by :func:`rejudge`,
  the one re-judging function (``earthbench rescore``, ``merge`` and ``verify`` all call it).
* **Scenario and suite digests** are recomputed from the stored documents and members, never
  read from a digest column.
* **Solve times, CPU times and memory** come from the machine that ran the case and cannot be
  recomputed from a store; :func:`spot_check` reruns a seeded sample of cases on this machine
  and reports how far those figures agree.

A run without a plan whose reason is ``timeout``, ``memory``, ``crashed`` or ``error`` carries
no referee figures to verify; its reason is the word of the harness that ran it and cannot be
re-checked here. :func:`audit` counts such runs (``unjudged``) and lets them through only when
they claim nothing else (no success, no metrics, no violations). A run stored ``ok`` or
``invalid`` without a plan claims a verdict nobody can check, and is refused.
"""

from __future__ import annotations

import json
import math
import random
import traceback
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime, UTC
from typing import Any

from .. import compat
from ..results import labels
from ..errors import EarthbenchError, UnknownNameError
from ..results.records import SpotCheck  # a record the store also reads; importable from here as before
from ..running.harness.steps import step_metrics
from ..results.store import METRIC_COLUMNS, BlobTooLargeError, Store, decompress, stored_steps
from ..results.suite import suite_digest
from ..plan import Plan
from ..world import Scenario

#: Float round-off allowed between a stored figure and the re-judged one.
REL_TOL = 1e-9
ABS_TOL = 1e-9
#: Metrics only the harness measures: carried from the machine that ran the case, never re-judged.
HARNESS_METRICS = ("solve_time_s", "solve_cpu_s", "steps", "replans", "step_compute_median_s", "step_compute_max_s")
#: Reasons that carry a referee verdict, hence need a stored plan.
JUDGED_REASONS = ("ok", "invalid")


class VerifyError(EarthbenchError):
    """A store whose runs cannot be re-checked here (planner not installed, no runs to sample)."""


@dataclass(frozen=True)
class Judgement:
    """The referee's findings on one stored plan, in the shape the store keeps them."""

    reason: str
    metrics: dict[str, Any] | None
    violations: tuple[dict[str, Any], ...]
    error: str = ""

    @property
    def success(self) -> bool:
        return bool(self.metrics and self.metrics.get("success"))


def _score(scenario: Scenario, plan_json: str, threshold: float) -> tuple[Any, dict[str, Any]]:
    """The core scoring entry point (referee verdict and every metric), called from this one place."""
    from ..results.scoring import score

    return score(scenario, plan_json, threshold)


def rejudge(scenario: Scenario, plan_json: str, threshold: float, *,
            solve_time_s: float | None = None, solve_cpu_s: float | None = None,
            steps: Sequence[Sequence[float]] | None = None) -> Judgement:
    """Judge a stored plan again; the harness's solve times (and a closed-loop run's steps) are
    carried in as they were measured. A closed-loop run's plan is its steps concatenated.

    A referee failure is an ``error`` judgement with its traceback, as when the case first ran.
    """
    try:
        verdict, metrics = _score(scenario, plan_json, threshold)
    except Exception:  # noqa: BLE001 - a referee bug is reported on the run, never a crash
        return Judgement("error", None, (), "the referee failed on this plan:\n" + traceback.format_exc())
    metrics.update(solve_time_s=solve_time_s, solve_cpu_s=solve_cpu_s)
    if steps is not None:
        metrics.update(step_metrics(steps))
    return Judgement("ok" if verdict.valid else "invalid", metrics, tuple(v.to_dict() for v in verdict.violations))



def time_ordered_prefixes(plan: Plan) -> Iterator[Plan]:
    """Every proper prefix of a plan in the referee's time order (actions by start), longest first:
    what a wrapper that stops a planner early could submit instead."""
    order = sorted(range(len(plan.actions)), key=lambda n: (plan.actions[n].t_start, n))
    for k in range(len(order) - 1, -1, -1):
        keep = set(order[:k])
        yield Plan(tuple(a for n, a in enumerate(plan.actions) if n in keep), plan.predicted, plan.info)


def prefix_violations(scenario: Scenario, plan: Plan, threshold: float) -> tuple[int, list[str]]:
    """Check docs/metrics.md's promise on one plan: no valid prefix of a valid plan has a lower time
    per target m³, a success the plan lacks, or a better :func:`~earthbench.results.scoring.run_order`.
    Returns how many valid prefixes were judged and one line per prefix that breaks it (an invalid
    prefix is never ranked, so it cannot rank better; an invalid plan's prefixes are only counted)."""
    from ..referee import judge
    from ..results.scoring import evaluate, run_order

    m = evaluate(scenario, plan, judge(scenario, plan), threshold)
    full = run_order(m["success"], m["time_per_target_m3"], m["volume_ratio"])
    checked, broken = 0, []
    for prefix in time_ordered_prefixes(plan):
        verdict = judge(scenario, prefix)
        if not verdict.valid:
            continue
        checked += 1
        if not m["valid"]:
            continue
        mp = evaluate(scenario, prefix, verdict, threshold)
        n = len(prefix.actions)
        if mp["time_per_target_m3"] < m["time_per_target_m3"]:
            broken.append(f"{n} actions: time per target m³ {mp['time_per_target_m3']:.6g} < {m['time_per_target_m3']:.6g}")
        if mp["success"] and not m["success"]:
            broken.append(f"{n} actions: a success where the plan fails")
        if run_order(mp["success"], mp["time_per_target_m3"], mp["volume_ratio"]) < full:
            broken.append(f"{n} actions: ranks before the plan")
    return checked, broken

# -- comparing stored figures with re-judged ones -----------------------------------------------


def same(a: Any, b: Any) -> bool:
    """Equal up to float round-off (NaN equals NaN, ±inf only itself), recursively in lists and dicts."""
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        x, y = float(a), float(b)
        if math.isnan(x) or math.isnan(y):
            return math.isnan(x) and math.isnan(y)
        return x == y or math.isclose(x, y, rel_tol=REL_TOL, abs_tol=ABS_TOL)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def _show(v: Any) -> str:
    return f"{v:.6g}" if isinstance(v, float) else repr(v)


def differences(row: Any, judged: Judgement) -> list[str]:
    """What a stored run claims that the re-judged plan does not (empty when they agree).

    ``row`` is a ``runs`` row; every referee figure is compared: the reason, the success
    column, each metric in the JSON and in its own column, and the violations.
    """
    out: list[str] = []
    if row["reason"] != judged.reason:
        out.append(f"reason {row['reason']} (re-judged {judged.reason})")
    if bool(row["success"]) != judged.success:
        out.append(f"success {bool(row['success'])} (re-judged {judged.success})")
    try:
        stored = json.loads(row["metrics"]) if row["metrics"] else None
    except ValueError:
        stored = "unreadable"
    if isinstance(stored, dict):
        from ..results.scoring import restate  # on first use, as the rest of the scoring (a case's start-up)

        restate(stored)  # a store written under the rule before issue 35 is not a tampered one
    fresh = judged.metrics
    if not isinstance(stored, dict) or fresh is None:
        if not (stored is None and fresh is None):
            out.append(f"metrics {'none' if stored is None else 'unreadable' if not isinstance(stored, dict) else 'stored'} "
                       f"(re-judged {'none' if fresh is None else 'present'})")
    else:
        for k in sorted((stored.keys() | fresh.keys()) - set(HARNESS_METRICS)):
            if k not in fresh:
                out.append(f"metric {k} = {_show(stored[k])} is not computed by this earthbench")
            elif k not in stored:
                out.append(f"metric {k} missing (re-judged {_show(fresh[k])})")
            elif not same(stored[k], fresh[k]):
                out.append(f"metric {k} {_show(stored[k])} (re-judged {_show(fresh[k])})")
    for c in METRIC_COLUMNS:
        want = None if fresh is None else fresh.get(c)
        if not same(row[c], want):
            out.append(f"column {c} {_show(row[c])} (re-judged {_show(want)})")
    try:
        violations = json.loads(row["violations"] or "[]")
    except ValueError:
        violations = "unreadable"
    if not same(violations, list(judged.violations)):
        n = len(violations) if isinstance(violations, list) else "unreadable"
        out.append(f"violations {n} stored (re-judged {len(judged.violations)}: "
                   f"{', '.join(sorted({v['rule'] for v in judged.violations})) or 'none'})")
    return out


# -- auditing a whole store ---------------------------------------------------------------------


@dataclass(frozen=True)
class Finding:
    """One run (or one suite) that does not hold, and why."""

    run_id: int | None
    label: str
    what: str

    def __str__(self) -> str:
        return (f"run {self.run_id} ({self.label}): " if self.run_id is not None else f"{self.label}: ") + self.what


@dataclass
class Audit:
    """The outcome of re-checking every run of a store (:func:`audit`)."""

    path: str
    agreed: int = 0                                                #: re-judged and equal to what is stored
    differ: list[Finding] = field(default_factory=list)            #: stored figures differ from the re-judged ones
    broken: list[Finding] = field(default_factory=list)            #: cannot be verified at all (never mergeable)
    unjudged: Counter = field(default_factory=Counter)             #: runs without a plan, by reason (harness's word)
    judgements: dict[int, Judgement] = field(default_factory=dict)  #: by run id, every run re-judged
    scenarios: dict[str, Scenario] = field(default_factory=dict)    #: by digest, every stored scenario that reproduces it
    #: re-judged runs stored as judged under another version of the referee's rules, by that version
    other_rules: Counter = field(default_factory=Counter)

    def rules_note(self) -> str:
        """One line on runs judged under other rules than this referee's (empty when there are none)."""
        if not self.other_rules:
            return ""
        from ..referee import RULES_VERSION

        older = ", ".join(f"{n} under rules {v}" for v, n in sorted(self.other_rules.items()))
        return (f"{sum(self.other_rules.values())} run(s) were judged under other rules than this referee's "
                f"(rules {RULES_VERSION}): {older}; `earthbench rescore --db {self.path}` re-judges them")

    def problems(self, *, rescore: bool = False) -> list[str]:
        """Every reason to refuse this store; with ``rescore``, differing figures are not one."""
        out = [f"{self.path}: {f}" for f in self.broken]
        if not rescore:
            out += [f"{self.path}: {f}" for f in self.differ]
        return out


def _label(row: Any) -> str:
    return f"{row['scenario_id']} × {row['planner']} {row['planner_version']}"


def _check_suites(store: Store, audit: Audit) -> None:
    """Each stored suite version's digest, recomputed from its members and threshold."""
    for s in store.suite_versions():
        members = [(m["scenario_id"], m["scenario_digest"]) for m in store.suite_members(s["id"])]
        got = suite_digest(members, s["threshold"])
        if got != s["digest"]:
            audit.broken.append(Finding(None, f"suite {s['name']}", f"the stored digest {s['digest'][:12]}… is not the one its "
                                        f"{len(members)} scenarios and threshold give ({got[:12]}…)"))


def _scenarios(store: Store, digests: Iterable[str]) -> dict[str, Scenario | str]:
    """Each stored scenario by digest, or the reason it cannot be used (digest recomputed from the document)."""
    out: dict[str, Scenario | str] = {}
    for d in digests:
        blob = store.scenario_blob(d)
        if blob is None:
            out[d] = f"its scenario {d[:12]}… is not stored"
            continue
        try:
            sc = Scenario.from_text(decompress(blob))
        except Exception as exc:  # noqa: BLE001 - an edited document of any kind is a finding, not a crash
            out[d] = f"its stored scenario document cannot be read ({type(exc).__name__}: {str(exc)[:120]})"
            continue
        out[d] = sc if sc.digest == d else (f"its stored scenario document does not reproduce the digest {d[:12]}… "
                                            f"(it gives {sc.digest[:12]}…): the scenario was edited")
    return out


def audit(store: Store, rows: Sequence[Any] | None = None) -> Audit:
    """Re-check every run of ``store`` (or the given ``runs`` rows); writes nothing. A run stored
    as judged under other rules than this referee's is counted in ``other_rules``, and its
    finding says so when its figures differ."""
    from ..referee import RULES_VERSION as current_rules

    result = Audit(str(store.path))
    _check_suites(store, result)
    if rows is None:
        rows = store.runs()
    suites = {(s["name"], s["digest"]): (s["id"], s["threshold"]) for s in store.suite_versions()}
    members = store.memberships()
    scenarios = _scenarios(store, {r["scenario_digest"] for r in rows})
    result.scenarios = {d: sc for d, sc in scenarios.items() if isinstance(sc, Scenario)}
    for r in rows:
        label = _label(r)
        suite = suites.get((r["suite"], r["suite_digest"]))
        if suite is not None and not same(suite[1], r["threshold"]):
            result.broken.append(Finding(r["id"], label, f"threshold {r['threshold']!r} is not its suite's ({suite[1]!r})"))
            continue
        if suite is not None and (suite[0], r["scenario_digest"]) not in members:
            result.broken.append(Finding(r["id"], label, f"its scenario is not a member of suite {r['suite']} {r['suite_digest'][:12]}…"))
            continue
        sc = scenarios[r["scenario_digest"]]
        if isinstance(sc, str):
            result.broken.append(Finding(r["id"], label, sc))
            continue
        if r["plan"] is None:
            if r["reason"] in JUDGED_REASONS:
                result.broken.append(Finding(r["id"], label, f"stored {r['reason']} without a plan: its verdict cannot be verified"))
            elif r["success"] or r["metrics"] is not None or any(r[c] is not None for c in METRIC_COLUMNS) \
                    or (r["violations"] or "[]") != "[]":
                result.broken.append(Finding(r["id"], label, f"stored {r['reason']} without a plan, yet it carries referee figures"))
            else:
                result.unjudged[r["reason"]] += 1
            continue
        try:
            plan = decompress(r["plan"])
        except Exception as exc:  # noqa: BLE001 - an edited blob
            why = str(exc) if isinstance(exc, BlobTooLargeError) else type(exc).__name__
            result.broken.append(Finding(r["id"], label, f"its stored plan cannot be decompressed: {why}"))
            continue
        judged = rejudge(sc, plan, r["threshold"], solve_time_s=r["solve_time_s"], solve_cpu_s=r["solve_cpu_s"], steps=stored_steps(r))
        result.judgements[r["id"]] = judged
        diff = differences(r, judged)
        rules = r["rules"] if "rules" in r.keys() else 1
        if rules != current_rules:
            result.other_rules[rules] += 1
            if diff:
                diff.insert(0, f"judged under rules {rules} (this referee: rules {current_rules})")
        if r["reason"] == "error" and judged.reason == "error":
            diff = []  # the referee fails on it here too: an error either way (its traceback may differ)
        if diff:
            result.differ.append(Finding(r["id"], label, "; ".join(diff)))
        else:
            result.agreed += 1
    return result


# -- spot re-timing -------------------------------------------------------------------------------


def _ref_for(row: Any, config: dict[str, Any]):
    """The installed planner matching a stored run's name, version and configuration (or a clear error)."""
    from ..running.harness.probe import resolve

    try:
        ref = resolve(row["planner"], config)
    except UnknownNameError as exc:
        raise VerifyError(f"{exc}; a planner from a file is loaded with --plugin FILE.py") from None
    if ref.version != row["planner_version"]:
        raise VerifyError(f"planner {row['planner']!r} {ref.version} is installed, but the runs to re-time are of version "
                          f"{row['planner_version']}; install that version to re-time them")
    if ref.config_hash != row["config_hash"]:
        raise VerifyError(f"planner {row['planner']!r} {ref.version} gives configuration hash {ref.config_hash[:8]} for the "
                          f"stored configuration, not the stored {row['config_hash'][:8]}: its Config changed without a version bump")
    return ref


def spot_check(store: Store, n: int, *, seed: int = 0, suite: str | None = None, planners: Sequence[str] = (),
               jobs: int | None = None, executor: Any = None) -> list[SpotCheck]:
    """Rerun ``n`` seeded random runs of ``store`` on this machine; one :class:`SpotCheck` per planner.

    Every sampled planner must be installed at the stored version and configuration; the
    scenarios are the stored documents (their digests recomputed). Writes nothing.
    """
    from ..running.harness import LocalExecutor, isolation
    from ..results.records import Case
    from ..running.harness.environment import environment  # the package attribute is the submodule once it is loaded

    if n < 1:
        raise VerifyError("--sample must be at least 1")
    rows = sorted(store.query(suite=suite, planner=planners or None), key=lambda r: r["id"])
    if not rows:
        raise VerifyError(f"no runs to re-time in {str(store.path)!r}" + (f" for suite {suite!r}" if suite else "")
                          + (f" and planner(s) {', '.join(planners)}" if planners else ""))
    sample = random.Random(seed).sample(rows, min(n, len(rows)))
    scenarios = _scenarios(store, {r["scenario_digest"] for r in sample})
    cases, refs = [], {}
    for r in sample:
        sc = scenarios[r["scenario_digest"]]
        if isinstance(sc, str):
            raise VerifyError(f"run {r['id']} ({_label(r)}): {sc}")
        key = (r["planner"], r["planner_version"], r["config_hash"])
        if key not in refs:
            cfg = store.planner_config(r["planner_config_id"])
            refs[key] = _ref_for(r, json.loads(cfg["config"]) if cfg else {})
        # re-timed as it was timed: with its planner's preparation when the run used one
        prepared = "prepare_s" in r.keys() and r["prepare_s"] is not None
        cases.append(Case(r["suite"], r["suite_digest"], r["threshold"], sc, refs[key], prepare=prepared))
    by_key = {c.key: r for c, r in zip(cases, sample)}
    exposed = isolation.store_exposure(str(store.path), (c.planner.source for c in cases))
    if exposed:  # no case may read the store it is re-timed against (docs/isolation.md)
        raise VerifyError(exposed)
    fresh = {res.key: res for res in (executor or LocalExecutor(jobs)).run(cases)}
    here = labels.machine_label(environment())
    stored_env = {e["id"]: labels.machine_label(e) for e in store.environments()}
    now = datetime.now(UTC).isoformat(timespec="seconds")
    out = []
    for key in refs:
        runs = [(c, by_key[c.key]) for c in cases if (c.planner.name, c.planner.version, c.planner.config_hash) == key]
        agree, ratios, bad = 0, [], []
        cpu_ratios: list[float] = []
        load_stored: list[float] = []
        load_here: list[float] = []
        steal: list[float] = []
        for case, row in runs:
            res = fresh.get(case.key)
            if res is None:
                bad.append(f"run {row['id']}: no result")
                continue
            judged = Judgement(res.reason, res.metrics, tuple(res.violations))
            diff = differences(row, judged) if res.reason in JUDGED_REASONS or row["reason"] in JUDGED_REASONS \
                else ([] if res.reason == row["reason"] else [f"reason {row['reason']} (rerun {res.reason})"])
            if diff:
                bad.append(f"run {row['id']} ({row['scenario_id']}): " + "; ".join(diff))
            else:
                agree += 1
            if row["solve_time_s"] and res.solve_time_s is not None:
                ratios.append(res.solve_time_s / row["solve_time_s"])
            if row["solve_cpu_s"] and res.solve_cpu_s is not None:
                cpu_ratios.append(res.solve_cpu_s / row["solve_cpu_s"])
            load_stored += [float(row[c]) for c in ("load_before", "load_after") if c in row.keys() and row[c] is not None]
            load_here += [float(v) for c in ("load_before", "load_after") if (v := res.machine_load.get(c)) is not None]
            if res.machine_load.get("steal_share") is not None:
                steal.append(float(res.machine_load["steal_share"]))
        out.append(SpotCheck(key[0], key[1], key[2], tuple(r["id"] for _, r in runs), agree, tuple(ratios), tuple(bad), here,
                             tuple(sorted({stored_env.get(r["environment_id"], "unknown machine") for _, r in runs})), now,
                             tuple(cpu_ratios), tuple(load_stored), tuple(load_here), max(steal) if steal else None))
    return sorted(out, key=lambda s: (s.planner, s.version, s.config_hash))



# -- suite identity and sealed draws ----------------------------------------------------------


def suite_versions(store: Store) -> list[Any]:
    """Every suite version ``store`` lists, as :mod:`earthbench.results.identity` reads it."""
    from ..results.identity import Version

    out = []
    for s in store.suite_versions():
        keys = s.keys()
        out.append(Version(s["name"], s["digest"], str(store.path),
                           *(s[k] if k in keys else None for k in ("sealed_from", "public_digest", "commitment"))))
    return out


def identity_problems(store: Store) -> list[str]:
    """Every suite version of ``store`` stored under a name that is not its own (:mod:`earthbench.results.identity`)."""
    from ..results.identity import problems

    return problems(suite_versions(store))


@dataclass
class SealCheck:
    """What a revealed key says about a store's sealed draw (:func:`check_seal`)."""

    suite: str                                               #: the sealed suite's name
    problems: list[str] = field(default_factory=list)       #: reasons the draw does not hold
    scenarios: int = 0                                       #: sealed scenarios regenerated and matched
    run_rows: list[Any] = field(default_factory=list)        #: the stored runs of the draw, to re-judge


def check_seal(store: Store, key: Any) -> SealCheck:
    """Check a sealed draw of ``store`` against its revealed ``key`` (a :class:`~earthbench.seal.SealKey`):
    the key reproduces its commitment from the registered public suite (every sealed scenario
    regenerated), the store lists that draw under that commitment, and every stored scenario
    of the draw is the regenerated one. Re-judging the draw's runs is :func:`audit`'s
    (on ``run_rows``); this is the cost sealing adds to verifying a store.
    """
    from ..seal import SealError
    from ..results.suite import open_sealed, public_suite

    out = SealCheck(key.name)
    try:
        sealed = open_sealed(public_suite(key), key)
    except (SealError, EarthbenchError) as exc:
        out.problems.append(f"key for {key.name}: {exc}")
        return out
    ver = store.suite_versions(sealed.name)
    if not ver:
        out.problems.append(f"{store.path} holds no suite {sealed.name!r}: this key draws another store's board")
        return out
    regenerated = {sc.id: sc.digest for sc in sealed.scenarios}
    for v in ver:
        keys = v.keys()
        if v["digest"] != sealed.digest:
            out.problems.append(f"suite {sealed.name!r} is stored with digest {v['digest'][:12]}…, but the revealed key draws "
                                f"{sealed.digest[:12]}…")
        if "commitment" in keys and v["commitment"] != key.commitment:
            out.problems.append(f"suite {sealed.name!r} is stored with commitment {str(v['commitment'])[:12]}…, not the key's "
                                f"{key.commitment[:12]}…")
        for m in store.suite_members(v["id"]):
            sid, digest = m["scenario_id"], m["scenario_digest"]
            if regenerated.get(sid) != digest:
                out.problems.append(f"scenario {sid} is stored with digest {digest[:12]}…, the key regenerates "
                                    f"{str(regenerated.get(sid, 'nothing'))[:12]}…")
            else:
                out.scenarios += 1
    digests = set(regenerated.values())
    for r in store.runs(labelled=sealed.name):
        if r["scenario_digest"] in digests:
            out.run_rows.append(r)
        else:
            out.problems.append(f"run {r['id']} ({_label(r)}) is labelled {sealed.name} but its scenario is not one the key draws")
    return out


__getattr__ = compat.forward(__name__)  # machine_label, latest_spot_checks: moved to earthbench.results.labels (earthbench.compat)
