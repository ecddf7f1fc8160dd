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
from earthbench.results.store import MAX_BLOB_BYTES, BlobTooLargeError, Store, decompress


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
    # VmHWM: this process image's own peak (ru_maxrss would carry over the forking pytest's)
    code = ("import sys\n"
            "from earthbench.cli import main\n"
            f"rc = main(['merge', {str(out)!r}, {str(bomb_store)!r}])\n"
            "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')][0].split()[1]\n"
            "print('peak_mb', int(hwm) / 1024)\n"
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
    database). Six processes released at once, twenty times, beside two busy loops: every one opens the store."""
    ctx = multiprocessing.get_context("fork")
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]  # the load
    try:
        _race(ctx, tmp_path)
    finally:
        for b in burners:
            b.kill()
            b.wait()


def _race(ctx, tmp_path: Path) -> None:
    for r in range(20):
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


# -- control sequences in what is printed --------------------------------------------------------

ESCAPING = str(Path(__file__).parent / "plugins" / "escaping_planners.py")


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "earthbench", *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def _raw_controls(text: str) -> list[str]:
    """The characters of ``text`` a terminal would act on (newline and tab are text)."""
    import unicodedata

    return sorted({c for c in text if (unicodedata.category(c) in ("Cc", "Cf", "Zl", "Zp")) and c not in "\n\t"})


def test_printable_escapes_every_control_and_formatting_character():
    import unicodedata

    from earthbench.errors import printable

    controls = "".join(chr(c) for c in range(0x3000) if unicodedata.category(chr(c)) in ("Cc", "Zl", "Zp") or 0x200B <= c <= 0x200F
                       or 0x202A <= c <= 0x202E or 0x2060 <= c <= 0x2069)
    out = printable("name " + controls + "\n\tend ü ³ – ∞")
    assert _raw_controls(out) == []
    assert out.startswith("name \\x00\\x01") and "\\x1b" in out and "\\u202e" in out and out.endswith("\n\tend ü ³ – ∞")


def test_control_sequences_in_names_errors_and_logs_reach_the_terminal_as_text(tmp_path):
    """The attack: a planner named with a line erase and a fake green "ok", a clipboard write
    (OSC 52) and a right-to-left override is refused by the probe, its refusal printed as
    escapes; planners that print them to their log and raise with them, under a suite whose
    name carries a colour, go through `run`, `runs`, `runs --id`, `list`, `leaderboard` and the
    error of `plan`, and every sequence is printed as escapes."""
    sys.path.insert(0, str(Path(ESCAPING).parent))
    from escaping_planners import HOSTILE_NAME, TRICKS, Escaping, EscapingQuiet

    import json

    from helpers import tiny_suite_toml

    shown = "\\x1b[2K\\x0d\\x1b[32m ok \\x1b[0m\\x1b]52;c;ZXZpbA==\\x07\\u202e\\x9b31m"
    named = tmp_path / "named.py"
    named.write_text("from earthbench import Plan, Planner\n\n\nclass Named(Planner):\n"
                     f"    name = {HOSTILE_NAME!r}\n    tracks = ('backhoe',)\n\n    def plan(self, scenario):\n        return Plan()\n")
    refused = _cli("list", "planners", "--plugin", str(named), cwd=tmp_path)
    assert refused.returncode != 0 and "refused: planner name 't-esc\\x1b[2K" in refused.stderr
    assert _raw_controls(refused.stdout + refused.stderr) == []

    suite = tmp_path / "s.toml"
    suite.write_text("planners = " + json.dumps([Escaping.name, EscapingQuiet.name]) + "\n"
                     + tiny_suite_toml("tiny\\u001b[31mred\\u0007"))
    db = str(tmp_path / "x.db")
    outputs = [_cli("run", str(suite), "--plugin", ESCAPING, "--db", db, cwd=tmp_path),
               _cli("runs", "--db", db, cwd=tmp_path), _cli("runs", "--db", db, "--id", "1", cwd=tmp_path),
               _cli("list", "planners", "--plugin", ESCAPING, cwd=tmp_path),
               _cli("leaderboard", "--db", db, "--out", str(tmp_path / "lb"), "--no-figures", cwd=tmp_path)]
    for p in outputs:
        assert p.returncode == 0, p.stderr
        assert _raw_controls(p.stdout + p.stderr) == [], p.args
    in_process = _cli("plan", "--plugin", ESCAPING, Escaping.name, cwd=tmp_path)  # the planner raises, in its fence
    assert in_process.returncode == 2 and "returned no plan (error)" in in_process.stderr and "\\x1b[32m ok" in in_process.stderr
    assert _raw_controls(in_process.stdout + in_process.stderr) == []
    assert TRICKS not in "".join(p.stdout + p.stderr for p in outputs)
    run, _, one, _, _ = outputs
    assert "tiny\\x1b[31mred\\x07" in run.stderr
    assert "error text " + shown in one.stdout and "log line " + shown in one.stdout and "stderr line " + shown in one.stdout


# -- two runs on a new store, from the command line, under load ----------------------------------


@pytest.mark.slow
def test_two_runs_started_together_on_a_new_store_under_load_both_succeed(tmp_path):
    """The attack as it was seen: two `earthbench run` on a store that does not exist yet, the
    machine busy. Both finish and both suites' runs are stored once."""
    from helpers import tiny_suite_toml

    for name, seeds in (("a", "0-0"), ("b", "1-1")):
        (tmp_path / f"{name}.toml").write_text(tiny_suite_toml(name, seeds=seeds))
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        runs = [subprocess.Popen([sys.executable, "-m", "earthbench", "run", str(tmp_path / f"{name}.toml"), "--planner", "greedy",
                                  "--db", str(tmp_path / "new.db"), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True) for name in ("a", "b")]
        results = [(p.wait(timeout=300), p.communicate()[1]) for p in runs]
    finally:
        for b in burners:
            b.kill()
            b.wait()
    assert [rc for rc, _ in results] == [0, 0], results
    with Store(tmp_path / "new.db", create=False) as st:
        assert sorted(r["suite"] for r in st.runs()) == ["a", "b"]


# -- sealed draws a case could recognise ---------------------------------------------------------

PROBE = """name = "{g}-probe"
track = "{track}"
[[family]]
name = "f"
generator = "{g}"
targets = [{target}]
seeds = "0-15"
{extra}"""
REALISM = '[family.soil]\nmaterial = "loam"\n[family.sensing]\nnoise = 0.01\n'


def _features(sc) -> dict[str, object]:
    """What a case can measure of its observation at a glance: where the map lies and how big
    it is, where each machine stands and faces, the dig area's box, the floor, the keep-outs,
    the open ground's level, and the terrain's own statistics."""
    import numpy as np

    from earthbench.sensing import observe

    v = observe(sc)
    t = v.terrain
    out: dict[str, object] = {"origin": tuple(t.origin), "shape": t.z.shape, "resolution": t.resolution,
                              "outside_level": v.outside_level, "floor": v.site.floor, "keep_outs": v.site.keep_outs,
                              "budget": v.budget, "target": v.task.target_volume, "soil": v.soil}
    for mid in v.machines.ids:
        p = v.machines.pose(mid)
        out[f"{mid} x"], out[f"{mid} y"], out[f"{mid} yaw"] = p.x, p.y, p.yaw
    xs, ys = zip(*v.site.dig_area)
    out.update({"dig x min": min(xs), "dig x max": max(xs), "dig y min": min(ys), "dig y max": max(ys)})
    out.update({"mean height": float(np.mean(t.z)), "highest": float(np.max(t.z)), "height sd": float(np.std(t.z))})
    return out


@pytest.mark.parametrize("generator,track,target,extra", [
    ("rbf", "backhoe", 0.56, ""), ("rbf", "backhoe", 0.56, REALISM), ("bench", "backhoe", 4.0, ""),
    ("dem", "backhoe", 4.0, ""), ("pile", "wheel_loader", 2.0, REALISM)])
def test_no_observation_feature_tells_a_sealed_draw_from_the_public_suite(generator, track, target, extra):
    """The attack: a case looked at its map's origin (moved by up to 50 m on a sealed draw, 0 on
    every public scenario) and knew it was sealed; a turned map's extents and the machines'
    headings told the same. Now a sealed draw changes only the seeds: every feature the public
    seeds hold fixed is the same value sealed, and every feature they vary is drawn from the same
    distribution (16 public seeds against 16 sealed draws, a rank test at 1 %)."""
    from scipy.stats import mannwhitneyu

    from earthbench.seal import SealKey
    from earthbench.results.suite import parse_suite

    public = parse_suite(PROBE.format(g=generator, track=track, target=target, extra=extra))
    sealed = public.sealed(SealKey(public.name, public.digest, bytes(range(32))))  # a fixed key: the test is reproducible
    pub = [_features(sc) for sc in public.scenarios]
    sea = [_features(sc) for sc in sealed.scenarios]
    assert all(not _same_terrain(a, b) for a, b in zip(public.scenarios, sealed.scenarios))  # the worlds are new
    for name in pub[0]:
        p_values, s_values = [f[name] for f in pub], [f[name] for f in sea]
        if all(v == p_values[0] for v in p_values):
            assert all(v == p_values[0] for v in s_values), f"{name}: public always {p_values[0]!r}, sealed {s_values[:3]!r}…"
        else:
            p = mannwhitneyu(p_values, s_values).pvalue
            assert p >= 0.01, f"{name}: sealed values differ from the public ones (p = {p:.2g})"


def _same_terrain(a, b) -> bool:
    import numpy as np

    return bool(np.array_equal(a.terrain.z, b.terrain.z))


# -- free re-scans on the realistic closed loop --------------------------------------------------

RESCAN = """name = "rescan"
track = "backhoe"
[[family]]
name = "f"
generator = "rbf"
targets = [0.56]
seeds = [3]
[family.params]
n_bases = 14
[family.soil]
material = "loam"
[family.sensing]
noise = 0.011
occlusion = false
"""


class _Rescanner:
    """The attack: a closed-loop planner that stands still for 10 ms a hundred times, keeping
    every scan, to average the scans' noise away (it cut the error from 11 mm to under 1 mm)."""

    closed_loop = True

    def __init__(self, moving: bool = False):
        self.scans: list = []
        self.times: list[float] = []
        self.moving = moving

    def step(self, observation):
        from earthbench.plan import Move, Plan

        self.scans.append(observation.scenario.terrain.z.copy())
        self.times.append(observation.t)
        if len(self.scans) > 100:
            return None
        p = observation.scenario.machines.excavator_pose
        t = observation.t
        if not self.moving:
            return Plan((Move("excavator", ((t, p.x, p.y, p.yaw), (t + 0.01, p.x, p.y, p.yaw))),))
        dx = 1.5 if len(self.scans) % 2 else -1.5  # to and fro along its heading, between two stations 1.5 m apart
        return Plan((Move("excavator", ((t, p.x, p.y, p.yaw), (t + 3.0, p.x + dx, p.y, p.yaw))),))


def _rescan(moving: bool):
    import numpy as np

    from earthbench.running.harness.steps import run_closed_loop
    from earthbench.results.suite import parse_suite

    truth = parse_suite(RESCAN).scenarios[0]
    planner = _Rescanner(moving)
    plan = run_closed_loop(planner, truth, max_steps=200)
    scans = np.array(planner.scans)
    error = lambda z: float(np.sqrt(np.mean((z - truth.terrain.z) ** 2)))  # noqa: E731
    return truth, plan, planner, error(scans[0]), error(scans.mean(axis=0))


def test_a_hundred_scans_from_one_place_cost_their_sweeps_and_average_nothing_away():
    """Now every scan after a step costs its sweep (SCAN_S of plan time before the next actions),
    and a scan from the same station repeats that station's error: the average of 101 scans is
    exactly as wrong as one, and the hundred steps cost their sweeps in plan time."""
    from earthbench.sensing import SCAN_S

    truth, plan, planner, one, averaged = _rescan(moving=False)
    assert 0.008 < one < 0.014  # the scan's own error (σ 11 mm)
    assert averaged == pytest.approx(one, rel=1e-12)
    assert len(planner.scans) == 101
    assert all(b - a >= SCAN_S + 0.01 - 1e-9 for a, b in zip(planner.times, planner.times[1:]))
    assert max(a.t_end for a in plan.actions) == pytest.approx(100 * 0.01 + 99 * SCAN_S)  # 100 steps, 99 sweeps between them


def test_scans_from_two_stations_are_two_scans_and_each_costs_the_drive_and_the_sweep():
    """Going to and fro between two stations gets two error fields, not a hundred: averaging
    them helps by √2 at most, bought with a hundred drives and sweeps."""
    from earthbench.sensing import SCAN_S

    _, plan, planner, one, averaged = _rescan(moving=True)
    assert averaged > one / 2
    assert max(a.t_end for a in plan.actions) == pytest.approx(100 * 3.0 + 99 * SCAN_S)


def test_a_step_that_starts_before_the_scan_ends_is_refused():
    """A planner that ignores the sweep (its next actions start as the last ones end) is told so."""
    from earthbench.errors import PlanFormatError
    from earthbench.running.harness.steps import run_closed_loop
    from earthbench.plan import Move, Plan
    from earthbench.results.suite import parse_suite

    class Impatient(_Rescanner):
        def step(self, observation):
            p = observation.scenario.machines.excavator_pose
            t = 0.0 if observation.step == 0 else observation.t - 1.0
            return Plan((Move("excavator", ((t, p.x, p.y, p.yaw), (t + 0.01, p.x, p.y, p.yaw))),))

    with pytest.raises(PlanFormatError, match="before the executed actions end and the 1 s scan after them"):
        run_closed_loop(Impatient(), parse_suite(RESCAN).scenarios[0])


# -- keys that survive ---------------------------------------------------------------------------

LEADERBOARD = Path(__file__).resolve().parents[1] / "leaderboard"


def test_every_committed_key_is_listed_with_its_commitment_and_reads():
    """A key committed beside a board is worth something only if it reads and names the
    commitment that was published before its draw ran (leaderboard/commitments.txt)."""
    from earthbench.seal import LEGACY_SCHEMA, SealKey

    published = (LEADERBOARD / "commitments.txt").read_text()
    keys = sorted(LEADERBOARD.glob("keys-*/*.key"))
    assert keys
    for f in keys:
        key = SealKey.read(f)
        assert f"commitment:   {key.commitment}" in published, f
        assert key.schema == LEGACY_SCHEMA  # the 0.2.0 draws: made with the site transform, and still drawn so


def test_a_revealed_legacy_key_still_regenerates_its_draw_and_commitment():
    """The 0.2.0 draws moved their sites; sealed draws no longer do, yet a revealed key of
    theirs still opens: its schema says how its draw was made (earthbench.seal.LEGACY_SCHEMA)."""
    from earthbench.seal import SealKey
    from earthbench.results.suite import load_suite, open_sealed

    key = SealKey.read(LEADERBOARD / "keys-0.2.0" / "standard-realistic-1.key")
    sealed = open_sealed(load_suite(key.suite), key)  # raises unless the regenerated draw gives the commitment
    assert sealed.name == "standard-realistic~sealed-df1b17309007" and len(sealed.scenarios) == 48
    assert any(sc.terrain.origin != (0.0, 0.0) for sc in sealed.scenarios)  # drawn as it was: sites moved


@pytest.mark.slow
def test_a_board_published_with_its_key_can_be_verified_from_the_published_key(tmp_path):
    """The process: seal, run the draw, publish the board with `--key` (checked against the
    store, written to keys/), then anyone re-judges the store with the published key. A board
    published without it says so."""
    from helpers import tiny_suite_toml

    suite = tmp_path / "tiny.toml"
    suite.write_text(tiny_suite_toml("tiny", seeds="0-1"))
    db, key = str(tmp_path / "board.db"), str(tmp_path / "secret.key")
    assert _cli("seal", str(suite), "--key", key, cwd=tmp_path).returncode == 0
    for extra in ([], ["--sealed", key]):
        assert _cli("run", str(suite), "--planner", "greedy", "--db", db, "--quiet", *extra, cwd=tmp_path).returncode == 0
    bare = _cli("leaderboard", "--db", db, "--out", str(tmp_path / "bare"), "--no-figures", cwd=tmp_path)
    assert bare.returncode == 0 and "is published without its key" in bare.stderr
    out = tmp_path / "lb"
    board = _cli("leaderboard", "--db", db, "--out", str(out), "--no-figures", "--key", key, cwd=tmp_path)
    assert board.returncode == 0, board.stderr
    assert "without its key" not in board.stderr
    published = list((out / "keys").glob("tiny~sealed-*.key"))
    assert len(published) == 1 and published[0].stat().st_mode & 0o044  # readable by all: it is published
    check = _cli("verify", db, "--key", str(published[0]), cwd=tmp_path)
    assert check.returncode == 0, check.stdout + check.stderr
    assert "regenerated" in check.stdout
    other = tmp_path / "other.key"
    assert _cli("seal", str(suite), "--key", str(other), cwd=tmp_path).returncode == 0
    refused = _cli("leaderboard", "--db", db, "--out", str(tmp_path / "x"), "--no-figures", "--key", str(other), cwd=tmp_path)
    assert refused.returncode == 2 and "holds no suite" in refused.stderr and not (tmp_path / "x").exists()


def test_a_sealed_draw_shares_its_worlds_across_targets_as_the_public_suite_does():
    """A public seed serves every target of its family with one world; a sealed draw that gave
    each target its own would tell itself apart to a case that remembers what it saw."""
    from earthbench.seal import SealKey
    from earthbench.results.suite import parse_suite

    public = parse_suite(PROBE.format(g="rbf", track="backhoe", target="0.56, 1.12", extra="").replace('"0-15"', '"0-2"'))
    sealed = public.sealed(SealKey(public.name, public.digest, bytes(range(32))))

    def shared(scenarios):
        return [[_same_terrain(a, b) for b in scenarios] for a in scenarios]

    assert shared(sealed.scenarios) == shared(public.scenarios)
    assert sum(map(sum, shared(public.scenarios))) == 12  # each of 6 with itself and its other target


def test_sealing_a_generator_that_ignores_its_seed_says_it_hides_nothing(tmp_path, capsys):
    """Nothing but the seeds may change, so a site whose generator ignores its seed (as `file`
    does) is its public self when sealed: `earthbench seal` says so rather than promise a draw."""
    from earthbench.cli import main
    from earthbench.registry import TERRAINS
    from earthbench_terrains.rbf import rbf

    def fixed(seed, target_volume, **params):
        return rbf(0, target_volume, **params)

    TERRAINS.register("t-fixed", fixed)
    try:
        (tmp_path / "s.toml").write_text('name = "fixed"\n[[family]]\nname = "f"\ngenerator = "t-fixed"\ntargets = [0.56]\nseeds = "0-2"\n')
        assert main(["seal", str(tmp_path / "s.toml"), "--key", str(tmp_path / "k.key")]) == 0
        assert "3 of 3 sealed scenarios have their public terrain" in capsys.readouterr().err
    finally:
        TERRAINS.unregister("t-fixed")
