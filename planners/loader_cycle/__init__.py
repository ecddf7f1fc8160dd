"""Shared machinery of the wheel-loader planners: zero contour, charge model, two-arc routes.

Both loader planners (``singh-cannon-loader`` and ``greedy-loader``) differ only in how they
rank dig candidates; the rest lives in this package, one module per part (``scan``,
``soil_model``, ``contours``, ``charge``, ``routes``, ``cycle``, ``closed_loop``), every public
name importable from the package as before (issue 52):

- :func:`read_scan` — the planner's ground from what it is given: on a scan (the realistic
  track) the cells' noise is estimated from the scan itself (second differences, a robust
  spread), the scan is smoothed in proportion to it, the floor's offset (a scanner's bias) is
  measured on the open ground and taken off, and heights within a few smoothed σ of the floor
  are the floor; the contour level and a height margin for the step rule follow from the same
  σ. Exact terrain comes back as it is (σ ≈ 0).
- :func:`zero_contour` — the pile's contour at ground level (``floor + level``) as
  polylines resampled every ``spacing`` metres (contourpy on the cell-centred grid).
- :func:`entry_for` — from the centre ``M`` of the bucket's cutting edge on the contour and a
  heading ``h`` into the pile, the entry pose of a charge: the cutting edge starts just before
  the first material in the bucket's corridor and the loader's pose (front axle) is
  ``bucket_offset`` behind it.
- :func:`simulate_charge` — the public cut model (:func:`earthbench.cut.cut_along`) on a
  copy of the grid. The penetration is chosen so that the bucket takes whole cells up to the
  capacity and no more, so the loader never drives onto material its bucket cannot take. With
  the soil's class (:class:`SoilModel`) the cut stops at the harder layer as the class's
  shallowest layer would stop it (:meth:`SoilModel.levels`), the faces it leaves
  slump to the nominal angle of repose (:func:`earthbench.soil.slump`), and the bucket is
  expected to deliver the nominal fill factor of its capacity.
- :func:`search_routes` — car-like routes at or above the minimum turning radius: an optional
  straight reverse, **two arcs** (a reverse arc, a cusp, a forward arc) and a final straight
  along a target ray (into the entry pose, or up to the truck). Every combination of a grid of
  reverse lengths/curvatures and target rays is solved in closed form at once (numpy), sorted
  by duration, and the fastest few are checked for the traversable step, the truck clearance
  and the map bounds with the referee's own functions.
- :func:`search_dubins` — the return leg may also back out (straight and one arc) and then
  follow a forward Dubins path (arc, straight, arc) into the entry; the faster of the two
  feasible returns is used. The leg to the truck is always two arcs (the paper's constraint).
- :class:`CycleBuilder` — turns a ranked list of candidates into charge, reverse out, two arcs
  to the truck, dump, return; the first candidate whose charge, route to the truck and approach
  are all feasible wins; :meth:`CycleBuilder.load_until_target` is the cycle loop both planners
  run, each with its own choice of dig. On a scan (open loop) no cycle follows one after which
  the truck may be full (``planners/truck_load.py``: each charge's most by the class's fullest
  bucket, the truck's room at its largest swell; a charge that is not the last leaves room for
  the next), so no charge starts with what a full truck left in the bucket.

All moves are sampled finely enough (≤ 0.25 m and ≤ 0.08 rad per step) that the referee's
chord, speed, yaw-rate and curvature checks see exact arcs, at ``MARGIN`` of every limit.
"""

from __future__ import annotations

from .charge import ChargeResult, charge_model, entry_for, simulate_charge
from .closed_loop import CyclePlanner, LoopMemory
from .contours import box_volumes, pile_side, zero_contour
from .cycle import Cycle, CycleBuilder, LoaderPlanConfig
from .routes import MARGIN, RADIUS_MARGIN, Route, RouteOptions, Sample, dump_rays, search_dubins, search_routes
from .scan import EXACT_NOISE, GroundModel, read_scan, scan_noise
from .soil_model import SoilModel

__all__ = [
    "EXACT_NOISE", "MARGIN", "RADIUS_MARGIN", "ChargeResult", "Cycle", "CycleBuilder", "CyclePlanner", "GroundModel",
    "LoaderPlanConfig", "LoopMemory", "Route", "RouteOptions", "Sample", "SoilModel", "box_volumes", "charge_model",
    "dump_rays", "entry_for", "pile_side", "read_scan", "scan_noise", "search_dubins", "search_routes", "simulate_charge",
    "zero_contour",
]
