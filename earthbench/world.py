"""The world model: terrain, site, machines, task, budget and the immutable Scenario.

Conventions (docs/DESIGN.md §3): SI units; x east, y north, z up; yaw counter-clockwise from +x;
time in seconds from 0; volumes are bank volumes in m³.

The heightmap is cell-centred: cell ``z[j, i]`` covers ``[x0 + i·r, x0 + (i+1)·r) ×
[y0 + j·r, y0 + (j+1)·r)`` and its height is the height of the whole cell, so a volume is a
sum of heights times ``r²``. This grid is the only terrain truth a planner receives.
"""

from __future__ import annotations

import base64
import dataclasses
import difflib
import functools
import hashlib
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .errors import ScenarioError, read_document
from .machines import LATER, ExcavatorSpec, LoaderSpec, Machines, Pose, TruckSpec, later, rectangle  # noqa: F401 - their documented place is here too

SCENARIO_SCHEMA = "earthbench.scenario/1"
TRACKS = ("backhoe", "wheel_loader")
Track = Literal["backhoe", "wheel_loader"]
Point = tuple[float, float]
Polygon = tuple[Point, ...]

@dataclass(frozen=True, eq=False)
class Heightmap:
    """A regular grid of cell heights ``z[ny, nx]`` with its lower-left corner at ``origin``."""

    origin: Point
    resolution: float
    z: np.ndarray

    def __post_init__(self) -> None:
        z = np.array(self.z, dtype=np.float64)  # a private, read-only copy keeps Scenario immutable
        if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2:
            raise ScenarioError(f"heightmap z must be a 2-D grid of at least 2×2 cells, got shape {z.shape}")
        if not np.all(np.isfinite(z)):
            raise ScenarioError("heightmap z contains NaN or infinite values; fill or crop them first")
        if not (self.resolution > 0 and math.isfinite(self.resolution)):
            raise ScenarioError(f"heightmap resolution must be a positive number of metres, got {self.resolution}")
        z.setflags(write=False)
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "origin", (float(self.origin[0]), float(self.origin[1])))
        object.__setattr__(self, "resolution", float(self.resolution))

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Heightmap)
            and self.origin == other.origin
            and self.resolution == other.resolution
            and np.array_equal(self.z, other.z)
        )

    def __hash__(self) -> int:
        return hash((self.origin, self.resolution, self.z.shape, self.z.tobytes()))

    @property
    def shape(self) -> tuple[int, int]:
        return self.z.shape  # type: ignore[return-value]

    @property
    def cell_area(self) -> float:
        return self.resolution**2

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the grid's outer cell edges."""
        ny, nx = self.shape
        x0, y0 = self.origin
        return (x0, x0 + nx * self.resolution, y0, y0 + ny * self.resolution)

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """1-D arrays of the x and y coordinates of the cell centres."""
        ny, nx = self.shape
        x0, y0 = self.origin
        r = self.resolution
        return x0 + (np.arange(nx) + 0.5) * r, y0 + (np.arange(ny) + 0.5) * r

    def height_at(self, x: float, y: float, z: np.ndarray | None = None) -> float:
        """Bilinear height between cell centres (clamped at the border) of ``z`` or the map."""
        zz = self.z if z is None else z
        ny, nx = zz.shape
        fx = (x - self.origin[0]) / self.resolution - 0.5
        fy = (y - self.origin[1]) / self.resolution - 0.5
        fx = min(max(fx, 0.0), nx - 1.0)
        fy = min(max(fy, 0.0), ny - 1.0)
        i0 = min(int(fx), nx - 2)
        j0 = min(int(fy), ny - 2)
        tx, ty = fx - i0, fy - j0
        top = zz[j0, i0] * (1 - tx) + zz[j0, i0 + 1] * tx
        bot = zz[j0 + 1, i0] * (1 - tx) + zz[j0 + 1, i0 + 1] * tx
        return float(top * (1 - ty) + bot * ty)

    def heights_at(self, x: np.ndarray, y: np.ndarray, z: np.ndarray | None = None) -> np.ndarray:
        """:meth:`height_at` for arrays of points at once, with the same clamping and arithmetic."""
        zz = self.z if z is None else z
        ny, nx = zz.shape
        fx = np.clip((np.asarray(x) - self.origin[0]) / self.resolution - 0.5, 0.0, nx - 1.0)
        fy = np.clip((np.asarray(y) - self.origin[1]) / self.resolution - 0.5, 0.0, ny - 1.0)
        i0 = np.minimum(fx.astype(int), nx - 2)
        j0 = np.minimum(fy.astype(int), ny - 2)
        tx, ty = fx - i0, fy - j0
        top = zz[j0, i0] * (1 - tx) + zz[j0, i0 + 1] * tx
        bot = zz[j0 + 1, i0] * (1 - tx) + zz[j0 + 1, i0 + 1] * tx
        return top * (1 - ty) + bot * ty

    def contains(self, x: float, y: float) -> bool:
        xmin, xmax, ymin, ymax = self.extent
        return xmin <= x <= xmax and ymin <= y <= ymax

    def volume_above(self, level: float | np.ndarray, mask: np.ndarray | None = None) -> float:
        """Bank volume (m³) of the cells above ``level``, optionally only where ``mask``."""
        excess = np.clip(self.z - level, 0.0, None)
        if mask is not None:
            excess = excess[mask]
        return float(excess.sum() * self.cell_area)

    def with_z(self, z: np.ndarray) -> Heightmap:
        return Heightmap(self.origin, self.resolution, z)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: origin, resolution, and the heights as base64 of little-endian float64."""
        z = np.ascontiguousarray(self.z, dtype="<f8")
        return {"origin": list(self.origin), "resolution": self.resolution,
                "z": {"shape": list(z.shape), "f8_base64": base64.b64encode(z.tobytes()).decode()}}

    @classmethod
    def from_dict(cls, t: dict[str, Any]) -> Heightmap:
        """Read :meth:`to_dict`'s form (or heights as nested lists)."""
        z = t["z"]
        if isinstance(z, dict):
            z = np.frombuffer(base64.b64decode(z["f8_base64"]), dtype="<f8").reshape(z["shape"])
        return cls(tuple(t["origin"]), t["resolution"], np.asarray(z, dtype=float))


