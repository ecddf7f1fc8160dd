"""Suites: named sets of scenarios, written as data (TOML) and identified by a digest.

A suite file names its track, budget, success threshold and scenario families; each family
calls one terrain generator from the ``earthbench.terrains`` registry as
``gen(seed, target_volume, **params)`` for every (target, seed). The loader then stamps each
scenario with the suite's id scheme ``SUITE/FAMILY/sSEED/vTARGET`` and the suite's budget, so
the same generator call in two suites gives two labels but, with equal budgets, one digest.

Where suites come from (:func:`known_suites`): the ``earthbench.suites`` entry-point group.
Each entry point names a *package*; every ``*.toml`` file directly in it is a suite named by
the file's stem. The built-in suites register this way (``earthbench_terrains.suites``), exactly as a
third-party package would, so the core never imports ``terrains`` by name. A user may also
pass the path of any suite file.

Format (every key is checked; a typo is a :class:`SuiteError` that suggests the close names)::

    name = "smoke"
    description = "A few small cases for CI."
    track = "backhoe"
    success_threshold = 0.9          # optional
    planners = ["greedy"]            # optional; default: every planner supporting the track
    prepare = false                  # optional: run no planner's preparation (docs/DESIGN.md §6)
    class = "20t"                    # optional machine class of every family (docs/machine-classes.md)
    classes = ["compact", "20t"]     # or: sweep each family over classes (renamed FAMILY@CLASS)
    [budget]                         # earthbench.world.Budget
    wall_s = 60
    cores = 2
    memory_mb = 4096
    step_s = 60                      # optional: one closed-loop step's limit (s; default 300)
    max_steps = 1000                 # optional: the closed-loop step cap
    prepare_s = 1800                 # optional: a planner's preparation (s; docs/DESIGN.md §6)
    prepare_memory_mb = 4096         # optional: its memory
    prepare_disk_mb = 2048           # optional: its folder's size on disk (MB)
    [[family]]
    name = "rbf14"
    generator = "rbf"
    targets = [0.56, 1.12]           # m³
    seeds = [0, 1]                   # or "0-9"
    class = "20t"                    # optional: this family's machine class (targets: its bank m³)
    [family.params]
    n_bases = 14
    [family.soil]                    # optional (realistic track): a material, drawn per seed
    material = "loam"                # earthbench.soil.MATERIALS; other Soil fields fix a value
    [family.sensing]                 # optional: earthbench.world.Sensing (seed: the scenario's)
    noise = 0.01
    [config.NAME]                    # optional Planner(**overrides) per planner name
    steepness = 20.0

A suite may also take the families of other suites: ``include = ["paper-extensive", "bench"]``
(registered names, or paths relative to the including file). Each included family keeps its
generator, parameters, targets and seeds and is renamed ``SUITE.FAMILY``, so its ids read
``standard/paper-extensive.rbf30/s0/v4``; the including suite's own track (which every included
suite must share), budget, threshold and planner config apply. With equal budgets the
scenarios keep their digests, so runs stored for the included suite count for the union.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import math
import re
import secrets
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from functools import cache, cached_property
from importlib import resources
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from ..errors import EarthbenchError, SuiteError, UnknownNameError
from .suite_checks import check_params, refuse_unknown
from .scoring import DEFAULT_SUCCESS_THRESHOLD
from ..seal import KEY_BYTES, LEGACY_SCHEMA, TRANSFORMS, SealError, SealKey, SiteTransform, commitment, sealed_name
from ..classes import DEFAULT_CLASS, fit, machine_class
from ..soil import draw
from ..world import TRACKS, Budget, Scenario, Sensing

SUITE_GROUP = "earthbench.suites"
DEFAULT_THRESHOLD = DEFAULT_SUCCESS_THRESHOLD  # the scoring rule's default

#: The most cells a generated heightmap may have (e.g. 2,000 × 2,000); a family asking for more is refused
#: when the suite is loaded, before anything is generated.
MAX_CELLS = 4_000_000
_TOP_KEYS = ("name", "description", "track", "success_threshold", "planners", "budget", "family", "config", "include",
             "prepare", "class", "classes")
_FAMILY_KEYS = ("name", "generator", "targets", "seeds", "params", "soil", "sensing", "class")
_BUDGET_KEYS = tuple(f.name for f in dataclasses.fields(Budget))


def suite_digest(members: Iterable[tuple[str, str]], threshold: float) -> str:
    """A suite version's identity from its (scenario id, scenario digest) pairs and threshold.

    A function of its own so a store can recompute the digest of a suite it only lists; the
    threshold is read as a float, so ``1`` and ``1.0`` (as SQLite gives it back) are one suite.
    """
    h = hashlib.sha256()
    for sid, d in sorted(members):
        h.update(f"{sid}\t{d}\n".encode())
    h.update(f"threshold\t{float(threshold)!r}\n".encode())
    return h.hexdigest()


@dataclass(frozen=True)
class Family:
    """One generator with fixed parameters, swept over targets × seeds."""

    name: str
    generator: str
    targets: tuple[float, ...]
    seeds: tuple[int, ...]
    params: dict[str, Any] = field(default_factory=dict, hash=False)
    soil: dict[str, Any] | None = field(default=None, hash=False)
    sensing: dict[str, Any] | None = field(default=None, hash=False)
    #: The machine class (:mod:`earthbench.classes`): its scenarios are the generator's, fitted
    #: to the class (:func:`earthbench.classes.fit`); the targets are the class's bank m³.
    machine_class: str = DEFAULT_CLASS

    def realism(self, seed: int, scan_seed: int | None = None) -> dict[str, Any]:
        """The scenario sections of the realistic track for ``seed``: the soil drawn from its
        material with that seed (:func:`earthbench.soil.draw`), the sensing seeded with it
        (or with ``scan_seed``: a sealed draw seeds the two apart)."""
        out: dict[str, Any] = {}
        if self.soil is not None:
            out["soil"] = draw(self.soil, seed, f"family {self.name!r} soil", self.machine_class)
        if self.sensing is not None:
            out["sensing"] = Sensing(**{"seed": seed if scan_seed is None else scan_seed, **self.sensing})
        return out


@dataclass(frozen=True, eq=False)
class Suite:
    """A loaded suite file. ``scenarios`` are generated once, on first use."""

    name: str
    track: str
    budget: Budget
    families: tuple[Family, ...]
    description: str = ""
    success_threshold: float = DEFAULT_THRESHOLD
    planners: tuple[str, ...] | None = None
    config: dict[str, dict[str, Any]] = field(default_factory=dict)
    path: str = ""
    #: The key of a sealed draw of this suite (:mod:`earthbench.seal`); None for the public suite.
    sealing: SealKey | None = field(default=None, repr=False)
    #: Whether the planners' preparations run before this suite's cases (docs/DESIGN.md §6);
    #: ``prepare = false`` in the file: its cases run without them (a quick first look).
    prepare: bool = True

    def sealed(self, key: SealKey, *, drawn: Iterable[Scenario] = ()) -> Suite:
        """This suite drawn with ``key`` (:mod:`earthbench.seal`), named by the key's commitment.

        ``drawn``: the same key's scenarios already generated (under any name), relabelled
        rather than generated again.
        """
        out = dataclasses.replace(self, name=sealed_name(self.name, key.commitment), sealing=key,
                                  description=f"{self.name} drawn with a sealed key (commitment {key.commitment[:12]}…)")
        drawn = tuple(drawn)
        if drawn:
            out.__dict__["scenarios"] = tuple(
                sc.replace(id=out.name + sc.id[sc.id.index("/"):], meta={**sc.meta, "suite": out.name}) for sc in drawn
            )
        return out

    @cached_property
    def scenarios(self) -> tuple[Scenario, ...]:
        """Every scenario of the suite, in file order (family, then target, then seed).

        A sealed suite (``sealing``) calls the same generators with the seeds of terrain, soil
        and scan drawn from its key (:mod:`earthbench.seal`); its scenarios keep the public seed
        in ``meta["seed"]`` so ``--seeds`` selects the same draws.
        """
        from ..registry import TERRAINS

        out: list[Scenario] = []
        seen: set[str] = set()
        for fam in self.families:
            gen = TERRAINS.get(fam.generator)
            for target in fam.targets:
                for seed in fam.seeds:
                    sid = f"{self.name}/{fam.name}/s{seed}/v{target:g}"
                    if sid in seen:
                        raise SuiteError(f"{self._where}: scenario id {sid!r} occurs twice; give the families distinct names")
                    seen.add(sid)
                    try:
                        sc = self._generate(gen, fam, seed, target)
                    except EarthbenchError as exc:
                        raise SuiteError(f"{self._where}: family {fam.name!r}, seed {seed}, target {target:g}: {exc}") from exc
                    except MemoryError:
                        raise SuiteError(f"{self._where}: family {fam.name!r}, seed {seed}, target {target:g}: generator "
                                         f"{fam.generator!r} ran out of memory; are its parameters too large?") from None
                    if not isinstance(sc, Scenario):
                        raise SuiteError(f"{self._where}: generator {fam.generator!r} returned {type(sc).__name__}, not a Scenario")
                    if sc.track != self.track:
                        raise SuiteError(
                            f"{self._where}: family {fam.name!r} makes {sc.track!r} scenarios but the suite's track is {self.track!r}"
                        )
                    meta = {**sc.meta, "suite": self.name, "family": fam.name, "seed": seed, "target": target}
                    if self.sealing is None:
                        out.append(sc.replace(id=sid, budget=self.budget, meta=meta, **fam.realism(seed)))
                    else:
                        out.append(sc.replace(id=sid, budget=self.budget, meta={**meta, "sealed": True}))
        return tuple(out)

    def _generate(self, gen: Any, fam: Family, seed: int, target: float) -> Scenario:
        """One scenario from its generator: public (the seed as given) or sealed (every seed
        drawn from the key and the public seed's id, and nothing else changed: a sealed draw is a
        sample of the same distribution as the public suite, its targets sharing a world per seed
        as the public ones do, so no feature of it tells it apart)."""
        key = self.sealing
        if key is None:
            return _fitted(gen(seed, _generator_target(fam, target), **fam.params), fam, target)
        # as a public seed serves every target of its family, so does its sealed draw's (a /1 key drew per target)
        public_id = f"{key.suite}/{fam.name}/s{seed}" + (f"/v{target:g}" if key.schema == LEGACY_SCHEMA else "")
        sc = _fitted(gen(key.derive(public_id, "terrain"), _generator_target(fam, target), **fam.params), fam, target)
        if not isinstance(sc, Scenario):
            return sc  # refused by the caller, as for a public suite
        sc = sc.replace(**fam.realism(key.derive(public_id, "soil"), key.derive(public_id, "scan")))
        if key.schema == LEGACY_SCHEMA:  # a 0.2.0/0.3.0 key: its draw also moved the site (kept so the key still opens)
            allowed = tuple(getattr(gen, "seal_transforms", TRANSFORMS))
            sc = SiteTransform.draw(key.derive(public_id, "transform"), allowed, sc.terrain.resolution).apply(sc)
        return sc

    @cached_property
    def digest(self) -> str:
        """sha256 over the sorted (id, scenario digest) pairs and the success threshold."""
        return suite_digest(((s.id, s.digest) for s in self.scenarios), self.success_threshold)

    def select(self, seeds: Iterable[int] | None = None) -> tuple[Scenario, ...]:
        """The scenarios whose seed is in ``seeds`` (all when None)."""
        if seeds is None:
            return self.scenarios
        keep = set(seeds)
        return tuple(s for s in self.scenarios if s.meta.get("seed") in keep)

    @property
    def _where(self) -> str:
        return f"suite {self.name!r}" + (f" ({self.path})" if self.path else "")


def _generator_target(fam: Family, target: float) -> float:
    """The target to generate a family's site with: the class's target shrunk by its scale³, so
    that the generator's site, grown by the scale, holds what it promises for the target."""
    if fam.machine_class == DEFAULT_CLASS:
        return target
    return round(target / machine_class(fam.machine_class).scale ** 3, 9)


