"""stl-tamp's local problem as a plan poses it, shared by the tests of the classic and the staged NLP."""

from __future__ import annotations

from typing import Any

from earthbench_planners.stl_tamp import StlTampPlanner
from earthbench_planners.stl_tamp.convert import SimState
from earthbench_planners.stl_tamp.hierarchy import candidate_areas, get_nlp, site_box
from earthbench_planners.stl_tamp.surface import fit_rbf
from earthbench_terrains.rbf import rbf


def richest_local_area(sc: Any = None, solver: str = "cvxpy") -> tuple[Any, StlTampPlanner, Any, SimState, Any, Any]:
    """The local NLP (built once, as in a run), the richest area of ``sc`` (a 14-basis map by
    default) and its fit by ``solver``: ``(scenario, planner, nlp, start state, area, surface)``."""
    sc = sc if sc is not None else rbf(0, 1.0, n_bases=14)
    pl = StlTampPlanner()
    c = pl.config
    nlp, _ = get_nlp(pl.local_shape(sc), sc, site_box(sc))
    st = SimState.start(sc)
    areas = candidate_areas(sc, st.z, pl.area_side(sc), c.dig_depth, c.area_vmax, c.base_offset, c.truck_offset)
    area = max(areas, key=lambda a: a.estimate)
    cx, cy = area.centre
    hw = c.local_fit_half
    surf = fit_rbf(sc.terrain, spacing=c.local_fit_spacing, window=(cx - hw, cx + hw, cy - hw, cy + hw),
                   shape=nlp.shape.terrain_shape, margin=0, solver=solver)
    return sc, pl, nlp, st, area, surf
