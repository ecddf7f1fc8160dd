"""Hostile data, not hostile code (issue 47): what a submitted store, a planner's name or log, a
second `earthbench run`, a sealed draw's observation and a closed loop's scans can do to the
harness and its figures. Each test is an attack as it was tried, and what ends it.
"""

from __future__ import annotations

import multiprocessing
import sqlite3
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from helpers.leaderboard import Behaviour, fill_store, ref, suite_of

from earthbench.errors import StoreError
from earthbench.store import MAX_BLOB_BYTES, BlobTooLargeError, Store, decompress


# -- decompression bombs -------------------------------------------------------------------------


def _bomb(inflated: int) -> bytes:
    """zlib of ``inflated`` zero bytes, built a megabyte at a time (never held inflated)."""
    z, chunk = zlib.compressobj(9), bytes(2**20)
    return b"".join(z.compress(chunk) for _ in range(inflated // 2**20)) + z.flush()


def test_a_blob_that_inflates_past_the_cap_is_refused_after_reading_the_cap():
    assert decompress(zlib.compress(b'{"a": 1}')) == '{"a": 1}'
    with pytest.raises(BlobTooLargeError, match="decompression bomb"):
        decompress(_bomb(MAX_BLOB_BYTES + 2**20))


@pytest.fixture(scope="module")
def bomb_store(tmp_path_factory):
    """A store of one real run whose plan blob (about 1 MB) inflates to 1 GB."""
    db = tmp_path_factory.mktemp("bomb") / "bomb.db"
    fill_store(db, suite_of(1, targets=(0.56,)), [Behaviour(ref("greedy-like"))])
    con = sqlite3.connect(db)
    with con:
        con.execute("UPDATE runs SET plan = ?", (_bomb(2**30),))
    con.execute("VACUUM")
    con.close()
    return db


def test_merge_refuses_a_plan_bomb_quickly_with_bounded_memory(bomb_store, tmp_path):
    """The attack: a 1 MB submitted store whose plan inflates to 1 GB drove `merge` to 2.1 GB
    before it refused. Now it inflates at most the cap: the merge refuses, writes nothing, and
    the process's peak memory stays far below the bomb (measured in a process of its own)."""
    assert bomb_store.stat().st_size < 2 * 2**20
    out = tmp_path / "out.db"
    code = ("import resource, sys\n"
            "from earthbench.cli import main\n"
            f"rc = main(['merge', {str(out)!r}, {str(bomb_store)!r}])\n"
            "print('peak_mb', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n"
            "sys.exit(rc)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 2, p.stderr
    assert "merge refused" in p.stderr and "cannot be decompressed" in p.stderr and "decompression bomb" in p.stderr
    assert not out.exists()
    peak = float(p.stdout.split()[-1])
    assert peak < 2 * MAX_BLOB_BYTES / 2**20 + 400, f"peak RSS {peak:.0f} MB while refusing a 1 GB bomb"


# -- two runs on a new store ---------------------------------------------------------------------


def _open_new(path: str, barrier, out) -> None:
    barrier.wait()
    try:
        with Store(path) as st:
            st.check_writable()
        out.put("")
    except StoreError as exc:
        out.put(str(exc))


def test_processes_racing_to_create_a_store_all_open_it(tmp_path):
    """The attack (seen under load): two commands started together on a store that did not exist;
    one stopped with "locked by another process" (or took the half-made file for a foreign
    database). Six processes released at once, twelve times: every one opens the store."""
    ctx = multiprocessing.get_context("fork")
    for r in range(12):
        path = str(tmp_path / f"new{r}.db")
        barrier, out = ctx.Barrier(6), ctx.Queue()
        procs = [ctx.Process(target=_open_new, args=(path, barrier, out)) for _ in range(6)]
        for p in procs:
            p.start()
        errors = [out.get(timeout=60) for _ in procs]
        for p in procs:
            p.join()
        assert errors == [""] * 6, (r, [e for e in errors if e][0])
        with Store(path, create=False) as st:
            assert st.runs() == []
        assert sorted(x.name for x in tmp_path.iterdir() if x.name.startswith(f".new{r}")) == []