def _fitted(sc: Any, fam: Family, target: float) -> Any:
    """A generated scenario fitted to the family's machine class (the compact class's as it is)."""
    if fam.machine_class == DEFAULT_CLASS or not isinstance(sc, Scenario):
        return sc
    return fit(sc, machine_class(fam.machine_class), target)


# -- sealed draws (earthbench.seal holds the key and the site transform) -------------------------


def new_key(suite: Suite) -> tuple[SealKey, Suite]:
    """A fresh random key for ``suite`` and the sealed suite it draws (its commitment computed)."""
    draft = SealKey(suite.name, suite.digest, secrets.token_bytes(KEY_BYTES), created_at=datetime.now(UTC).isoformat(timespec="seconds"),
                    path=str(Path(suite.path).resolve()) if suite.path else "")
    return _complete(draft, suite)


def _complete(key: SealKey, suite: Suite) -> tuple[SealKey, Suite]:
    """The sealed suite of ``key`` and the key with the commitment those scenarios give."""
    probe = suite.sealed(key)
    c = commitment(key.key, suite.digest, [s.digest for s in probe.scenarios], key.schema)
    full = dataclasses.replace(key, commitment=c)
    return full, suite.sealed(full, drawn=probe.scenarios)


def open_sealed(suite: Suite, key: SealKey) -> Suite:
    """The sealed suite ``key`` draws from ``suite``, after checking the key is for this suite
    version and that its scenarios reproduce the key's commitment."""
    if key.suite != suite.name:
        raise SealError(f"the key was made for suite {key.suite!r}, not {suite.name!r}")
    if key.suite_digest != suite.digest:
        raise SealError(f"the key was made for suite {suite.name!r} digest {key.suite_digest[:12]}…, but the suite here has digest "
                        f"{suite.digest[:12]}… (the suite changed); make a new key with `earthbench seal {suite.name}`")
    full, sealed = _complete(key, suite)
    if full.commitment != key.commitment:
        raise SealError(f"the key file's commitment {key.commitment[:12]}… is not the one its key and suite give "
                        f"({full.commitment[:12]}…): the key file was edited, or the generators changed")
    return sealed


