"""Issue 39: would a truck-placement rule force a swing the lower bound could price?

The rule measured ("R"): while the excavator digs, the truck's body stays clear of the arm's
ground shadow (the convex hull of the base centre and the bucket's footprint: the stick would
pass through the truck), and while it is loaded the truck stands off the dig area (on ground
that is not being dug). Not a rule of the referee: this measures what it would do (docs/metrics.md,
"What the geometry forces"), on a copy of a board's store (never the published one):

``plans``   — for every stored plan of a board: which valid runs R would make invalid (the
              verdicts that would move), and the swing each dump paid (the angle between the last
              dig's contact and the truck's centre, seen from the base).
``forced``  — for every scenario of a suite: the least swing R allows a dump after a dig at each
              contact of the dig area that holds soil above the floor (0.25 m grid, richest
              first), searched over bases 2–6.1 m from it (their ground ignored: tilt and
              undermining only remove bases) and truck stands in dump reach; it stops once the soil
              at contacts where R allows no swing holds the target. Where it does, no bound that
              holds for every plan valid under R can charge a swing. ``--strict`` also keeps the
              excavator's base off the dig area; ``--largest`` judges each map at its largest
              target only (the soil with no forced swing does not depend on the target).
``witness`` — plans valid under R (below).

    python scripts/swing_rule_audit.py plans   STORE.db [--suite standard]
    python scripts/swing_rule_audit.py forced  STORE.db [--suite standard] [--family F] [--largest] [--strict]
    python scripts/swing_rule_audit.py witness STORE.db [--suite standard] [--family bench.bench] [--spread 20] [--out DIR]

``witness`` builds, for each scenario of a family whose truck starts in dump reach of the
excavator and off the dig area (the bench family), a plan that never moves the excavator and
digs, bucket after bucket, the contact within ``--spread`` degrees of the truck's bearing, nearest
it first, that fills the bucket without breaking R or undermining the tracks, each dig and dump
at its least duration; when none is left the truck drives along its heading, during a dig, to
the next stand off the dig area in dump reach. It
reports the referee's verdict, R's breaches and the plan's time per target m³ against both
bounds. A plan valid under R at r × ``time_per_m3_lower_bound`` shows that no bound holding for
every plan valid under R can exceed r × that bound on the scenario. ``--out DIR`` writes each
plan as a candidate file (``DIR/<scenario digest>.json``) for ``earthbench best update --plans DIR
--suite S``, which judges it again before keeping it as a best known plan.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPoint, Point, Polygon

from earthbench.cut import cut_along, footprint, path_cells
from earthbench.motion import swing_time, turn_drive_turn, wrap
from earthbench.plan import Dig, Dump, Move, Plan
from earthbench.referee import judge
from earthbench.rules import arm_shadow, track_level_and_tilt, undermining_excess
from earthbench.results.scoring import evaluate
from earthbench.referee.state import Replay
from earthbench.results.store import Store, decompress
from earthbench.world import Pose, Scenario

#: Area (m²) below which two shapes count as touching, not overlapping (a footprint edge on the dig area's edge).
TOUCH = 1e-4


def _scenario(store: Store, digest: str, cache: dict[str, Scenario]) -> Scenario:
    if digest not in cache:
        cache[digest] = store.scenario(digest)
    return cache[digest]


def _maps(store: Store, suite: str) -> list[tuple[str, str, str, float]]:
    """(scenario digest, id, family, target) of each scenario run under ``suite``, by id."""
    seen = {(r["scenario_digest"], r["scenario_id"], r["family"], float(r["target_volume"])) for r in store.runs(labelled=suite)}
    return sorted(seen, key=lambda k: k[1])


def _truck_polygon(sc: Scenario, x: float, y: float, yaw: float) -> Polygon:
    return Polygon(sc.machines.truck.body(x, y, yaw)[0])


def audit_plan(sc: Scenario, plan: Plan) -> dict[str, object]:
    """Rule R's breaches in one plan, and the swing (rad) each excavator dump paid."""
    r = Replay(sc, plan)
    exc, truck = r.timelines["excavator"], r.timelines["truck"]
    spec = sc.machines.excavator
    area = Polygon(sc.site.dig_area)
    under_arm = on_area = base_on_area = 0
    swings: list[float] = []
    last_contact: tuple[float, float] | None = None
    for a in sorted(plan.actions, key=lambda a: a.t_start):
        if isinstance(a, Dig) and a.machine == "excavator":
            base = exc.pose(a.t_start)
            base_on_area += bool(area.contains(Point(base.x, base.y)))
            shadow = Polygon(arm_shadow(base, a.contact, a.heading, spec.bucket_width, a.drag_length))  # the referee's since rules 2
            times = np.unique(np.concatenate([np.linspace(a.t_start, a.t_end, 9),
                                              truck.path[(truck.path[:, 0] > a.t_start) & (truck.path[:, 0] < a.t_end), 0]]))
            poses = truck.poses(times)
            if any(_truck_polygon(sc, *p).intersection(shadow).area > TOUCH for p in poses):
                under_arm += 1
            last_contact = a.contact
        elif isinstance(a, Dump) and a.machine == "excavator":
            base, t = exc.pose(a.t_start), truck.pose(a.t_start)
            if _truck_polygon(sc, t.x, t.y, t.yaw).intersection(area).area > TOUCH:
                on_area += 1
            if last_contact is not None:
                to_contact = math.atan2(last_contact[1] - base.y, last_contact[0] - base.x)
                swings.append(abs(wrap(math.atan2(t.y - base.y, t.x - base.x) - to_contact)))
    return {"under_arm": under_arm, "on_area": on_area, "base_on_area": base_on_area, "swings": swings}


