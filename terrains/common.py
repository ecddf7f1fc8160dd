"""Helpers every terrain generator shares: scenario assembly, dig-area masks, volumes and checks.

A generator builds its scenario with :func:`assemble_scenario`, which ends in
:func:`check_scenario`, so a target the site cannot hold
or machine poses the referee would reject fail at generation time with a
:class:`~earthbench.errors.ScenarioError`, not later inside a planner run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon

from earthbench.errors import ScenarioError
from earthbench.world import Budget, Heightmap, LoaderSpec, Machines, Pose, Scenario, Site, Task, TruckSpec

#: A site must hold at least this multiple of its target above the floor (issue 4), so a
#: planner has to choose where to dig rather than scrape up everything there is.
MIN_VOLUME_FACTOR = 2.0


Point = tuple[float, float]
PoseLike = tuple[float, float, float]


def rectangle(xmin: float, ymin: float, xmax: float, ymax: float) -> tuple[Point, ...]:
    """The axis-aligned rectangle as a polygon, counter-clockwise from the lower-left corner."""
    return ((xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax))


def paper_poses(
    xmin: float, xmax: float, ymax: float, excavator: PoseLike | None = None, truck: PoseLike | None = None
) -> tuple[Pose, Pose]:
    """(excavator, truck) poses, each the given one or the STL-TAMP paper's default offset from
    the map's corners: the excavator 1.0 m east and 1.2 m north of the north-east corner facing
    west, the truck 2.0 m east of the west edge and 7.0 m north of the map facing east. Offsets
    rather than a scaling keep the drive to the map the same on larger maps."""
    return (Pose(*(excavator or (xmax + 1.0, ymax + 1.2, math.pi))), Pose(*(truck or (xmin + 2.0, ymax + 7.0, 0.0))))


def assemble_scenario(
    scenario_id: str,
    terrain: Heightmap,
    *,
    dig_area: Sequence[Point],
    target_volume: float,
    truck_pose: Pose,
    truck_capacity: float,
    excavator_pose: Pose | None = None,
    loader_pose: Pose | None = None,
    floor: float | None = 0.0,
    budget: Budget | None = None,
    meta: dict[str, Any],
) -> Scenario:
    """The checked scenario of a generator: a backhoe site when ``excavator_pose`` is given, a
    wheel-loader site (default loader, no excavator) when ``loader_pose`` is; the default budget
    unless one is given. Raises ScenarioError as :func:`check_scenario` does."""
    if (excavator_pose is None) == (loader_pose is None):
        raise ValueError("assemble_scenario needs exactly one of excavator_pose and loader_pose")
    truck = TruckSpec(capacity=truck_capacity)
    if loader_pose is None:
        machines = Machines(truck=truck, truck_pose=truck_pose, excavator_pose=excavator_pose)
    else:
        machines = Machines(
            truck=truck, truck_pose=truck_pose, excavator=None, excavator_pose=None, loader=LoaderSpec(), loader_pose=loader_pose
        )
    return check_scenario(
        Scenario(
            id=scenario_id,
            terrain=terrain,
            site=Site(dig_area=tuple(dig_area), floor=floor),
            machines=machines,
            task=Task(target_volume),
            track="backhoe" if loader_pose is None else "wheel_loader",
            budget=budget or Budget(),
            meta=meta,
        )
    )


def backhoe_site(
    scenario_id: str,
    terrain: Heightmap,
    *,
    dig_area: Sequence[Point],
    target_volume: float,
    corner: tuple[float, float, float],
    excavator: PoseLike | None,
    truck: PoseLike | None,
    truck_capacity: float,
    budget: Budget | None,
    meta: dict[str, Any],
    floor: float | None = 0.0,
) -> Scenario:
    """:func:`assemble_scenario` for a backhoe site whose machines stand where the generator's
    ``excavator`` and ``truck`` parameters say, or at the paper's offsets (:func:`paper_poses`)
    from the map's ``corner`` (west edge, east edge, north edge): the tail the backhoe generators share."""
    exc, trk = paper_poses(*corner, excavator, truck)
    return assemble_scenario(scenario_id, terrain, dig_area=dig_area, floor=floor, target_volume=target_volume,
                             excavator_pose=exc, truck_pose=trk, truck_capacity=truck_capacity, budget=budget, meta=meta)


def round_heights(z: np.ndarray) -> np.ndarray:
    """Heights rounded to 0.1 mm: float noise below that never changes a digest across machines."""
    return np.round(np.asarray(z, dtype=np.float64), 4) + 0.0  # + 0.0 turns -0.0 into 0.0


def polygon_mask(terrain: Heightmap, polygon) -> np.ndarray:
    """Boolean ``[ny, nx]`` mask of the cells whose centre lies inside (or on) ``polygon``."""
    xs, ys = terrain.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    poly = Polygon(polygon)
    return shapely.contains_xy(poly, X, Y) | shapely.intersects_xy(poly.boundary, X, Y)


def dig_area_volume(scenario: Scenario) -> float:
    """Bank volume (m³) above the floor inside the dig area; 0 m when the site has no floor."""
    mask = polygon_mask(scenario.terrain, scenario.site.dig_area)
    floor = scenario.site.floor if scenario.site.floor is not None else 0.0
    return scenario.terrain.volume_above(floor, mask)


def reachable_volume(scenario: Scenario) -> float:
    """Volume above the floor in the dig area whose cells lie in the excavator's reach annulus
    from its initial pose: what a planner can dig without moving the base."""
    sc = scenario
    exc, pose = sc.machines.excavator, sc.machines.excavator_pose
    if exc is None or pose is None:
        return 0.0
    xs, ys = sc.terrain.cell_centres()
    X, Y = np.meshgrid(xs, ys)
    d = np.hypot(X - pose.x, Y - pose.y)
    mask = polygon_mask(sc.terrain, sc.site.dig_area) & (d >= exc.reach_min) & (d <= exc.reach_max)
    floor = sc.site.floor if sc.site.floor is not None else 0.0
    return sc.terrain.volume_above(floor, mask)


def check_scenario(scenario: Scenario, factor: float = MIN_VOLUME_FACTOR) -> Scenario:
    """Raise ScenarioError unless the site holds ``factor`` × target above the floor, the truck
    can carry the target, and the initial poses keep the excavator–truck (and loader–truck)
    clearance.

    Returns the scenario unchanged so generators can ``return check_scenario(Scenario(...))``.
    """
    sc = scenario
    target = sc.task.target_volume
    held = dig_area_volume(sc)
    if held < factor * target - 1e-9:
        raise ScenarioError(
            f"scenario {sc.id!r}: the dig area holds {held:.3f} m³ above the floor, less than "
            f"{factor:g} × the target {target:g} m³; choose a target of at most {held / factor:.3f} m³"
        )
    if sc.machines.truck.capacity < target:
        raise ScenarioError(
            f"scenario {sc.id!r}: the truck carries {sc.machines.truck.capacity:g} m³, less than the "
            f"target {target:g} m³; raise the generator's truck_capacity"
        )
    t = sc.machines.truck_pose
    for name in ("excavator", "loader"):
        spec, pose = getattr(sc.machines, name, None), getattr(sc.machines, f"{name}_pose", None)
        if spec is None or pose is None:
            continue
        d = math.hypot(t.x - pose.x, t.y - pose.y)
        if d < spec.clearance:
            raise ScenarioError(
                f"scenario {sc.id!r}: {name} and truck start {d:.3f} m apart, closer than the "
                f"clearance {spec.clearance:g} m; move one of them"
            )
    return sc