# -- finding suites -------------------------------------------------------------------------------


def known_suites() -> dict[str, Path]:
    """Suite name → file, from every package in the ``earthbench.suites`` entry-point group.

    A package that fails to import is skipped (as a broken planner plugin is); the first
    package to define a name wins.
    """
    found: dict[str, Path] = {}
    for ep in sorted(entry_points(group=SUITE_GROUP), key=lambda e: e.name):
        try:
            pkg = ep.load()
            root = resources.files(pkg)
        except Exception:  # noqa: BLE001 - one broken plugin must not hide the others
            continue
        for item in sorted(root.iterdir(), key=lambda p: p.name):
            if item.name.endswith(".toml") and item.is_file():
                found.setdefault(item.name[: -len(".toml")], Path(str(item)))
    return found


@cache
def registered_suite(name: str) -> Suite:
    """The registered suite ``name``, loaded and generated once per process (for the checks that
    compare stored suites with it: :mod:`earthbench.results.identity`, ``verify --key``). Not for
    running: a run may change its copy's planner settings."""
    return load_suite(name)


def public_suite(key: SealKey) -> Suite:
    """The public suite a sealed key was drawn from: the registered suite of its name, else the
    suite file the key was made from."""
    return registered_suite(key.suite) if key.suite in known_suites() or not key.path else load_suite(key.path)


