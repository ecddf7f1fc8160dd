"""Where the truck stands while the excavator digs an area: the planner's choice, not the NLP's.

The local NLP models neither the arm's ground shadow nor the truck's ground (rules version 2,
docs/referee.md): left free, its truck drives onto the dig area beside the arm, where no dig
may pass over it. So the stand is a decision of the layer that chooses the areas (issue 48),
made when an area comes up, on the grid as dug so far: among the stands
``planners/truck_stands.py`` offers for the area's base (off the dig area, on ground within the
truck's limits, in dump reach), cheapest first in the truck's drive plus the swing its dumps
cost, the first one clear of every dig the area can hold (the hull of the base and the area,
which holds each dig's arm shadow) that the truck can drive to on kept ground without touching
the excavator where it will stand. The local NLP is then bound to it (``PhaseNLP.bounds``'s
``truck_stand``), so its swings are priced against where the truck will really stand, and the
conversion drives the truck there (``Converter.move_both``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import shapely
from shapely.geometry import MultiPoint, Polygon

from earthbench.motion import turn_drive_turn
from earthbench.plan import Move
from earthbench.world import Pose, Scenario

from ..stability import face_blur
from ..truck_stands import GAP
from .convert import TILT_MARGIN, Converter, SimState, fastest_steps, integrate
from .judge import AT_THE_STAND, StandJudge
from .hierarchy import Area, Layout, candidate_areas, greedy_tour, level_stand, site_layout

#: Metres between the truck's centre and the dig area's edge (half its width, the area's
#: shadow and the gap) and under its dump reach, for an area to face away from the truck.
FACE_AWAY_MARGIN = 1.3
#: Stands looked at, cheapest first, before the truck is left to the conversion's own choice.
TRIES = 300
#: Turns (rad) tried for the stand of a tile facing away from the truck when the straight one is too steep.
AWAY_TURNS = (0.3, -0.3, 0.6, -0.6)
#: Share of an area's V_max the tiles facing away must hold to be toured alone (:func:`tour`).
MIN_AWAY = 0.5


def area_shadow(area: Area, bucket_width: float) -> Polygon:
    """What every dig of ``area`` may shade: the hull of its base and its square (its contacts'
    bucket footprints stay inside the square, :func:`.hierarchy.candidate_areas`), widened by
    half a bucket."""
    cx, cy = area.centre
    half = math.hypot(cx - area.px, cy - area.py)
    ux, uy = math.cos(area.psi), math.sin(area.psi)
    corners = [(cx + a * half * ux - b * half * uy, cy + a * half * uy + b * half * ux) for a in (-1, 1) for b in (-1, 1)]
    return MultiPoint([*corners, area.base]).convex_hull.buffer(bucket_width / 2)


def base_pose(area: Area) -> Pose:
    """The excavator at the area's base, facing it (as the local NLP leaves it, near enough)."""
    return Pose(area.base[0], area.base[1], math.atan2(area.centre[1] - area.base[1], area.centre[0] - area.base[0]))


def truck_stand(conv: Converter, st: SimState, area: Area, buckets: float) -> Pose | None:
    """The truck's stand for ``area`` (module docstring): the first of the stands cheapest in
    the truck's drive plus ``buckets`` dumps' swing (:meth:`TruckStands.parking`) that keeps
    every rule; None when none of the first :data:`TRIES` does (the NLP and the conversion then
    place the truck as 0.10.5 did)."""
    stands = conv.stands(st)
    base = base_pose(area)
    shadow = area_shadow(area, conv.exc_spec.bucket_width)
    shapely.prepare(shadow)
    ts = conv.truck_spec
    bearing = math.atan2(area.centre[1] - base.y, area.centre[0] - base.x)
    for tried, stand in enumerate(stands.parking(base, st.truck, bearing, buckets)):
        if tried >= TRIES:
            break
        body = shapely.polygons(np.asarray(ts.body(stand.x, stand.y, stand.yaw)[0]))
        if shapely.distance(shadow, body) <= GAP:
            continue
        path = turn_drive_turn(st.truck, (stand.x, stand.y), st.t, ts.travel_speed, ts.yaw_rate, final_yaw=stand.yaw)
        if conv.clear(base, stand) and stands.path_ok(path) and conv.clear(base, path):
            return stand
    return None