def _polygon(points: Any, what: str) -> Polygon:
    try:
        poly = tuple((float(p[0]), float(p[1])) for p in points)
    except (TypeError, ValueError, IndexError) as exc:
        raise ScenarioError(f"{what} must be a list of [x, y] vertices: {exc}") from None
    if len(poly) < 3 or not all(math.isfinite(c) for p in poly for c in p):
        raise ScenarioError(f"{what} needs at least 3 finite [x, y] vertices, got {len(poly)}")
    return poly


@dataclass(frozen=True)
class Site:
    """Where digging is allowed: the dig area, the design grade and the keep-out zones.

    ``open_outside`` says whether the ground beyond the heightmap's edge is open, level ground
    at the floor (or, without a floor, at the map's lowest cell) that machines may use, or
    closed (a path or footprint leaving the map is ``off_map``). ``None`` (the default, left out
    of the JSON) means the track's convention: open for ``backhoe`` (the STL-TAMP paper's maps
    show only the dig area, with the machines beside it), closed for ``wheel_loader``.
    """

    dig_area: Polygon
    floor: float | None = None
    keep_outs: tuple[Polygon, ...] = ()
    open_outside: bool | None = later(None)

    def __post_init__(self) -> None:
        object.__setattr__(self, "dig_area", _polygon(self.dig_area, "site.dig_area"))
        object.__setattr__(
            self,
            "keep_outs",
            tuple(_polygon(k, f"site.keep_outs[{n}]") for n, k in enumerate(self.keep_outs)),
        )
        if self.floor is not None:
            object.__setattr__(self, "floor", float(self.floor))
        if self.open_outside not in (None, True, False):
            raise ScenarioError(f"site.open_outside must be true, false or absent, got {self.open_outside!r}")