def load_suite(name_or_path: str | Path) -> Suite:
    """Load a suite by registered name or by the path of a TOML file."""
    text = str(name_or_path)
    p = Path(text)
    if text.endswith(".toml") or p.is_file() or "/" in text:
        if not p.is_file():
            raise SuiteError(f"suite file {text!r} not found")
        body = _read(p)
        suite = parse_suite(body, path=str(p), default_name=p.stem)
        known = known_suites().get(suite.name)
        if known is not None and known.resolve() != p.resolve() and _read(known) != body:
            # a store and a board know a suite by its name: the two would hide each other's runs
            raise SuiteError(f"suite file {text!r} is named {suite.name!r}, like the registered suite of that name "
                             f"({known}), but differs from it; give it a name of its own (its 'name' key, or the file's name)")
        return suite
    suites = known_suites()
    if text not in suites:
        raise UnknownNameError("suite", text, suites)
    f = suites[text]
    return parse_suite(_read(f), path=str(f), default_name=text)


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise SuiteError(f"suite file {str(path)!r} is not UTF-8 text (is it a TOML file?)") from None
    except OSError as exc:
        raise SuiteError(f"cannot read suite file {str(path)!r}: {exc.strerror}") from None


# -- parsing ---------------------------------------------------------------------------------------