def cmd_plans(args: argparse.Namespace) -> None:
    store = Store(args.store, read_only=True)
    cache: dict[str, Scenario] = {}
    rows = [(r["id"], r["suite"], r["scenario_digest"], r["planner"], r["planner_version"], r["reason"], r["plan"])
            for r in store.runs() if r["plan"] is not None and (r["suite"] == args.suite or r["suite"].startswith(args.suite + "~"))]
    moved: Counter[tuple[str, str]] = Counter()
    valid: Counter[tuple[str, str]] = Counter()
    breaches: dict[tuple[str, str], Counter[str]] = {}
    swing_by: dict[tuple[str, str], list[float]] = {}
    for rid, suite, digest, planner, version, reason, blob in rows:
        key = (planner, version)
        sc = _scenario(store, digest, cache)
        out = audit_plan(sc, Plan.from_json(decompress(blob)))
        swing_by.setdefault(key, []).extend(out["swings"])  # type: ignore[arg-type]
        c = breaches.setdefault(key, Counter())
        c["under_arm digs"] += int(out["under_arm"])  # type: ignore[call-overload]
        c["dumps on the dig area"] += int(out["on_area"])  # type: ignore[call-overload]
        c["digs from a base on the dig area"] += int(out["base_on_area"])  # type: ignore[call-overload]
        c["runs with a base on the dig area"] += bool(out["base_on_area"])
        if reason == "ok":
            valid[key] += 1
            if out["under_arm"] or out["on_area"]:
                moved[key] += 1
                if args.verbose:
                    print(f"  run {rid} {suite} {planner} {version}: {out['under_arm']} digs under the arm, "
                          f"{out['on_area']} dumps on the dig area", file=sys.stderr)
    print(f"store {args.store}, suite {args.suite} (with its sealed draws): {len(rows)} plans")
    for key in sorted(valid):
        s = np.degrees(np.array(swing_by.get(key, [])))
        print(f"{key[0]} {key[1]}: {valid[key]} valid runs, {moved[key]} of them invalid under R "
              f"({dict(breaches[key])}); swing a dump median {np.median(s):.0f}° "
              f"(quartiles {np.percentile(s, 25):.0f}–{np.percentile(s, 75):.0f}°, least {s.min():.1f}°)")
    print(f"total: {sum(moved.values())} of {sum(valid.values())} valid runs would become invalid")