@dataclass(frozen=True)
class Task:
    """What must be achieved: remove ``target_volume`` m³ from the dig area into the truck."""

    target_volume: float

    def __post_init__(self) -> None:
        if not (self.target_volume > 0 and math.isfinite(self.target_volume)):
            raise ScenarioError(f"task.target_volume must be a positive number of m³, got {self.target_volume}")


@dataclass(frozen=True)
class Budget:
    """Resources a planner gets for one scenario; the harness enforces them.

    ``wall_s`` bounds the planner's compute, over all steps of a closed-loop run; ``step_s``
    bounds one step and ``max_steps`` the number of steps (docs/DESIGN.md §6); ``cpu_s`` bounds
    the CPU seconds of the case's whole process tree, counted by the kernel (docs/isolation.md).
    The step limits and ``cpu_s`` are left out of the JSON at their defaults, so scenarios keep
    their digests. ``prepare_s``, ``prepare_memory_mb`` and ``prepare_disk_mb`` bound a planner's scenario-blind
    preparation, run once per machine before its first case (docs/DESIGN.md §6 "Preparation");
    left out at their defaults too.
    """

    wall_s: float = 300.0
    cores: int = 2
    memory_mb: int = 4096
    step_s: float = later(300.0)
    max_steps: int = later(1000)
    #: CPU seconds of the whole process tree over all calls (None: only the wall budget bounds it).
    cpu_s: float | None = later(None)
    prepare_s: float = later(1800.0)
    prepare_memory_mb: int = later(4096)
    #: Disk a preparation's folder may take (MB; docs/isolation.md "Disk").
    prepare_disk_mb: int = later(2048)