def _seeds(value: Any, where: str) -> tuple[int, ...]:
    if isinstance(value, str):
        try:
            a, b = (int(x) for x in value.split("-"))
        except ValueError:
            raise SuiteError(f"{where}: seeds {value!r} must be a list of integers or a range 'A-B' such as '0-9'") from None
        if b < a:
            raise SuiteError(f"{where}: seed range {value!r} is empty (end before start)")
        return tuple(range(a, b + 1))
    if isinstance(value, list) and value and all(isinstance(s, int) and not isinstance(s, bool) for s in value):
        if len(set(value)) != len(value):
            raise SuiteError(f"{where}: seeds {value} repeat a seed")
        return tuple(value)
    raise SuiteError(f"{where}: seeds must be a non-empty list of integers or a range 'A-B', got {value!r}")


def parse_seed_range(text: str) -> tuple[int, ...]:
    """``"3"``, ``"0-9"`` or a comma-separated list of both (``"2,4"``, ``"0-2,7"``) → the seeds;
    used by ``earthbench run --seeds``."""
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not re.fullmatch(r"\d+(-\d+)?", part):
            raise SuiteError(f"--seeds: {text!r} must be a seed, a range 'A-B' such as '0-9', or a comma-separated list of both")
        got = (int(part),) if part.isdigit() else _seeds(part, "--seeds")
        if set(got) & set(out):
            raise SuiteError(f"--seeds: {text!r} names a seed twice")
        out += got
    return tuple(out)