#: Metres every corner of an area keeps inside the reach annulus for the excavator to dig it
#: from where it stands (:func:`kept_base`), and its tracks keep from the area.
REACH_MARGIN, TRACK_GAP = 0.25, 0.3


def kept_base(conv: Converter, st: SimState, area: Area) -> Area:
    """``area`` with the excavator's present stand as its base when the whole area is in reach
    from there, its tracks clear of it and the stand level enough (area sequencing: no
    relocation between neighbouring areas one stand serves, as the swing it saves is the
    driving's and the truck's too); else ``area`` as it is."""
    es = conv.exc_spec
    cx, cy = area.centre
    half = math.hypot(cx - area.px, cy - area.py)
    ux, uy = math.cos(area.psi), math.sin(area.psi)
    square = Polygon([(cx + a * half * ux - b * half * uy, cy + a * half * uy + b * half * ux)
                      for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    d = [math.hypot(x - st.exc.x, y - st.exc.y) for x, y in square.exterior.coords]
    if max(d) > es.reach_max - REACH_MARGIN or min(d) < es.reach_min + REACH_MARGIN:
        return area
    if Polygon(es.body(st.exc.x, st.exc.y, st.exc.yaw)[0]).distance(square) < TRACK_GAP:
        return area
    if conv.station(st)[1] > es.max_tilt - TILT_MARGIN or math.dist(area.base, (st.exc.x, st.exc.y)) < 1e-9:
        return area
    return dataclasses.replace(area, base=(st.exc.x, st.exc.y))


def stand_judge(c: Any, scenario: Scenario, others: tuple[np.ndarray, ...] = ()) -> StandJudge:
    """How the planner's configuration ``c`` judges a stand's tilt on ``scenario``'s grid: with
    ``c.swing_first`` (0.13.0, whose stands stand on the dig area) blurred by the distance a scan
    may misplace a face (0 on the exact track) and on ``others``, earlier scans; else at the stand."""
    return StandJudge(face_blur(scenario), others) if c.swing_first else AT_THE_STAND


def candidate_areas_for(c: Any, scenario: Scenario, z: np.ndarray, side: float, layout: Layout | None = None,
                        judge: StandJudge | None = None) -> list[Area]:
    """The candidate areas of the planner's configuration ``c`` (:func:`.hierarchy.candidate_areas`);
    with ``c.face_away``, those whose base beyond them from the truck leaves the truck a stand on
    their far side, off the dig area and in dump reach (the dig area's row on the truck's side),
    face that way, the tile facing the truck kept as ``Area.toward``; with ``c.side_by_swing``,
    each area faces the side (toward the truck, away, or either way across) whose base leaves the
    truck a stand with the least swing (:func:`least_swing`), the others kept as fallbacks.
    ``judge``: how a stand's tilt is judged (default: :func:`stand_judge` of ``c``)."""
    m = scenario.machines
    away = m.excavator.reach_max + m.truck.loading_radius - FACE_AWAY_MARGIN if c.face_away else None
    areas = candidate_areas(scenario, z, side, c.dig_depth, c.area_vmax, c.base_offset, c.truck_offset, c.truck_angle,
                            layout, away, AWAY_TURNS if c.swing_first else (),
                            stand_judge(c, scenario) if judge is None else judge)
    if c.swing_first:
        dig = Polygon(scenario.site.dig_area)
        shapely.prepare(dig)
        areas = [_priced(scenario, dig, a) for a in areas]
    if not c.side_by_swing or len(areas) < 2:
        return areas
    lay = layout or site_layout(scenario)
    dig = Polygon(scenario.site.dig_area)
    shapely.prepare(dig)
    return [_least_swing_side(scenario, z, dig, a, lay, c.base_offset, side) for a in areas]


def _priced(scenario: Scenario, dig: Polygon, area: Area | None) -> Area | None:
    """``area`` and its fallbacks, each with its least swing (:func:`least_swing`)."""
    if area is None:
        return None
    return dataclasses.replace(area, swing=least_swing(scenario, dig, area), toward=_priced(scenario, dig, area.toward))


def tour(c: Any, areas: list[Area], start: tuple[float, float], target: float, exc: Any) -> list[Area]:
    """The areas in the order the global problem is seeded with (:func:`.hierarchy.greedy_tour`).
    With ``c.swing_first`` (0.13.0, issue 49) the tiles the truck serves from beyond them (facing
    away, the dump on the dig's bearing) are toured alone while they hold ``MIN_AWAY`` of an area,
    and every area's work counts its least swing (``Area.swing``): the global problem and the
    seed tour knew nothing of where the truck may stand, and chose areas it serves only behind
    the excavator (a swing of 110–120° a dump on dem and paper-extensive)."""
    work_per_m3 = (exc.min_stroke_time + exc.min_dump_time + 2.0) / (exc.bucket_capacity * c.fill_estimate)
    if not c.swing_first:
        return greedy_tour(areas, start, target, exc.travel_speed, work_per_m3)
    away = [a for a in areas if a.toward is not None]
    if sum(a.estimate for a in away) >= MIN_AWAY * c.area_vmax:
        areas = away
    swing_per_m3 = 2.0 / exc.swing_rate / (exc.bucket_capacity * c.fill_estimate)
    return greedy_tour(areas, start, target, exc.travel_speed, work_per_m3, swing_per_m3=swing_per_m3)


def _across(scenario: Scenario, z: np.ndarray, area: Area, toward: tuple[float, float], base_offset: float,
            side: float) -> Area | None:
    """``area``'s tile with its base ``base_offset`` toward ``toward`` (a level stand), or None."""
    base = level_stand(scenario, z, area.centre, toward, base_offset, side)
    if base is None:
        return None
    cx, cy = area.centre
    off = (area.truck[0] - area.base[0], area.truck[1] - area.base[1])
    return dataclasses.replace(area, px=cx - toward[0] * side / 2, py=cy - toward[1] * side / 2,
                               psi=math.atan2(toward[1], toward[0]), base=base, truck=(base[0] + off[0], base[1] + off[1]),
                               toward=None)


def _least_swing_side(scenario: Scenario, z: np.ndarray, dig: Polygon, area: Area, lay: Layout, base_offset: float,
                      side: float) -> Area:
    """``area``'s tiles (facing the truck, away from it, and either way across the loading axis)
    whose base leaves the truck less swing than the tile facing the truck (:func:`least_swing`),
    least first, chained as fallbacks (``Area.toward``) that end at the tile facing the truck."""
    tx, ty = lay.toward_start
    paper = area.toward if area.toward is not None else area  # facing the truck: the last fallback
    tiles = [area] if area.toward is not None else []
    tiles += [t for t in (_across(scenario, z, area, (tx, ty), base_offset, side),
                          _across(scenario, z, area, (-tx, -ty), base_offset, side)) if t is not None]
    costs = [least_swing(scenario, dig, t) for t in tiles]
    paper_cost = least_swing(scenario, dig, paper)
    chain = dataclasses.replace(paper, toward=None)
    for k in sorted(range(len(tiles)), key=lambda k: (round(costs[k], 3), k), reverse=True):
        if costs[k] < paper_cost - 1e-3:
            chain = dataclasses.replace(tiles[k], toward=chain)
    return chain


def least_swing(scenario: Scenario, dig: Polygon, area: Area) -> float:
    """The least swing (rad) from ``area``'s centre to a truck in dump reach of its base, the
    truck's body (its half width and the gap) off the dig area and clear of the area's digs
    (:func:`area_shadow`); π when there is none. An estimate for choosing the side an area faces."""
    e, t = scenario.machines.excavator, scenario.machines.truck
    bx, by = area.base
    rad = np.arange(e.clearance + 0.3, e.reach_max + t.loading_radius - 0.3, 0.3)
    ang = np.radians(np.arange(-180.0, 180.0, 5.0))
    r, a = np.meshgrid(rad, ang)
    pts = shapely.points(bx + r.ravel() * np.cos(a.ravel()), by + r.ravel() * np.sin(a.ravel()))
    keep = t.width / 2 + GAP
    ok = (shapely.distance(dig, pts) >= keep) & (shapely.distance(area_shadow(area, e.bucket_width), pts) >= keep)
    if not ok.any():
        return math.pi
    bearing = math.atan2(area.centre[1] - by, area.centre[0] - bx)
    return float(np.min(np.abs((a.ravel()[ok] - bearing + math.pi) % (2 * math.pi) - math.pi)))


def place(c: Any, conv: Converter, st: SimState, area: Area, buckets: float) -> tuple[Area, Pose | None]:
    """The area as the local problem digs it (its base kept when the excavator reaches it from
    where it stands, ``c.keep_base``) and the truck's stand (``c.place_truck``; None: the NLP
    places the truck). An area facing away from the truck falls back to its tile facing the
    truck (``Area.toward``) when the truck has no stand beyond it."""
    stand, tile = None, area
    while tile is not None and stand is None:
        area = kept_base(conv, st, tile) if c.keep_base else tile
        stand = truck_stand(conv, st, area, buckets) if c.place_truck else None
        tile = tile.toward
    return area, stand


def served(c: Any, conv: Converter, st: SimState, areas: list[Area], buckets: float) -> list[Area]:
    """The ``areas`` for which :func:`place` finds the truck a stand: what a window's global problem
    is given once areas without one have proved hopeless (:meth:`.hierarchy.Standless.hopeless`)."""
    return [a for a in areas if place(c, conv, st, a, buckets)[1] is not None]


def to_stand(conv: Converter, st: SimState, ve: np.ndarray, we: np.ndarray, dts: np.ndarray, stand: Pose) -> str | None:
    """Phase 0 with the truck's stand chosen: the excavator along the NLP's controls and the
    truck straight to ``stand`` (turn, drive, turn; the NLP's truck ends within ``stand_tol``
    of it), together when they keep the clearance, else one after the other; None (nothing
    emitted) when the truck's way breaks its ground limits or no order keeps the clearance."""
    es, ts = conv.exc_spec, conv.truck_spec
    ne = integrate(st.exc, ve, we, dts, es.travel_speed, es.yaw_rate)
    if conv.retime:
        dts = fastest_steps(ne, np.asarray(dts, float), es.travel_speed, es.yaw_rate)
    times = st.t + np.concatenate([[0.0], np.cumsum(dts)])
    still = np.max(np.hypot(ne[:, 0] - ne[0, 0], ne[:, 1] - ne[0, 1])) < 1e-6 and abs(ne[-1, 2] - ne[0, 2]) < 1e-6
    pe = [(float(t), float(x), float(y), float(w)) for t, (x, y, w) in zip(times, ne)]
    pt = turn_drive_turn(st.truck, (stand.x, stand.y), st.t, ts.travel_speed, ts.yaw_rate, final_yaw=stand.yaw)
    if len(pt) < 2:  # the truck stands there already
        return "excavator" if conv.move_excavator(st, ve, we, np.diff(times)) else None
    if not conv.stands(st).path_ok(pt):
        return None
    span_e, span_t = float(times[-1] - times[0]), pt[-1][0] - pt[0][0]
    shift = lambda path, dt: [(t + dt, x, y, w) for t, x, y, w in path]  # noqa: E731
    orders = [("together", pe, pt)] if not still else []
    orders += [("truck-first", shift(pe, span_t), pt), ("excavator-first", pe, shift(pt, span_e))]
    for how, e_path, t_path in orders:
        e_end, t_end = Pose(*e_path[-1][1:]), Pose(*t_path[-1][1:])
        if how == "together":
            ok = conv.clear(e_path, t_path) and conv.clear(e_end, t_path) and conv.clear(e_path, t_end)
        else:  # one machine waits where it is while the other moves
            e0, t0 = (st.exc, t_end) if how == "truck-first" else (e_end, st.truck)
            ok = conv.clear(e0, t_path) and (still or conv.clear(e_path, t0))
        if ok:
            if not still:
                st.actions.append(Move("excavator", tuple(e_path)))
            st.actions.append(Move("truck", tuple(t_path)))
            st.exc, st.truck = e_end, t_end
            st.t = max(float(e_path[-1][0]), float(t_path[-1][0]))
            return "truck" if still else how
    return None
