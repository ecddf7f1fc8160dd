"""The disk cache of built NLPs (``earthbench_planners.stl_tamp.nlp_cache``): a hit gives the very
NLP a build gives, and a damaged, partial or unwritable cache is a miss, never a failure."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import subprocess
import sys

import numpy as np
import pytest

from earthbench_planners.stl_tamp import nlp_cache


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    d = tmp_path / "nlp"
    monkeypatch.setenv(nlp_cache.ENV, str(d))
    return d


def _writer(text: str):
    def write(path: str) -> None:
        with open(path, "w") as f:
            f.write(text)
    return write


def _read(name: str) -> str | None:
    path = nlp_cache.load(name)
    return None if path is None else path.read_text()[: -len("\nearthbench-nlp/1 sha256 ") - 64]


def test_round_trip_and_off(cache_dir, monkeypatch):
    assert nlp_cache.load("k") is None
    assert nlp_cache.save("k", _writer("payload ∑"))
    assert _read("k") == "payload ∑"
    assert nlp_cache.load("k").stat().st_mode & 0o777 == 0o644  # a sandboxed case (another user) reads it
    monkeypatch.setenv(nlp_cache.ENV, "off")
    assert nlp_cache.directory() is None
    assert nlp_cache.load("k") is None and not nlp_cache.save("k", _writer("x"))


def test_default_directory_is_the_users_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(nlp_cache.ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert nlp_cache.directory() == tmp_path / "earthbench" / "nlp"


@pytest.mark.parametrize("damage", ["truncate", "flip", "append", "garbage", "empty"])
def test_a_damaged_file_is_a_miss(cache_dir, damage):
    nlp_cache.save("k", _writer("some payload " * 100))
    path = cache_dir / "k.nlp"
    blob = path.read_bytes()
    if damage == "truncate":
        blob = blob[: len(blob) // 2]
    elif damage == "flip":
        blob = blob[:5] + bytes([blob[5] ^ 0xFF]) + blob[6:]
    elif damage == "append":
        blob = blob + b"x"
    elif damage == "garbage":
        blob = os.urandom(len(blob))
    else:
        blob = b""
    path.write_bytes(blob)
    assert nlp_cache.load("k") is None
    assert nlp_cache.save("k", _writer("rebuilt")) and _read("k") == "rebuilt"


def test_an_unwritable_directory_or_a_failed_write_is_no_error(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv(nlp_cache.ENV, str(blocker / "nlp"))
    assert not nlp_cache.save("k", _writer("x"))
    assert nlp_cache.load("k") is None
    assert blocker.read_text() == "not a directory"
    monkeypatch.setenv(nlp_cache.ENV, str(tmp_path / "nlp"))

    def fails(path: str) -> None:
        raise RuntimeError("disk full")

    assert not nlp_cache.save("k", fails)
    assert not list((tmp_path / "nlp").iterdir())  # no temporary file left behind


def test_keys_change_with_the_content():
    assert nlp_cache.key(1, (2.0, 3.0)) == nlp_cache.key(1, (2.0, 3.0))
    assert nlp_cache.key(1, (2.0, 3.0)) != nlp_cache.key(1, (2.0, 3.0000001))


def _keep_writing(directory: str, payload: str, rounds: int) -> None:
    os.environ[nlp_cache.ENV] = directory
    for _ in range(rounds):
        assert nlp_cache.save("k", _writer(payload))


def test_two_writers_and_a_reader_never_see_a_partial_file(cache_dir):
    a, b = "a" * 3_000_000, "b" * 1_000
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_keep_writing, args=(str(cache_dir), p, 30)) for p in (a, b)]
    for p in procs:
        p.start()
    while any(p.is_alive() for p in procs):
        assert _read("k") in (None, a, b)
    for p in procs:
        p.join()
        assert p.exitcode == 0
    assert _read("k") in (a, b)
    assert not [f for f in cache_dir.iterdir() if f.suffix == ".tmp"]


@pytest.mark.slow
def test_a_plan_is_the_same_from_a_built_and_a_loaded_nlp(cache_dir):
    """Two fresh processes, as two cases of a run: the first builds the NLPs and stores them, the
    second loads them; the plans (and the IPOPT iterations behind them) are the same."""
    cmd = [sys.executable, "-c", "from earthbench.cli import main; raise SystemExit(main())",
           "plan", "stl-tamp", "--seed", "1", "--target", "1.5"]
    env = dict(os.environ, EARTHBENCH_PREPARED=str(cache_dir / "no-preparation"))  # not this machine's compiled NLPs
    plans = []
    for _ in range(2):
        out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stdout
        plans.append(json.loads(out))
    assert len(list(cache_dir.glob("*.nlp"))) >= 2  # the global and the local NLP
    info = [p.pop("info", None) for p in plans]
    assert plans[0] == plans[1]
    its = [[r["iterations"] for r in i["local"]] for i in info]
    assert its[0] == its[1]
    assert [i["nlp_cache"] for i in info] == [{"miss": 2}, {"hit": 2}]


def test_a_loaded_nlp_evaluates_as_the_built_one(cache_dir):
    from earthbench_planners.stl_tamp.model import PhaseNLP
    from earthbench_planners.stl_tamp.problem import Shape
    from earthbench.world import ExcavatorSpec, TruckSpec

    shape = Shape(phases=2, steps=4, contact_step=2, unit_width=0.7, unit_length=1.0, unit_depth=0.4, vmax=0.28,
                  work_time=5.0, terrain_shape=(4, 5), terrain_spacing=0.6, terrain_sigma=0.6)
    built = PhaseNLP(shape, ExcavatorSpec(), TruckSpec(), (0.0, 6.0, 0.0, 3.0))
    loaded = PhaseNLP(shape, ExcavatorSpec(), TruckSpec(), (0.0, 6.0, 0.0, 3.0))
    assert (built.cache, loaded.cache) == ("miss", "hit")
    rng = np.random.default_rng(0)
    w, p = rng.normal(size=built.nw), rng.normal(size=sum(n for _, n in built.p_parts))
    lam = rng.normal(size=built.ng)
    for name in ("hess_lag", "jac_g", "grad_f"):
        f, g = built._derivs[name], loaded._derivs[name]
        args = [w, p, 1.0, lam] if name == "hess_lag" else [w, p]
        for a, b in zip(f.call(args), g.call(args)):
            assert np.array_equal(np.array(a), np.array(b))
    assert np.array_equal(built.lbg, loaded.lbg) and np.array_equal(built.ubg, loaded.ubg)
    # another site: the same graph, other bounds on the dig corners
    other = PhaseNLP(shape, ExcavatorSpec(), TruckSpec(), (1.0, 7.0, -1.0, 3.5))
    assert other.cache == "hit"
    moved = np.flatnonzero(other.lbg != built.lbg)
    assert len(moved) == 2 * 4 * shape.phases  # x and y of four corners per dig phase
    assert sorted(set(other.lbg[moved])) == pytest.approx([-1.0 + 1e-3, 1.0 + 1e-3])
    assert sorted(set(other.ubg[moved])) == pytest.approx([3.5 - 1e-3, 7.0 - 1e-3])
    assert PhaseNLP(dataclasses.replace(shape, vmax=0.3), ExcavatorSpec(), TruckSpec(), (0.0, 6.0, 0.0, 3.0)).cache == "miss"