def _targets(value: Any, where: str) -> tuple[float, ...]:
    if not isinstance(value, list) or not value:
        raise SuiteError(f"{where}: targets must be a non-empty list of volumes in m³, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0 and math.isfinite(v)):
            raise SuiteError(f"{where}: target {v!r} must be a positive number of m³")
        out.append(float(v))
    return tuple(out)


def _check_realism(fam: Family, where: str) -> None:
    """Refuse a family's ``soil`` or ``sensing`` table that no scenario could carry, naming the key."""
    for key in ("soil", "sensing"):
        table = getattr(fam, key)
        if table is not None and not isinstance(table, dict):
            raise SuiteError(f"{where}: {key} must be a table, got {table!r:.40}")
    if fam.sensing is not None:
        refuse_unknown(fam.sensing, [f.name for f in dataclasses.fields(Sensing)], f"{where} sensing")
    try:
        fam.realism(fam.seeds[0])
    except EarthbenchError as exc:
        raise SuiteError(f"{where}: {exc}") from None


def _included_families(names: Any, where: str, path: str, track: str, stack: tuple[str, ...]) -> list[Family]:
    """The families of the suites named in ``include``, renamed ``SUITE.FAMILY``."""
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        raise SuiteError(f"{where}: include must be a list of suite names or paths, got {names!r}")
    out: list[Family] = []
    for name in names:
        if name in stack:
            raise SuiteError(f"{where}: include {name!r} forms a cycle ({' -> '.join(stack + (name,))})")
        suites = known_suites()
        rel = Path(path).parent / name if path else Path(name)
        if name in suites:
            file = suites[name]
        elif rel.is_file():
            file = rel
        else:
            close = difflib.get_close_matches(name, list(suites), n=3, cutoff=0.5)
            hint = f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise SuiteError(
                f"{where}: include {name!r} is neither a known suite nor a file.{hint} Known suites: {', '.join(sorted(suites))}."
            )
        sub = parse_suite(_read(Path(file)), path=str(file), default_name=Path(file).stem, _stack=stack + (name,))
        if sub.track != track:
            raise SuiteError(f"{where}: included suite {sub.name!r} is a {sub.track!r} suite; this suite's track is {track!r}")
        out.extend(dataclasses.replace(f, name=f"{sub.name}.{f.name}") for f in sub.families)
    return out


def _budget(budget_doc: Any, where: str) -> Budget:
    """The suite's ``[budget]`` table, checked: positive finite numbers, integers where counted."""
    if not isinstance(budget_doc, dict):
        raise SuiteError(f"{where}: [budget] must be a table with {', '.join(_BUDGET_KEYS)}")
    refuse_unknown(budget_doc, _BUDGET_KEYS, f"{where} [budget]")
    for k, v in budget_doc.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0 and math.isfinite(v)):
            raise SuiteError(f"{where} [budget]: {k} must be a positive finite number, got {v!r}")
    if "cores" in budget_doc and not isinstance(budget_doc["cores"], int):
        raise SuiteError(f"{where} [budget]: cores must be an integer, got {budget_doc['cores']!r}")
    if "memory_mb" in budget_doc and not isinstance(budget_doc["memory_mb"], int):
        raise SuiteError(f"{where} [budget]: memory_mb must be an integer, got {budget_doc['memory_mb']!r}")
    for k in ("max_steps", "prepare_memory_mb", "prepare_disk_mb"):
        if k in budget_doc and not isinstance(budget_doc[k], int):
            raise SuiteError(f"{where} [budget]: {k} must be an integer, got {budget_doc[k]!r}")
    for k in ("wall_s", "step_s", "cpu_s", "prepare_s"):  # 60 and 60.0 must give the same scenario digest
        if k in budget_doc:
            budget_doc = {**budget_doc, k: float(budget_doc[k])}
    return Budget(**budget_doc)


def _family(fd: Any, n: int, where: str, path: str) -> Family:
    """The ``n``-th ``[[family]]`` table (from 0), checked against its generator's parameters."""
    from ..registry import TERRAINS

    fwhere = f"{where} [[family]] #{n + 1}"
    refuse_unknown(fd, _FAMILY_KEYS, fwhere)
    for req in ("name", "generator", "targets", "seeds"):
        if req not in fd:
            raise SuiteError(f"{fwhere}: missing key {req!r}")
    fname = fd["name"]
    if not isinstance(fname, str) or not fname or "/" in fname:
        raise SuiteError(f"{fwhere}: name must be a non-empty string without '/', got {fname!r}")
    fwhere = f"{where} family {fname!r}"
    try:
        gen = TERRAINS.get(fd["generator"])
    except EarthbenchError as exc:
        raise SuiteError(f"{fwhere}: {exc}") from None
    params = fd.get("params", {})
    if not isinstance(params, dict):
        raise SuiteError(f"{fwhere}: params must be a table")
    params = check_params(gen, params, fwhere, path, MAX_CELLS)
    fam = Family(fname, fd["generator"], _targets(fd["targets"], fwhere), _seeds(fd["seeds"], fwhere), params,
                 fd.get("soil"), fd.get("sensing"), _class_name(fd.get("class", DEFAULT_CLASS), fwhere))
    _check_realism(fam, fwhere)
    return fam


