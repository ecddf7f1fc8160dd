"""The backhoe's rules: digs (reach, depth, drag, dig area, floor, undermining, tilt,
duration, no machine under the bucket or the arm, the truck's ground left as it was) and dumps
into the truck (reach, duration, the truck still)."""

from __future__ import annotations

import math


from ..lazy import moved_getattr
from ..cut import cut_level, footprint, path_cells
from ..motion import ABS_TOL, dump_reach_excess, min_dig_time, min_dump_time
from ..plan import Dig, Dump
from ..rules import stroke_start
from ..rules import track_level_and_tilt as _track_level_and_tilt
from ..rules import undermining_excess as _undermining_excess
from ..world import ExcavatorSpec, Pose
from .site import near_dig, truck_stands, undercut
from .state import DigRecord, Replay


def dig(r: Replay, n: int, a: Dig) -> None:
    spec = r.specs.get(a.machine)
    if a.machine != "excavator" or not isinstance(spec, ExcavatorSpec):
        r.flag(n, "wrong_machine", 1.0, f"{a.machine} cannot dig; only the excavator digs")
        return
    base = r.timelines[a.machine].pose(a.t_start)
    level_under, _ = _station(r, n, spec, base)
    if r.bucket > ABS_TOL:
        r.flag(n, "bucket_not_empty", r.bucket, f"the bucket still holds {r.bucket:.4f} m³")
    if a.depth > spec.max_cut_depth + ABS_TOL:
        r.flag(n, "cut_depth", a.depth - spec.max_cut_depth, f"depth {a.depth:.4f} m; limit {spec.max_cut_depth} m")
    if a.drag_length > spec.max_drag_length + ABS_TOL:
        r.flag(n, "drag_length", a.drag_length - spec.max_drag_length, f"drag {a.drag_length:.4f} m; limit {spec.max_drag_length} m")
    end = (a.contact[0] + math.cos(a.heading) * a.drag_length, a.contact[1] + math.sin(a.heading) * a.drag_length)
    for label, pt in (("contact", a.contact), ("drag end", end)):
        dist = math.hypot(pt[0] - base.x, pt[1] - base.y)
        if dist > spec.reach_max + ABS_TOL or dist < spec.reach_min - ABS_TOL:
            off = max(dist - spec.reach_max, spec.reach_min - dist)
            r.flag(n, "reach", off, f"{label} is {dist:.3f} m from the base; reach {spec.reach_min}–{spec.reach_max} m")
    fp = footprint(a.contact, a.heading, spec.bucket_width, a.drag_length)
    if not r.dig_area_tol.contains(fp):
        out = fp.difference(r.dig_area).area
        r.flag(n, "outside_dig_area", max(out, ABS_TOL), f"{out:.4f} m² of the bucket footprint lies outside the dig area")
    for ko in r.keep_outs:
        if fp.intersects(ko):
            r.flag(n, "keep_out", max(fp.intersection(ko).area, ABS_TOL), "the bucket footprint enters a keep-out zone")
    stroke = stroke_start(base, r.turn, a.contact, spec, a.t_start, a.t_end)
    near_dig(r, n, "excavator", a.contact, a.heading, spec.bucket_width, a.drag_length, base, stroke, a.t_end)
    stands = truck_stands(r, stroke, a.t_end, a.contact, a.heading, spec.bucket_width, a.drag_length)
    need = min_dig_time(base, r.turn, a.contact, spec)
    if a.t_end - a.t_start < need - ABS_TOL:
        r.flag(
            n, "duration", need - (a.t_end - a.t_start), f"dig lasts {a.t_end - a.t_start:.3f} s; the swing and stroke need {need:.3f} s"
        )
    level = cut_level(r.terrain, r.z, a.contact, a.depth)
    floor = r.sc.site.floor
    if floor is not None and level < floor - ABS_TOL:
        # only on the exact track is a cut below the floor the plan's own error; on the realistic
        # track (soil or a scan) the ground it meets is not the one its planner could know, and the
        # machine's grade control holds the floor (docs/DESIGN.md §5, "Rules where the planner's
        # model is not the world")
        if r.soil is None and r.sc.sensing is None:
            r.flag(n, "below_floor", floor - level, f"cut level {level:.4f} m is below the floor {floor} m")
        level = floor
    cells = path_cells(r.terrain, r.z.shape, a.contact, a.heading, spec.bucket_width, a.drag_length)
    jj, ii, _ = cells
    before = r.z[jj, ii]
    got, nominal = r.cut(a.contact, a.heading, spec.bucket_width, a.drag_length, level, spec.bucket_capacity, a.depth, cells)
    vol = got.volume
    # no cut reaches below the undermining line while its level is at or above the tracks' ground
    excess = -math.inf
    if level < level_under - ABS_TOL:
        cut = r.z[jj, ii] < before
        excess = _undermining_excess(r.terrain, r.z, spec, base, level_under, jj[cut], ii[cut])
    if excess > ABS_TOL:
        r.flag(
            n,
            "undermining",
            excess,
            f"the cut leaves ground {excess:.3f} m below the line falling {spec.undermine_slope:g} m per m"
            f" from the tracks (ground under them {level_under:.3f} m)",
        )
    r.settle()
    undercut(r, n, stands)
    r.bucket += vol
    r.removed += vol
    r.digs.append(DigRecord(n, vol, vol / spec.bucket_capacity, None if nominal is None else nominal.volume))
    r.turn = math.atan2(a.contact[1] - base.y, a.contact[0] - base.x) - base.yaw


def _station(r: Replay, n: int, spec: ExcavatorSpec, base: Pose) -> tuple[float, float]:
    """Track level and tilt where the excavator stands to work, judged once as it arrives."""
    if r.station is None or r.station[0] != base:
        level, tilt = _track_level_and_tilt(r.sc, r.z, spec, base)
        r.station = (base, level, tilt)
        if tilt > spec.max_tilt + ABS_TOL:
            r.flag(
                n,
                "tilt",
                tilt - spec.max_tilt,
                f"the excavator stands on ground tilted {math.degrees(tilt):.1f}°; limit {math.degrees(spec.max_tilt):.1f}°",
            )
    return r.station[1], r.station[2]


def dump(r: Replay, n: int, a: Dump, spec: ExcavatorSpec) -> None:
    truck_spec = r.sc.machines.truck
    tpos = r.truck_for_dump(n, a.t_start, a.t_end)
    base = r.timelines[a.machine].pose(a.t_start)
    _station(r, n, spec, base)
    off = dump_reach_excess(base, (tpos.x, tpos.y), spec, truck_spec)
    if off > ABS_TOL:
        dist = math.hypot(tpos.x - base.x, tpos.y - base.y)
        r.flag(n, "dump_reach", off, f"the truck is {dist:.3f} m from the base; its loading area is out of reach")
    need = min_dump_time(base, r.turn, (tpos.x, tpos.y), spec)
    if a.t_end - a.t_start < need - ABS_TOL:
        r.flag(n, "duration", need - (a.t_end - a.t_start), f"dump lasts {a.t_end - a.t_start:.3f} s; the swing and dump need {need:.3f} s")
    r.empty_bucket(a.t_end)
    r.turn = math.atan2(tpos.y - base.y, tpos.x - base.x) - base.yaw


# moved to earthbench.rules (0.2): the old names keep working for a release, with a warning
__getattr__ = moved_getattr(__name__, dict.fromkeys(("ground_under", "track_level_and_tilt", "undermining_excess"), "earthbench.rules"))
