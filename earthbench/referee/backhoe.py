"""The backhoe's rules: digs (reach, depth, drag, dig area, floor, undermining, tilt,
duration, and through :mod:`~earthbench.referee.site` no machine under the bucket or the arm)
and dumps into the truck (reach, duration). The replay loop (:mod:`earthbench.referee.loop`)
calls :func:`act` for each of the excavator's actions and :func:`after_cut` once it has made a
dig's cut; what a dig does to the state (the cut, the bucket, the upper body's turn) is the loop's."""

from __future__ import annotations

import math


from ..cut import Cut, cut_level, footprint, path_cells
from ..motion import ABS_TOL, dump_reach_excess, min_dig_time, min_dump_time
from ..plan import Dig, Dump
from .. import compat, rules  # its names that lived here until 0.2 stay out of this module's namespace (see __getattr__)
from ..world import ExcavatorSpec, Pose
from .site import around_dig
from .state import Replay, Stroke, Violation


def act(r: Replay, n: int, a: Dig | Dump) -> Stroke | None:
    """Check a dig (the machine must be the excavator) or an excavator's dump; returns the dig's
    stroke for the loop to cut, or None when there is nothing to cut."""
    spec = r.specs.get(a.machine)
    if isinstance(a, Dump):
        assert isinstance(spec, ExcavatorSpec)
        _dump(r, n, a, spec)
        return None
    if a.machine != "excavator" or not isinstance(spec, ExcavatorSpec):
        r.violations.append(Violation(n, "wrong_machine", 1.0, f"{a.machine} cannot dig; only the excavator digs"))
        return None
    return _dig(r, n, a, spec)


def _dig(r: Replay, n: int, a: Dig, spec: ExcavatorSpec) -> Stroke:
    base = r.timelines[a.machine].pose(a.t_start)
    _station(r, n, spec, base)
    if r.bucket > ABS_TOL:
        r.violations.append(Violation(n, "bucket_not_empty", float(r.bucket), f"the bucket still holds {r.bucket:.4f} m³"))
    if a.depth > spec.max_cut_depth + ABS_TOL:
        r.violations.append(Violation(n, "cut_depth", float(a.depth - spec.max_cut_depth),
            f"depth {a.depth:.4f} m; limit {spec.max_cut_depth} m"))
    if a.drag_length > spec.max_drag_length + ABS_TOL:
        r.violations.append(Violation(n, "drag_length", float(a.drag_length - spec.max_drag_length),
            f"drag {a.drag_length:.4f} m; limit {spec.max_drag_length} m"))
    end = (a.contact[0] + math.cos(a.heading) * a.drag_length, a.contact[1] + math.sin(a.heading) * a.drag_length)
    for label, pt in (("contact", a.contact), ("drag end", end)):
        dist = math.hypot(pt[0] - base.x, pt[1] - base.y)
        if dist > spec.reach_max + ABS_TOL or dist < spec.reach_min - ABS_TOL:
            off = max(dist - spec.reach_max, spec.reach_min - dist)
            r.violations.append(Violation(n, "reach", float(off),
                f"{label} is {dist:.3f} m from the base; reach {spec.reach_min}–{spec.reach_max} m"))
    fp = footprint(a.contact, a.heading, spec.bucket_width, a.drag_length)
    if not r.dig_area_tol.contains(fp):
        out = fp.difference(r.dig_area).area
        r.violations.append(Violation(n, "outside_dig_area", float(max(out, ABS_TOL)),
            f"{out:.4f} m² of the bucket footprint lies outside the dig area"))
    for ko in r.keep_outs:
        if fp.intersects(ko):
            r.violations.append(Violation(n, "keep_out", float(max(fp.intersection(ko).area, ABS_TOL)),
                "the bucket footprint enters a keep-out zone"))
    stroke = rules.stroke_start(base, r.turn, a.contact, spec, a.t_start, a.t_end)
    stands = around_dig(r, n, "excavator", a.contact, a.heading, spec.bucket_width, a.drag_length, base, stroke, a.t_end)
    need = min_dig_time(base, r.turn, a.contact, spec)
    if a.t_end - a.t_start < need - ABS_TOL:
        r.violations.append(Violation(n, "duration", float(need - (a.t_end - a.t_start)),
            f"dig lasts {a.t_end - a.t_start:.3f} s; the swing and stroke need {need:.3f} s"))
    level = cut_level(r.terrain, r.z, a.contact, a.depth)
    floor = r.sc.site.floor
    if floor is not None and level < floor - ABS_TOL:
        # only on the exact track is a cut below the floor the plan's own error; on the realistic
        # track (soil or a scan) the ground it meets is not the one its planner could know, and the
        # machine's grade control holds the floor (docs/DESIGN.md §5, "Rules where the planner's
        # model is not the world")
        if r.soil is None and r.sc.sensing is None:
            r.violations.append(Violation(n, "below_floor", float(floor - level),
                f"cut level {level:.4f} m is below the floor {floor} m"))
        level = floor
    cells = path_cells(r.terrain, r.z.shape, a.contact, a.heading, spec.bucket_width, a.drag_length)
    return Stroke("excavator", a.contact, a.heading, spec.bucket_width, a.drag_length, level, spec.bucket_capacity, a.depth,
                  cells, r.z[cells[0], cells[1]], base, stands)


