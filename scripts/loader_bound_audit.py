"""Issue 49: the wheel loader's time-to-target bound per scenario, and what a yaw-rate term would add.

For every scenario of a wheel-loader suite: ``n (t_c + t_d)`` (the bound before issue 49), the
bound now (``lower_bound_time_to_target``: the meeting of loader, pile and truck, docs/metrics.md
"The wheel loader"), and a *what-if*: the same recursion with the truck's approach also limited by
its yaw rate (its speed toward the pile along a direction ``u`` at most ``v_t`` times the cosine of
the least angle its heading can make with ``±u`` by then). The what-if is **not** a bound under
today's referee, whose ``heading`` rule still lets a truck slip sideways by up to 5 % of its
travel (its chord tolerance per metre of chord); it measures what pricing the turn would be worth.

    python scripts/loader_bound_audit.py [--suite pile]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from earthbench.rules import loader_base_level
from earthbench.results.suite import load_suite
from earthbench.world import Scenario
from earthbench_metrics import least_time, lower_bound_time_to_target


def with_yaw_rate(sc: Scenario, n: int) -> float:
    """The what-if bound (s) for ``n`` loaded dumps."""
    m = sc.machines
    lo, tr, t0, start = m.loader, m.truck, m.truck_pose, m.loader_pose
    assert lo is not None and start is not None
    level = sc.site.floor if sc.site.floor is not None else loader_base_level(sc)
    xs, ys = sc.terrain.cell_centres()
    jj, ii = np.nonzero(np.asarray(sc.terrain.z) > level)
    mat = np.stack([xs[ii], ys[jj]], axis=1)
    th = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    u = np.stack([np.cos(th), np.sin(th)], axis=1)
    beyond = (mat @ u.T).min(axis=0) - u @ np.array([t0.x, t0.y])  # how far all material lies past the truck along u
    off = np.abs((th - t0.yaw + math.pi / 2) % math.pi - math.pi / 2)  # the heading's angle to ±u
    v, w, vl, vp = tr.travel_speed * 1.001, tr.yaw_rate * 1.001, lo.travel_speed * 1.001, lo.penetration_speed * 1.001
    touch = math.hypot(lo.bucket_offset, lo.bucket_width / 2)
    reach = lo.bucket_offset + tr.loading_radius + lo.dump_reach
    dist = float(np.min(np.hypot(mat[:, 0] - t0.x, mat[:, 1] - t0.y)))
    tc, td = lo.min_charge_time, lo.min_dump_time

    def g(s: float) -> float:
        come = v * ((np.sin(off) - np.sin(np.maximum(off - w * s, 0.0))) / w + np.maximum(s - off / w, 0.0))
        return max(max(dist - v * s, float((beyond - come).max())) - touch - reach, 0.0)

    def leg(a: float, b: float) -> float:
        return tc + max(a + b - vp * tc, 0.0) / vl

    first = max(float(np.min(np.hypot(mat[:, 0] - start.x, mat[:, 1] - start.y))) - touch, 0.0)
    s = least_time(tc, lambda x: leg(first, g(x)))
    for k in range(1, n):
        if g(s) == 0.0:
            return s + (n - k) * (tc + td) + td
        after, back = s + td, g(s)
        s = least_time(after + tc, lambda x: after + leg(back, g(x)))  # noqa: B023 (used at once)
    return s + td


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="pile")
    args = ap.parse_args()
    print(f"{'scenario':24s} {'n(tc+td)':>9s} {'bound':>7s} {'yaw what-if':>11s}")
    for sc in load_suite(args.suite).scenarios:
        lo = sc.machines.loader
        assert lo is not None
        fill = sc.soil.fill_factor if sc.soil is not None else 1.0
        n = math.ceil(sc.task.target_volume / (lo.bucket_capacity * fill) - 1e-9)
        print(f"{sc.id:24s} {n * (lo.min_charge_time + lo.min_dump_time):9.2f} {lower_bound_time_to_target(sc):7.2f}"
              f" {with_yaw_rate(sc, n):11.2f}")


if __name__ == "__main__":
    main()