def _number(value: Any, where: str, *, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, hi_open: bool = False, integer: bool = False) -> Any:
    """``value`` checked as a finite number (an integer when ``integer``) in the given range;
    a :class:`ScenarioError` naming ``where`` (the field's path) otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        want = "an integer" if integer else "a number"
        raise ScenarioError(f"scenario field {where} must be {want}, got {type(value).__name__} {value!r:.40}")
    if not math.isfinite(value):
        raise ScenarioError(f"scenario field {where} must be finite, got {value}")
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise ScenarioError(f"scenario field {where} must be {'>' if lo_open else '≥'} {lo:g}, got {value:g}")
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise ScenarioError(f"scenario field {where} must be {'<' if hi_open else '≤'} {hi:g}, got {value:g}")
    return value if integer else float(value)


@dataclass(frozen=True)
class Soil:
    """How the ground really responds to digging; known to the referee only (docs/DESIGN.md §3).

    ``material`` names the class (``earthbench.soil.MATERIALS``), the one thing a planner is
    told. ``fill_factor``: the bank volume a full stroke or charge really holds, as a fraction of
    the machine's ``bucket_capacity``. ``swell``: loose ÷ bank volume (the truck's capacity
    counts loose m³). ``repose_deg``: the angle of repose; after each cut every slope between
    neighbouring cells steeper than it slumps (mass-conserving). ``hard_depth``: a harder
    layer starts this far below the initial surface (``None``: none); one stroke penetrates at
    most ``hard_penetration`` m into it. Values out of range are refused with the field's path.
    """

    material: str
    fill_factor: float
    swell: float
    repose_deg: float
    hard_depth: float | None = None
    hard_penetration: float = 0.1

    def __post_init__(self) -> None:
        if not isinstance(self.material, str) or not self.material:
            raise ScenarioError(f"scenario field soil.material must be a non-empty string, got {self.material!r:.40}")
        object.__setattr__(self, "fill_factor", _number(self.fill_factor, "soil.fill_factor", lo=0.0, hi=2.0, lo_open=True))
        object.__setattr__(self, "swell", _number(self.swell, "soil.swell", lo=1.0, hi=3.0))
        object.__setattr__(self, "repose_deg", _number(self.repose_deg, "soil.repose_deg", lo=0.0, hi=90.0, lo_open=True, hi_open=True))
        if self.hard_depth is not None:
            object.__setattr__(self, "hard_depth", _number(self.hard_depth, "soil.hard_depth", lo=0.0))
        object.__setattr__(self, "hard_penetration", _number(self.hard_penetration, "soil.hard_penetration", lo=0.0, lo_open=True))


@dataclass(frozen=True)
class Sensing:
    """The scan a planner receives instead of the true heightmap (docs/DESIGN.md §3;
    :func:`earthbench.sensing.observe`).

    ``cell_size``: the scan's grid (a whole multiple of the terrain's resolution; ``None``: the
    terrain's). ``noise``: σ (m) of the independent Gaussian error of each scanned cell;
    ``bias``: a constant height offset (m). ``occlusion``: cells hidden from a sensor
    ``sensor_height`` m above the ground at the working machine's pose are not measured (filled
    from the nearest measured cell). ``seed`` seeds the noise (mixed with the scan's step).
    """

    noise: float = 0.0
    bias: float = 0.0
    cell_size: float | None = None
    occlusion: bool = True
    sensor_height: float = 2.5
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "noise", _number(self.noise, "sensing.noise", lo=0.0))
        object.__setattr__(self, "bias", _number(self.bias, "sensing.bias"))
        if self.cell_size is not None:
            object.__setattr__(self, "cell_size", _number(self.cell_size, "sensing.cell_size", lo=0.0, lo_open=True))
        if self.occlusion not in (True, False):
            raise ScenarioError(f"scenario field sensing.occlusion must be true or false, got {self.occlusion!r:.40}")
        object.__setattr__(self, "sensor_height", _number(self.sensor_height, "sensing.sensor_height", lo=0.0, lo_open=True))
        object.__setattr__(self, "seed", _number(self.seed, "sensing.seed", lo=0, integer=True))


@dataclass(frozen=True)
class Scenario:
    """One benchmark problem. Immutable; ``digest`` identifies its content on every machine.

    ``id`` and ``meta`` (generator, parameters, seed) are labels: they are carried in the JSON
    but left out of the digest, so the same problem reached through two suites is one problem.
    """

    id: str
    terrain: Heightmap
    site: Site
    machines: Machines
    task: Task
    track: Track = "backhoe"
    budget: Budget = Budget()
    meta: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)
    soil: Soil | None = later(None)
    sensing: Sensing | None = later(None)

    def __post_init__(self) -> None:
        if self.track not in TRACKS:
            raise ScenarioError(f"track must be one of {TRACKS}, got {self.track!r}")
        needed = {"backhoe": "excavator", "wheel_loader": "loader"}[self.track]
        if getattr(self.machines, needed, None) is None:
            raise ScenarioError(f"a {self.track} scenario needs machines.{needed}")
        cell = self.sensing.cell_size if self.sensing is not None else None
        if cell is not None:
            k = cell / self.terrain.resolution
            if abs(k - round(k)) > 1e-9 * k or round(k) < 1:
                raise ScenarioError(
                    f"scenario field sensing.cell_size ({cell:g} m)"
                    f" must be a whole multiple of the terrain's resolution ({self.terrain.resolution:g} m)"
                )

    @property
    def worker(self) -> str:
        """The machine that digs: ``excavator`` (backhoe track) or ``loader`` (wheel-loader track)."""
        return "excavator" if self.track == "backhoe" else "loader"

    @property
    def outside_open(self) -> bool:
        """Whether machines may leave the map (``Site.open_outside``, else the track's convention)."""
        if self.site.open_outside is not None:
            return self.site.open_outside
        return self.track == "backhoe"

    @property
    def truck_holds(self) -> float:
        """Bank m³ the truck holds: its capacity counts loose m³, so with soil it is divided by the swell."""
        capacity = self.machines.truck.capacity
        return capacity if self.soil is None else capacity / self.soil.swell

    @property
    def outside_level(self) -> float:
        """Height of the open ground beyond the map: the floor, or the map's lowest cell."""
        return self.site.floor if self.site.floor is not None else float(self.terrain.z.min())

    # -- identity ---------------------------------------------------------------------------
    def _content(self) -> dict[str, Any]:
        d = _drop_absent_loader(_to_plain(self))
        d.pop("id"), d.pop("meta")
        d["terrain"].pop("z")
        return d

    @functools.cached_property
    def digest(self) -> str:
        """sha256 over canonical JSON of the content and the heightmap's little-endian bytes.

        Computed once per object (a scenario and its read-only heightmap never change).
        """
        h = hashlib.sha256(_canonical(self._content()).encode())
        h.update(np.ascontiguousarray(self.terrain.z, dtype="<f8").tobytes())
        return h.hexdigest()

    def replace(self, **changes: Any) -> Scenario:
        return dataclasses.replace(self, **changes)

    # -- JSON ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d = _drop_absent_loader(_to_plain(self))
        return {"schema": SCENARIO_SCHEMA, **d}

    def to_json(self, path: str | Path | None = None) -> str:
        text = json.dumps(self.to_dict(), indent=1, sort_keys=True)
        if path is not None:
            Path(path).write_text(text)
        return text

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Scenario:
        if not isinstance(d, dict):
            raise ScenarioError("a scenario document must be a JSON object")
        if d.get("schema", SCENARIO_SCHEMA) != SCENARIO_SCHEMA:
            raise ScenarioError(f"unsupported scenario schema {d.get('schema')!r}; expected {SCENARIO_SCHEMA!r}")
        try:
            terrain = Heightmap.from_dict(_section(d["terrain"], "terrain"))
            s = _section(d["site"], "site")
            site = Site(tuple(s["dig_area"]), s.get("floor"), tuple(s.get("keep_outs", ())), s.get("open_outside"))
            m = _section(d["machines"], "machines")
            machines = Machines(
                truck=checked_section(TruckSpec, m["truck"], "machines.truck"),
                truck_pose=checked_section(Pose, m["truck_pose"], "machines.truck_pose"),
                excavator=checked_section(ExcavatorSpec, m["excavator"], "machines.excavator") if m.get("excavator") else None,
                excavator_pose=checked_section(Pose, m["excavator_pose"], "machines.excavator_pose") if m.get("excavator_pose") else None,
                loader=checked_section(LoaderSpec, m["loader"], "machines.loader") if m.get("loader") else None,
                loader_pose=checked_section(Pose, m["loader_pose"], "machines.loader_pose") if m.get("loader_pose") else None,
                machine_class=m.get("machine_class", "compact"),
            )
            return cls(
                id=str(d["id"]),
                terrain=terrain,
                site=site,
                machines=machines,
                task=checked_section(Task, d["task"], "task"),
                track=d.get("track", "backhoe"),
                budget=checked_section(Budget, d.get("budget", {}), "budget"),
                meta=dict(d.get("meta", {})),
                soil=checked_section(Soil, d["soil"], "soil") if d.get("soil") is not None else None,
                sensing=checked_section(Sensing, d["sensing"], "sensing") if d.get("sensing") is not None else None,
            )
        except ScenarioError:
            raise
        except KeyError as exc:
            raise ScenarioError(f"malformed scenario document: the field {exc} is missing") from None
        except OverflowError:  # an integer beyond the largest float somewhere in the document
            raise ScenarioError("malformed scenario document: a number is too large for a float") from None
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f"malformed scenario document: {type(exc).__name__}: {exc}") from None

    @classmethod
    def from_json(cls, source: str | Path) -> Scenario:
        """A scenario from JSON text (a ``str``) or from a file (a :class:`~pathlib.Path`).

        A ``str`` that is not JSON but names an existing file is read as that file, as
        earthbench 0.1 did, with a :class:`DeprecationWarning`: pass a ``Path`` (or call
        :meth:`load`). Documents from a store are parsed with :meth:`from_text`, which never
        reads a file.
        """
        if isinstance(source, Path):
            return cls.load(source)
        if isinstance(source, str) and not source.lstrip().startswith("{") and _is_file(source):
            warnings.warn(
                f"Scenario.from_json({source!r}): a str is JSON text; read a file with Scenario.load({source!r}) "
                f"or Scenario.from_json(pathlib.Path({source!r})). Reading it as a file ends in a later release.",
                DeprecationWarning, stacklevel=2,
            )
            return cls.load(source)
        return cls.from_text(source)

    @classmethod
    def load(cls, path: str | Path) -> Scenario:
        """A scenario from a JSON file."""
        return cls.from_text(read_document(Path(path), "scenario", ScenarioError))

    @classmethod
    def from_text(cls, text: str) -> Scenario:
        """A scenario from JSON text only (never a file name: documents from a store are untrusted)."""
        try:
            doc = json.loads(text)
        except RecursionError:
            raise ScenarioError("scenario JSON is nested too deeply") from None
        except ValueError as exc:
            raise ScenarioError(f"scenario is not valid JSON: {exc}") from None
        return cls.from_dict(doc)



def _is_file(text: str) -> bool:
    try:
        return len(text) < 4096 and Path(text).is_file()
    except (OSError, ValueError):
        return False


#: Numeric fields of a scenario document that may be 0 (every other spec or budget number must be > 0).
_MAY_BE_ZERO = frozenset({
    "reach_min", "clearance", "chord_tolerance", "max_step", "min_stroke_time", "min_dump_time",
    "min_charge_time", "dump_reach", "bucket_offset",
})


def _section(doc: Any, path: str) -> dict[str, Any]:
    if not isinstance(doc, dict):
        raise ScenarioError(f"scenario field {path} must be an object, got {type(doc).__name__}")
    return doc


def checked_section(cls: type, doc: Any, path: str) -> Any:
    """Build ``cls`` from one section of a scenario document, checking each field's type and range.

    Poses may hold any finite numbers; every other number (specs, budget, task) must be finite
    and positive (0 allowed for the fields in ``_MAY_BE_ZERO``); ``int`` fields take integers only.
    """
    doc = _section(doc, path)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key, value in doc.items():
        where = f"{path}.{key}"
        f = fields.get(key)
        if f is None:
            close = difflib.get_close_matches(str(key), fields, n=1)
            hint = f" (did you mean {path}.{close[0]}?)" if close else f"; its fields: {', '.join(fields)}"
            raise ScenarioError(f"scenario field {where} is unknown{hint}")
        kind = str(f.type)
        if kind == "float | None" and value is not None:  # optional numbers, e.g. the budget's cpu_s
            kind = "float"
        if kind not in ("float", "int") or cls in (Soil, Sensing):  # these check their own ranges
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind == "int" and not isinstance(value, int)):
            want = "an integer" if kind == "int" else "a number"
            raise ScenarioError(f"scenario field {where} must be {want}, got {type(value).__name__} {value!r:.40}")
        if isinstance(value, int) and abs(value) > 2**1023:  # beyond any float: math.isfinite would overflow
            raise ScenarioError(f"scenario field {where} must be finite, got an integer of {len(str(abs(value)))} digits")
        if not math.isfinite(value):
            raise ScenarioError(f"scenario field {where} must be finite, got {value}")
        if cls is not Pose and (value < 0 or (value == 0 and key not in _MAY_BE_ZERO)):
            raise ScenarioError(f"scenario field {where} must be {'≥ 0' if key in _MAY_BE_ZERO else 'positive'}, got {value:g}")
    for name, f in fields.items():
        if name not in doc and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ScenarioError(f"scenario field {path}.{name} is missing")
    return cls(**doc)


def _to_plain(obj: Any) -> Any:
    """Dataclasses → dicts, tuples → lists, numpy → Python; the JSON form of the world model."""
    if isinstance(obj, Heightmap):
        return obj.to_dict()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {
            f.name: _to_plain(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if not (f.metadata.get("omit_default") and getattr(obj, f.name) == f.default)
        }
    if isinstance(obj, dict):
        return {str(k): _to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _drop_absent_loader(d: dict[str, Any]) -> dict[str, Any]:
    """Leave out ``machines.loader``/``loader_pose`` when there is no loader, so scenarios
    without one keep the JSON form and digest they had before the loader existed."""
    m = d.get("machines", {})
    if m.get("loader") is None and m.get("loader_pose") is None:
        m.pop("loader", None), m.pop("loader_pose", None)
    return d


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def canonical_json(obj: Any) -> str:
    """Canonical JSON (sorted keys, no spaces) of any world-model object; used for digests."""
    return _canonical(_to_plain(obj))