def _class_name(name: Any, where: str) -> str:
    """A machine class's name, checked (an unknown one suggests the close names)."""
    if not isinstance(name, str):
        raise SuiteError(f"{where}: class must be the name of a machine class, got {name!r:.40}")
    try:
        machine_class(name)
    except EarthbenchError as exc:
        raise SuiteError(f"{where}: {exc}") from None
    return name


def _with_classes(doc: dict[str, Any], families: list[Family], where: str) -> list[Family]:
    """The families under the suite's ``class`` (for those that name none) or swept over its
    ``classes`` (each family once per class, renamed ``FAMILY@CLASS``)."""
    if "class" in doc and "classes" in doc:
        raise SuiteError(f"{where}: give class or classes, not both")
    if "class" in doc:
        name = _class_name(doc["class"], where)
        return [f if f.machine_class != DEFAULT_CLASS else dataclasses.replace(f, machine_class=name) for f in families]
    if "classes" in doc:
        names = doc["classes"]
        if not isinstance(names, list) or not names or len(set(map(str, names))) != len(names):
            raise SuiteError(f"{where}: classes must be a non-empty list of distinct machine class names, got {names!r:.60}")
        return [dataclasses.replace(f, name=f"{f.name}@{n}", machine_class=_class_name(n, where)) for n in names for f in families]
    return families


def parse_suite(text: str, *, path: str = "", default_name: str = "", _stack: tuple[str, ...] = ()) -> Suite:
    """Check and build a suite from TOML text; every error names the file and the key."""
    where = path or "suite"
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SuiteError(f"{where} is not valid TOML: {exc}") from None
    refuse_unknown(doc, _TOP_KEYS, where)
    name = doc.get("name", default_name)
    if not isinstance(name, str) or not name or "/" in name:
        raise SuiteError(f"{where}: 'name' must be a non-empty string without '/', got {name!r}")
    track = doc.get("track", "backhoe")
    if track not in TRACKS:
        close = difflib.get_close_matches(str(track), TRACKS, n=1)
        raise SuiteError(f"{where}: track {track!r} is not one of {', '.join(TRACKS)}" + (f"; did you mean {close[0]!r}?" if close else ""))
    threshold = doc.get("success_threshold", DEFAULT_THRESHOLD)
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or not 0 < threshold <= 1:
        raise SuiteError(f"{where}: success_threshold must be a number in (0, 1], got {threshold!r}")
    budget = _budget(doc.get("budget", {}), where)
    prepare = doc.get("prepare", True)
    if not isinstance(prepare, bool):
        raise SuiteError(f"{where}: prepare must be true or false, got {prepare!r}")
    planners = doc.get("planners")
    if planners is not None and (not isinstance(planners, list) or not all(isinstance(p, str) for p in planners)):
        raise SuiteError(f"{where}: planners must be a list of planner names, got {planners!r}")
    config = doc.get("config", {})
    if not isinstance(config, dict) or not all(isinstance(v, dict) for v in config.values()):
        raise SuiteError(f"{where}: [config.PLANNER] sections must be tables of settings")
    fams_doc = doc.get("family", [] if "include" in doc else None)
    if not isinstance(fams_doc, list) or not (fams_doc or "include" in doc):
        raise SuiteError(f"{where}: a suite needs at least one [[family]] table or an include list")
    families = [_family(fd, n, where, path) for n, fd in enumerate(fams_doc)]
    if "include" in doc:
        families.extend(_included_families(doc["include"], where, path, track, _stack + (name,)))
    families = _with_classes(doc, families, where)
    if len({f.name for f in families}) != len(families):
        raise SuiteError(f"{where}: two families share a name; scenario ids would clash")
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise SuiteError(f"{where}: description must be a string")
    return Suite(
        name=name,
        track=track,
        budget=budget,
        families=tuple(families),
        description=desc,
        success_threshold=float(threshold),
        planners=tuple(planners) if planners is not None else None,
        prepare=prepare,
        config={k: dict(v) for k, v in config.items()},
        path=path,
    )