def _contacts(sc: Scenario, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid points of the dig area and the soil volume above the floor in each one's grid square."""
    t = sc.terrain
    area = Polygon(sc.site.dig_area)
    floor = sc.site.floor if sc.site.floor is not None else float(t.z.min())
    xmin, ymin, xmax, ymax = area.bounds
    xs = np.arange(xmin + spacing / 2, xmax, spacing)
    ys = np.arange(ymin + spacing / 2, ymax, spacing)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    inside = shapely.contains_xy(area, pts[:, 0], pts[:, 1])
    pts = pts[inside]
    # volume of each grid square: the terrain's cells whose centres fall in it
    ny, nx = t.z.shape
    cx = t.origin[0] + (np.arange(nx) + 0.5) * t.resolution
    cy = t.origin[1] + (np.arange(ny) + 0.5) * t.resolution
    ix = np.floor((cx - xmin) / spacing).astype(int)
    iy = np.floor((cy - ymin) / spacing).astype(int)
    vol = np.zeros((len(ys), len(xs)))
    ok_x, ok_y = (ix >= 0) & (ix < len(xs)), (iy >= 0) & (iy < len(ys))
    above = np.clip(t.z - floor, 0.0, None) * t.resolution ** 2
    sub = above[np.ix_(ok_y, ok_x)]
    np.add.at(vol, (iy[ok_y][:, None].repeat(ok_x.sum(), 1), ix[ok_x][None, :].repeat(ok_y.sum(), 0)), sub)
    v = vol.ravel()[inside]
    return pts, v


def least_swing(sc: Scenario, c: np.ndarray, strict: bool, alphas: np.ndarray) -> float:
    """The least swing (rad, of ``alphas``) rule R allows a dump after a dig at contact ``c``:
    over bases 2–6.1 m from it in 10° steps (drag toward the base, full length), truck centres
    3.5–7.1 m from the base at that angle either side of the contact's bearing, broadside or
    lengthwise; ``inf`` when none of them is allowed."""
    spec, tspec = sc.machines.excavator, sc.machines.truck
    area = Polygon(sc.site.dig_area)
    keep_outs = [Polygon(k) for k in sc.site.keep_outs]
    s_values = np.arange(spec.reach_min, spec.reach_max + 1e-9, 0.5)
    betas = np.radians(np.arange(0, 360, 10))
    d_max = spec.reach_max + tspec.loading_radius
    d_values = np.arange(spec.clearance, d_max + 1e-9, 0.2)
    for alpha in alphas:
        for beta in betas:
            u = np.array([math.cos(beta), math.sin(beta)])  # from the contact to the base
            for s in s_values:
                b = c + s * u
                if strict and area.contains(Point(*b)):
                    continue
                bearing = beta + math.pi  # from the base to the contact
                drag = min(spec.max_drag_length, s - spec.reach_min)
                bucket = footprint((float(c[0]), float(c[1])), beta, spec.bucket_width, max(drag, 1e-3))
                shadow = MultiPoint([tuple(b), *bucket.exterior.coords]).convex_hull
                cand = []
                for sign in ((1,) if alpha == 0 else (1, -1)):
                    th = bearing + sign * alpha
                    for d in d_values:
                        tx, ty = b[0] + d * math.cos(th), b[1] + d * math.sin(th)
                        for yaw in (th, th + math.pi / 2):
                            cand.append(Polygon(tspec.body(tx, ty, yaw)[0]))
                arr = np.array(cand, dtype=object)
                bad = (shapely.area(shapely.intersection(arr, area)) > TOUCH) | (shapely.area(shapely.intersection(arr, shadow)) > TOUCH)
                for k in keep_outs:
                    bad |= shapely.intersects(arr, k)
                if not bad.all():
                    return float(alpha)
    return math.inf


def cmd_forced(args: argparse.Namespace) -> None:
    store = Store(args.store, read_only=True)
    rows = _maps(store, args.suite)
    if args.family:
        rows = [r for r in rows if r[2] == args.family]
    if args.largest:  # the soil with no forced swing does not depend on the target: the largest one per map decides
        top: dict[tuple[str, str], float] = {}
        for _, sid, family, target in rows:
            top[(family, sid.rsplit("/", 1)[0])] = max(target, top.get((family, sid.rsplit("/", 1)[0]), 0.0))
        rows = [r for r in rows if r[3] == top[(r[2], r[1].rsplit("/", 1)[0])]]
    if args.limit:
        rows = rows[: args.limit]
    cache: dict[str, Scenario] = {}
    alphas = np.radians(np.arange(0, 91, 5))
    gains, per_family = [], Counter()
    for digest, sid, family, target in rows:
        sc = _scenario(store, digest, cache)
        pts, vol = _contacts(sc, args.spacing)
        keep = vol > 1e-6
        pts, vol = pts[keep], vol[keep]
        fill = sc.soil.fill_factor if sc.soil is not None else 1.0
        # contacts in order of volume: the least-swing volume only needs to reach the target
        order = np.argsort(-vol)
        zero, phis = 0.0, []
        for k in order:
            phi = least_swing(sc, pts[k], args.strict, alphas if args.full else alphas[:1])
            phis.append(phi)
            if phi == 0.0:
                zero += vol[k]
            if not args.full and zero >= target:
                break
        holds = zero >= target
        per_family[(family, holds)] += 1
        gains.append(0.0 if holds else math.nan)
        print(f"{sid}: target {target:g} m³; contacts tried {len(phis)} of {len(pts)}; volume above the floor at contacts "
              f"with no forced swing ≥ {zero:.2f} m³ → {'holds the target: no swing can be charged' if holds else 'SHORT of the target'}"
              + (f"; fill {fill:g}" if fill != 1.0 else ""), flush=True)
    print("families (family, zero-swing volume holds the target): count")
    for (family, holds), n in sorted(per_family.items()):
        print(f"  {family} {holds}: {n}")


def _candidates(sc: Scenario, stand: tuple[float, float, float], spread_deg: float) -> list[tuple[tuple[float, float], float]]:
    """Contacts (and drag headings, toward the base) within ``spread_deg`` of the bearing of a truck
    standing at ``stand``, nearest that bearing first, whose bucket stays on the dig area and whose
    arm's shadow stays clear of the truck."""
    spec = sc.machines.excavator
    assert spec is not None
    base = sc.machines.excavator_pose
    area = Polygon(sc.site.dig_area)
    body = _truck_polygon(sc, *stand)
    to_truck = math.atan2(stand[1] - base.y, stand[0] - base.x)
    out = []
    for delta in sorted(np.radians(np.arange(-spread_deg, spread_deg + 1e-9, 1.0)), key=abs):
        th = to_truck + delta
        for dist in np.arange(spec.reach_min + spec.max_drag_length + 0.01, spec.reach_max - 0.01, 0.1):
            c = (base.x + dist * math.cos(th), base.y + dist * math.sin(th))
            fp = footprint(c, th + math.pi, spec.bucket_width, spec.max_drag_length)
            shadow = MultiPoint([(base.x, base.y), *fp.exterior.coords]).convex_hull
            if area.contains(fp) and shadow.intersection(body).area <= TOUCH:
                out.append((c, th + math.pi))
    return out


def witness_plan(sc: Scenario, spread_deg: float) -> Plan:
    """Digs within ``spread_deg`` of the truck's bearing from where the excavator starts, the
    truck driving along its heading between stands off the dig area (see the module's docstring)."""
    spec, tspec = sc.machines.excavator, sc.machines.truck
    assert spec is not None
    base, tp = sc.machines.excavator_pose, sc.machines.truck_pose
    area = Polygon(sc.site.dig_area)
    reach = spec.reach_max + tspec.loading_radius - 0.01
    stands = []
    for k in [*range(0, 41), *range(-1, -41, -1)]:  # ahead first, then back behind the start
        x, y = tp.x + 0.25 * k * math.cos(tp.yaw), tp.y + 0.25 * k * math.sin(tp.yaw)
        if math.hypot(x - base.x, y - base.y) <= reach and _truck_polygon(sc, x, y, tp.yaw).intersection(area).area <= TOUCH:
            stands.append((x, y, tp.yaw))
    z = sc.terrain.z.astype(float).copy()
    floor = sc.site.floor if sc.site.floor is not None else -math.inf
    level_under, _ = track_level_and_tilt(sc, z, spec, base)
    cap = spec.bucket_capacity * (sc.soil.fill_factor if sc.soil is not None else 1.0)
    acts: list = []
    t, turn, loaded, at = 0.0, 0.0, 0.0, (tp.x, tp.y, tp.yaw)
    for stand in stands:
        cands = _candidates(sc, stand, spread_deg)
        while loaded < sc.task.target_volume - 1e-9:
            best = None
            for c, heading in cands:
                h = sc.terrain.height_at(c[0], c[1], z)
                depth = min(spec.max_cut_depth, h - floor)
                if depth < 0.02:
                    continue
                cells = path_cells(sc.terrain, z.shape, c, heading, spec.bucket_width, spec.max_drag_length)
                z2 = z.copy()
                got = cut_along(sc.terrain, z2, c, heading, spec.bucket_width, spec.max_drag_length, h - depth, cap, cells).volume
                jj, ii, _ = cells
                cut = z2[jj, ii] < z[jj, ii]
                if h - depth < level_under and undermining_excess(sc.terrain, z2, spec, base, level_under, jj[cut], ii[cut]) > 0:
                    continue
                if got >= 0.98 * cap:
                    best = (c, heading, depth, z2, got)
                    break
            if best is None:
                break  # no full bucket left near this stand's bearing: the truck moves on
            c, heading, depth, z, got = best
            arrive = t
            if (stand[0], stand[1]) != (at[0], at[1]):
                path = turn_drive_turn(Pose(*at), (stand[0], stand[1]), t, tspec.travel_speed, tspec.yaw_rate, final_yaw=stand[2])
                acts.append(Move("truck", tuple(path)))
                arrive, at = path[-1][0], stand
            d = swing_time(base, turn, c, spec) + spec.min_stroke_time + 1e-6
            acts.append(Dig("excavator", t, t + d, c, heading, depth, spec.max_drag_length))
            t = max(t + d, arrive)
            turn = math.atan2(c[1] - base.y, c[0] - base.x) - base.yaw
            d = swing_time(base, turn, (stand[0], stand[1]), spec) + spec.min_dump_time + 1e-6
            acts.append(Dump("excavator", t, t + d))
            t += d
            turn = math.atan2(stand[1] - base.y, stand[0] - base.x) - base.yaw
            loaded += got
    return Plan(tuple(acts))


def _write_candidate(out: Path, digest: str, plan: Plan, spread: float) -> None:
    """A candidate file for ``earthbench best update --plans``: the plan, its scenario's digest and who made it."""
    out.mkdir(parents=True, exist_ok=True)
    producer = {"kind": "witness", "name": f"scripts/swing_rule_audit.py witness --spread {spread:g}", "config": {"spread": spread}}
    doc = {"scenario_digest": digest, "producer": producer, "plan": json.loads(plan.to_json())}
    (out / f"{digest}.json").write_text(json.dumps(doc))


def cmd_witness(args: argparse.Namespace) -> None:
    store = Store(args.store, read_only=True)
    rows = [(digest, sid, target) for digest, sid, family, target in _maps(store, args.suite) if family == args.family]
    cache: dict[str, Scenario] = {}
    ratios = []
    for digest, sid, target in rows:
        sc = _scenario(store, digest, cache)
        plan = witness_plan(sc, args.spread)
        v = judge(sc, plan)
        m = evaluate(sc, plan, v)
        out = audit_plan(sc, plan)
        sw = np.degrees(np.array(out["swings"]))  # type: ignore[arg-type]
        ok = v.valid and not out["under_arm"] and not out["on_area"]
        if args.out:
            _write_candidate(Path(args.out), digest, plan, args.spread)
        if ok:
            ratios.append(m["time_per_target_m3_ratio"])
        print(f"{sid}: {'valid' if v.valid else 'INVALID ' + ','.join(sorted({x.rule for x in v.violations}))}, "
              f"R breaches {out['under_arm']} + {out['on_area']}; {m['digs']} digs, loaded {m['loaded_volume']:.2f} of {target:g} m³; "
              f"swing a dump median {np.median(sw):.1f}° (max {sw.max():.1f}°); time per target m³ {m['time_per_target_m3']:.2f} s = "
              f"{m['time_per_target_m3_ratio']:.3f} × time_per_m3_lower_bound, "
              f"{m['time_per_target_m3_bound_ratio']:.3f} × the target bound",
              flush=True)
    if ratios:
        r = np.array(ratios)
        print(f"valid under R: {len(r)} of {len(rows)}; their time per target m³ ÷ time_per_m3_lower_bound: "
              f"median {np.median(r):.3f}, max {r.max():.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("plans")
    p.add_argument("store")
    p.add_argument("--suite", default="standard")
    p.add_argument("--verbose", action="store_true")
    f = sub.add_parser("forced")
    f.add_argument("store")
    f.add_argument("--suite", default="standard")
    f.add_argument("--strict", action="store_true", help="keep the excavator's base off the dig area too")
    f.add_argument("--spacing", type=float, default=0.25)
    f.add_argument("--limit", type=int, default=0)
    f.add_argument("--family", default="", help="only this family's scenarios")
    f.add_argument("--largest", action="store_true", help="only each map's largest target (it decides for the smaller ones)")
    f.add_argument("--full", action="store_true", help="the least swing at every contact, not just until the target is held at 0")
    w = sub.add_parser("witness")
    w.add_argument("store")
    w.add_argument("--suite", default="standard")
    w.add_argument("--family", default="bench.bench")
    w.add_argument("--spread", type=float, default=10.0, help="largest swing (degrees) a dig may take from the truck's bearing")
    w.add_argument("--out", default="", help="write each plan here as a candidate file for `earthbench best update --plans`")
    args = ap.parse_args()
    {"plans": cmd_plans, "forced": cmd_forced, "witness": cmd_witness}[args.cmd](args)


if __name__ == "__main__":
    main()
