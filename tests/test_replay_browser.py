"""The replay viewer in a real browser (headless Chromium over the DevTools protocol).

Screenshots of the canvas at the start, middle and end of a run: with only the terrain drawn
they differ exactly at the cells whose height the referee changed by then; with paths and
marks the machines have moved; an invalid run shows red at its action. Skipped, with the
reason, when Chromium or websocket-client is missing.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from chromium import chromium_page, needs_browser
from earthbench.plan import Plan
from earthbench.publishing.publish import publish
from earthbench.running.playback import replay
from earthbench.results.store import Store
from helpers.leaderboard import Behaviour, fill_store, ref, standard_behaviours, suite_of

pytestmark = needs_browser


@pytest.fixture(scope="module")
def viewer(tmp_path_factory):
    root = tmp_path_factory.mktemp("replay")
    db = fill_store(root / "runs.db", suite_of(2), standard_behaviours() + [Behaviour(ref("jumpy"), teleport=4.0)])
    publish(db, root / "lb", figures=False)
    with chromium_page() as dt:
        dt.window(1400, 1000)
        dt.open((root / "lb" / "index.html").as_uri())
        assert dt.js("window.earthbenchReplayReady.then(() => true)") is True
        yield dt, db


def _load(dt, run_id: int) -> None:
    n = dt.js(f"Array.from(document.getElementById('rp-run').options).findIndex(o => o.textContent.startsWith('run {run_id}:'))")
    assert n >= 0
    dt.js(f"earthbenchReplay.load({n}).then(() => true)")


def _canvas(dt, t: float) -> np.ndarray:
    import matplotlib.image as mpimg

    dt.js(f"earthbenchReplay.setTime({t})")
    r = dt.js("(() => { const c = document.getElementById('rp-canvas'); c.scrollIntoView();"
              " const b = c.getBoundingClientRect();"
              " return [b.left + c.clientLeft + window.scrollX, b.top + c.clientTop + window.scrollY, c.width, c.height]; })()")
    png = dt.screenshot(clip={"x": r[0], "y": r[1], "width": r[2], "height": r[3]})
    return (mpimg.imread(io.BytesIO(png))[..., :3] * 255).round().astype(int)


def _scenario_plan(db, run_id: int):
    with Store(db, create=False) as store:
        row = store.query(run_id=run_id)[0]
        return store.scenario(row["scenario_digest"]), Plan.from_json(store.plan_json(run_id))


def _cell_pixels(img: np.ndarray, sc, cells: np.ndarray) -> np.ndarray:
    """The pixel at the centre of each (j, i) cell (the canvas draws the map's extent, north up)."""
    ny, nx = sc.terrain.z.shape
    h, w = img.shape[:2]
    px = ((cells[:, 1] + 0.5) * w / nx).astype(int)
    py = (h - (cells[:, 0] + 0.5) * h / ny).astype(int)
    return img[py.clip(0, h - 1), px.clip(0, w - 1)]


def test_terrain_changes_dig_by_dig_where_the_referee_cut(viewer):
    dt, db = viewer
    runs = dt.js("JSON.parse(document.getElementById('rp-data').textContent).map(d => [d.run, d.verdict, d.label])")
    greedy = next(r[0] for r in runs if "greedy" in r[2] and r[1] == "valid")  # a whole plan: digs before its end
    _load(dt, greedy)
    sc, plan = _scenario_plan(db, greedy)
    _, steps = replay(sc, plan)
    dt.js("document.getElementById('rp-overlays').checked = false")
    end_t = plan.makespan
    first_dig = next(a for a in plan.actions if a.kind == "dig")
    mid_t = first_dig.t_end + 1e-3  # after the first dig, before the last
    shots = [_canvas(dt, t) for t in (0.0, mid_t, end_t)]
    z = [sc.terrain.z, next(s.z for s in steps if plan.actions[s.action] is first_dig), steps[-1].z]
    assert len({s.tobytes() for s in shots}) == 3, "start, middle and end must differ"
    for k in (1, 2):
        changed = np.abs(z[k] - z[0]) > 0.02  # well above one colour step
        same = np.abs(z[k] - z[0]) == 0
        # keep cells whose 3×3 neighbourhood is all changed or all unchanged (pixel rounding at edges)
        pad_c, pad_s = np.pad(changed, 1), np.pad(same, 1, constant_values=True)
        core_c = np.all([pad_c[1 + dj:1 + dj + changed.shape[0], 1 + di:1 + di + changed.shape[1]]
                         for dj in (-1, 0, 1) for di in (-1, 0, 1)], axis=0)
        core_s = np.all([pad_s[1 + dj:1 + dj + same.shape[0], 1 + di:1 + di + same.shape[1]]
                         for dj in (-1, 0, 1) for di in (-1, 0, 1)], axis=0)
        a, b = _cell_pixels(shots[0], sc, np.argwhere(core_c)), _cell_pixels(shots[k], sc, np.argwhere(core_c))
        assert core_c.sum() > 5 and (np.abs(a - b).sum(axis=1) > 0).mean() > 0.9
        a, b = _cell_pixels(shots[0], sc, np.argwhere(core_s)), _cell_pixels(shots[k], sc, np.argwhere(core_s))
        assert (np.abs(a - b).sum(axis=1) > 0).mean() < 0.01
    dt.js("document.getElementById('rp-overlays').checked = true")


def _shot(dt, element: str) -> np.ndarray:
    import matplotlib.image as mpimg

    r = dt.js(f"(() => {{ const c = document.getElementById('{element}'); c.scrollIntoView();"
              " const b = c.getBoundingClientRect();"
              " return [b.left + c.clientLeft + window.scrollX, b.top + c.clientTop + window.scrollY, c.width, c.height]; })()")
    png = dt.screenshot(clip={"x": r[0], "y": r[1], "width": r[2], "height": r[3]})
    return (mpimg.imread(io.BytesIO(png))[..., :3] * 255).round().astype(int)


def test_height_scale_beside_the_map_reads_its_colours(viewer):
    """The scale spans the run's lowest to highest ground, and its bar at a cell's height has that cell's colour."""
    dt, db = viewer
    run = dt.js("earthbenchReplay.state().run")
    sc, _ = _scenario_plan(db, run)
    dt.js("document.getElementById('rp-overlays').checked = false")
    the_map = _canvas(dt, 0.0)
    scale = dt.js("earthbenchReplay.scale()")
    z0 = np.asarray(sc.terrain.z)
    assert scale["lo"] <= z0.min() + 1e-3 and scale["hi"] >= z0.max() - 1e-3
    heights = [t["height"] for t in scale["ticks"]]
    assert heights[0] == pytest.approx(scale["lo"]) and heights[-1] == pytest.approx(scale["hi"]) and heights == sorted(heights)
    bar = _shot(dt, "rp-scale")
    top, bottom, x = scale["ticks"][-1]["y"], scale["ticks"][0]["y"], scale["bar"]["x"] + scale["bar"]["w"] // 2
    assert bar[bottom - 1:bottom + 1, x - 2:x + 2].any()  # drawn
    # the highest, the lowest and a middling cell of the map: their colour on the map is the bar's at their height
    flat = z0.ravel()
    order = np.argsort(flat)
    picks = [order[-1], order[0], order[len(order) // 2]]
    cells = np.array([np.unravel_index(k, z0.shape) for k in picks])
    on_map = _cell_pixels(the_map, sc, cells)
    for (j, i), colour in zip(cells, on_map):
        f = (z0[j, i] - scale["lo"]) / (scale["hi"] - scale["lo"])
        y = int(round(bottom - f * (bottom - top)))
        near = bar[max(y - 2, top):min(y + 3, bottom + 1), x]
        assert np.abs(near - colour).sum(axis=1).min() <= 12, (z0[j, i], colour, near)
    dt.js("document.getElementById('rp-overlays').checked = true")


def test_machines_move_and_violations_are_red(viewer):
    dt, db = viewer
    runs = dt.js("JSON.parse(document.getElementById('rp-data').textContent).map(d => [d.run, d.verdict, d.label])")
    jumpy = next(r for r in runs if "jumpy" in r[2] and r[1] != "valid")
    _load(dt, jumpy[0])
    def red(img):
        return ((img[..., 0] > 190) & (img[..., 1] < 40) & (img[..., 2] < 40)).sum()
    start = _canvas(dt, 0.0)
    mk = dt.js("earthbenchReplay.state().makespan")
    end = _canvas(dt, mk)
    assert red(end) > red(start) + 50  # the bad move's path and the missed dumps, drawn once reached
    log = dt.js("Array.from(document.querySelectorAll('#rp-log li.rp-bad')).map(li => li.textContent)")
    assert any("discontinuous" in line for line in log)
    assert dt.js("document.getElementById('rp-verdict').className") == "rp-bad"


def test_replay_buttons_in_the_runs_table_and_no_errors(viewer):
    dt, _ = viewer
    n = dt.js("document.querySelectorAll('table.runs .rp-open').length")
    assert n == dt.js("JSON.parse(document.getElementById('rp-data').textContent).length")
    dt.js("document.querySelectorAll('table.runs .rp-open')[1].click()")
    dt.drain(0.3)
    errors = [e for e in dt.events if e.get("method") == "Runtime.exceptionThrown"
              or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")]
    assert errors == []
    urls = [e["params"]["request"]["url"] for e in dt.events if e.get("method") == "Network.requestWillBeSent"]
    assert [u for u in urls if not (u.startswith("file:") or u.startswith("data:") or u.startswith("blob:"))] == []
