"""Why a planner's sealed figures differ from its public ones: the checks of docs/sealed-evaluation.md,
"What the first sealed draws showed" (issue 34).

    python scripts/sealed_audit.py families --db standard-board.db
        per planner and family: median time per target m³ and success, public against the sealed draws
    python scripts/sealed_audit.py scenarios --db standard-board.db --suite standard
        terrain statistics per family: the public seeds and the sealed draws against the generator's
        own distribution (seeds 1000-1199); Mann-Whitney p-values
    python scripts/sealed_audit.py orientations --planner separate --family paper-extensive.rbf30 --seed 0 --target 4
        one planner on one public scenario turned and mirrored every way (in-process, the referee's figures)
    python scripts/sealed_audit.py rerun --db standard-board.db --key standard-1.key --family paper-extensive.rbf30
        the installed planner (in-process) on a sealed draw's scenarios, beside the store's runs of the same scenarios

The sealed draws need their keys only where a scenario is regenerated (``rerun``); everything else reads the store.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import pandas as pd
from scipy.stats import mannwhitneyu
from shapely import contains_xy
from shapely.geometry import Polygon

from earthbench.registry import PLANNERS, TERRAINS
from earthbench.results.scoring import score
from earthbench.seal import SealKey, SiteTransform, public_name
from earthbench.sensing import observe
from earthbench.results.store import Store, load_runs
from earthbench.results.suite import registered_suite
from earthbench.world import Scenario


def kind(suite: str) -> str:
    return "sealed" if public_name(suite) else "public"


def families(args: argparse.Namespace) -> None:
    runs = load_runs(args.db)
    runs["kind"] = runs["suite"].map(kind)
    t = runs.groupby(["planner", "family", "kind"]).agg(
        runs=("id", "size"), success=("success", "mean"), time_per_target_m3=("time_per_target_m3", "median"),
        digs=("digs", "median"), travel_m=("travel_m", "median"))
    print(t.round(3).to_string())


def features(sc: Scenario) -> dict[str, float]:
    """Material in the dig area, the highest point, and the excavator's and truck's distances to the dig area."""
    t = sc.terrain
    xs, ys = t.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    inside = contains_xy(Polygon(sc.site.dig_area), X, Y)
    floor = sc.site.floor if sc.site.floor is not None else float(t.z.min())
    cx, cy = np.mean(np.array(sc.site.dig_area), axis=0)
    e, q = sc.machines.excavator_pose, sc.machines.truck_pose
    assert e is not None
    return {"volume_in_dig_area": t.volume_above(floor, inside), "highest": float(t.z.max() - floor),
            "excavator_to_dig_area": math.hypot(e.x - cx, e.y - cy), "truck_to_dig_area": math.hypot(q.x - cx, q.y - cy)}


def scenarios(args: argparse.Namespace) -> None:
    store = Store(args.db, read_only=True)
    runs = load_runs(store)
    runs = runs[runs["suite"].map(lambda s: (public_name(s) or s) == args.suite)].drop_duplicates("scenario_digest")
    # a public seed's targets share one terrain: count it once
    runs = runs[(runs["suite"] != args.suite) | ~runs.duplicated(["family", "seed"])]
    rows = [{"family": r.family, "kind": kind(r.suite), **features(store.scenario(r.scenario_digest))} for r in runs.itertuples()]
    have = pd.DataFrame(rows)
    out = []
    for fam in registered_suite(args.suite).families:
        gen = TERRAINS.get(fam.generator)
        ref = pd.DataFrame([features(gen(s, fam.targets[0], **fam.params)) for s in range(1000, 1200)])
        pub, sea = have[(have.family == fam.name) & (have.kind == "public")], have[(have.family == fam.name) & (have.kind == "sealed")]
        for f in ref.columns:
            if np.ptp(ref[f]) == 0:
                continue  # fixed by the family (the paper's poses on a whole-map dig area)
            out.append({"family": fam.name, "feature": f, "generator": ref[f].mean(), "public": pub[f].mean(), "n_public": len(pub),
                        "p_public": mannwhitneyu(pub[f], ref[f]).pvalue, "sealed": sea[f].mean(), "n_sealed": len(sea),
                        "p_sealed": mannwhitneyu(sea[f], ref[f]).pvalue})
    print(pd.DataFrame(out).round(3).to_string())


def _judge(planner: str, sc: Scenario) -> dict[str, float]:
    plan = PLANNERS.get(planner)().plan(observe(sc))
    _, m = score(sc, plan.to_json(), 0.9)
    return {"time_per_target_m3": m["time_per_target_m3"], "volume_ratio": m["volume_ratio"], "digs": m["digs"],
            "areas": plan.info.get("areas", math.nan)}


def orientations(args: argparse.Namespace) -> None:
    sc = next(s for s in registered_suite(args.suite).scenarios
              if s.meta["family"] == args.family and s.meta["seed"] == args.seed and s.meta["target"] == args.target)
    for mirror in (False, True):
        for turns in range(4):
            got = _judge(args.planner, SiteTransform(turns, mirror).apply(sc))
            print(f"{args.planner} {PLANNERS.get(args.planner).version} {sc.id} turns={turns} mirror={mirror}: "
                  + " ".join(f"{k}={v:.4g}" for k, v in got.items()))


def rerun(args: argparse.Namespace) -> None:
    key = SealKey.read(args.key)
    sealed = registered_suite(key.suite).sealed(key)
    stored = load_runs(args.db)
    stored = stored[(stored.planner == args.planner)].set_index("scenario_digest")
    rows = []
    for sc in sealed.scenarios:
        if sc.meta["family"] != args.family:
            continue
        old = stored.loc[sc.digest] if sc.digest in stored.index else None
        rows.append({"scenario": sc.id, "stored_version": None if old is None else old["planner_version"],
                     "stored": math.nan if old is None else old["time_per_target_m3"],
                     "now": _judge(args.planner, sc)["time_per_target_m3"]})
        print(rows[-1], flush=True)
    t = pd.DataFrame(rows)
    print(f"median time per target m³: stored {t.stored.median():.2f}, {args.planner} {PLANNERS.get(args.planner).version} "
          f"{t.now.median():.2f} ({len(t)} scenarios)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("families")
    a.add_argument("--db", required=True)
    a = sub.add_parser("scenarios")
    a.add_argument("--db", required=True)
    a.add_argument("--suite", default="standard")
    a = sub.add_parser("orientations")
    a.add_argument("--planner", required=True)
    a.add_argument("--suite", default="standard")
    a.add_argument("--family", required=True)
    a.add_argument("--seed", type=int, required=True)
    a.add_argument("--target", type=float, required=True)
    a = sub.add_parser("rerun")
    a.add_argument("--db", required=True)
    a.add_argument("--key", required=True)
    a.add_argument("--family", required=True)
    a.add_argument("--planner", default="separate")
    args = p.parse_args()
    {"families": families, "scenarios": scenarios, "orientations": orientations, "rerun": rerun}[args.cmd](args)


if __name__ == "__main__":
    main()