def after_cut(r: Replay, n: int, a: Dig, stroke: Stroke, got: Cut, nominal: Cut | None) -> None:
    """``undermining``: no cut reaches below the undermining line while its level is at or above the tracks' ground."""
    assert r.station is not None and stroke.base is not None
    spec = r.specs["excavator"]
    assert isinstance(spec, ExcavatorSpec)
    level_under, level = r.station[1], stroke.level
    jj, ii, _ = stroke.cells
    excess = -math.inf
    if level < level_under - ABS_TOL:
        cut = r.z[jj, ii] < stroke.before
        excess = rules.undermining_excess(r.terrain, r.z, spec, stroke.base, level_under, jj[cut], ii[cut])
    if excess > ABS_TOL:
        r.violations.append(Violation(n, "undermining", float(excess),
            f"the cut leaves ground {excess:.3f} m below the line falling {spec.undermine_slope:g} m per m"
            f" from the tracks (ground under them {level_under:.3f} m)"))


def _station(r: Replay, n: int, spec: ExcavatorSpec, base: Pose) -> tuple[float, float]:
    """Track level and tilt where the excavator stands to work, judged once as it arrives."""
    if r.station is None or r.station[0] != base:
        level, tilt = rules.track_level_and_tilt(r.sc, r.z, spec, base)
        r.station = (base, level, tilt)
        if tilt > spec.max_tilt + ABS_TOL:
            r.violations.append(Violation(n, "tilt", float(tilt - spec.max_tilt),
                f"the excavator stands on ground tilted {math.degrees(tilt):.1f}°; limit {math.degrees(spec.max_tilt):.1f}°"))
    return r.station[1], r.station[2]


def _dump(r: Replay, n: int, a: Dump, spec: ExcavatorSpec) -> None:
    truck_spec = r.sc.machines.truck
    tpos = r.timelines["truck"].pose(a.t_start)
    base = r.timelines[a.machine].pose(a.t_start)
    _station(r, n, spec, base)
    off = dump_reach_excess(base, (tpos.x, tpos.y), spec, truck_spec)
    if off > ABS_TOL:
        dist = math.hypot(tpos.x - base.x, tpos.y - base.y)
        r.violations.append(Violation(n, "dump_reach", float(off),
            f"the truck is {dist:.3f} m from the base; its loading area is out of reach"))
    need = min_dump_time(base, r.turn, (tpos.x, tpos.y), spec)
    if a.t_end - a.t_start < need - ABS_TOL:
        r.violations.append(Violation(n, "duration", float(need - (a.t_end - a.t_start)),
            f"dump lasts {a.t_end - a.t_start:.3f} s; the swing and dump need {need:.3f} s"))


__getattr__ = compat.forward(__name__)  # the rules' predicates that lived here (earthbench.compat)
