"""Machine classes: sets of machines of one size, written as data (docs/machine-classes.md).

Each ``*.toml`` file in this package is a class named by its ``name``: the specs of its
excavator, truck and wheel loader (parsed into :mod:`earthbench.machines`' dataclasses, every
field checked as a scenario document's is), the scale of its sites against the compact class's,
the fill factors its buckets carry per material, the source of every value and the handbook's
bands it is calibrated against (``earthbench calibration``). ``compact`` is the default: its
values are the dataclasses' defaults, so scenarios of it keep the JSON form and digest they had
before classes existed (``Machines.machine_class`` is left out at ``compact``).

:func:`fit` makes a scenario generated for the compact class one of another class: lengths and
heights × ``scale`` (volumes × scale³), the class's specs in place of the compact ones.
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from ..errors import ScenarioError, UnknownNameError
from ..machines import ExcavatorSpec, LoaderSpec, Machines, Pose, TruckSpec
from ..world import Heightmap, Scenario, Site, checked_section

DEFAULT_CLASS = "compact"
_KEYS = ("name", "description", "scale", "calibrated", "compared_with", "excavator", "truck", "loader", "fill_loose",
         "sources", "calibration")
_BAND_KEYS = ("what", "machine", "swing_deg", "material", "band", "source")


@dataclass(frozen=True)
class Band:
    """One handbook band a class is held against: ``what`` (``cycle`` s, ``fill`` loose ÷ heaped,
    ``production`` m³/h), the ``machine``, the condition (``swing_deg`` or ``material``) and its source."""

    what: str
    machine: str
    band: tuple[float, float]
    source: str
    swing_deg: tuple[float, float] | None = None
    material: str | None = None


@dataclass(frozen=True)
class MachineClass:
    """A machine class: its specs, site scale, fill factors, sources and calibration bands."""

    name: str
    description: str
    excavator: ExcavatorSpec
    truck: TruckSpec
    loader: LoaderSpec
    scale: float = 1.0
    calibrated: bool = False
    compared_with: str = ""
    fill_loose: dict[str, tuple[float, float]] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    bands: tuple[Band, ...] = ()

    def production_band(self, machine: str) -> tuple[float, float] | None:
        """The handbook's production band (m³/h) of this class's ``machine``, if it has one."""
        for b in self.bands:
            if b.what == "production" and b.machine == machine:
                return b.band
        return None


def _pair(value: Any, where: str) -> tuple[float, float]:
    if (not isinstance(value, list) or len(value) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                                   for v in value) or value[0] > value[1]):
        raise ScenarioError(f"{where} must be [lo, hi] with lo ≤ hi, got {value!r:.60}")
    return float(value[0]), float(value[1])


def _band(doc: Any, where: str) -> Band:
    if not isinstance(doc, dict):
        raise ScenarioError(f"{where} must be a table")
    for key in doc:
        if key not in _BAND_KEYS:
            raise ScenarioError(f"{where}.{key} is unknown; its keys: {', '.join(_BAND_KEYS)}")
    if doc.get("what") not in ("cycle", "fill", "production") or doc.get("machine") not in ("excavator", "loader"):
        raise ScenarioError(f"{where} needs what = cycle, fill or production and machine = excavator or loader")
    return Band(doc["what"], doc["machine"], _pair(doc.get("band"), f"{where}.band"), str(doc.get("source", "")),
                _pair(doc["swing_deg"], f"{where}.swing_deg") if "swing_deg" in doc else None, doc.get("material"))


def parse_class(text: str, where: str) -> MachineClass:
    """A machine class from its TOML text; every error names ``where`` and the key."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where} is not valid TOML: {exc}") from None
    for key in doc:
        if key not in _KEYS:
            close = difflib.get_close_matches(key, _KEYS, n=1)
            raise ScenarioError(f"{where}: unknown key {key!r}" + (f"; did you mean {close[0]!r}?" if close else ""))
    name = doc.get("name")
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"{where}: name must be a non-empty string")
    specs = {k: checked_section(cls, doc.get(k, {}), f"{where} [{k}]")
             for k, cls in (("excavator", ExcavatorSpec), ("truck", TruckSpec), ("loader", LoaderSpec))}
    scale = doc.get("scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0.1 <= scale <= 10:
        raise ScenarioError(f"{where}: scale must be a number in [0.1, 10], got {scale!r}")
    fill = {str(m): _pair(v, f"{where} [fill_loose].{m}") for m, v in doc.get("fill_loose", {}).items()}
    bands = tuple(_band(b, f"{where} [[calibration]] #{n + 1}") for n, b in enumerate(doc.get("calibration", [])))
    return MachineClass(name, str(doc.get("description", "")), specs["excavator"], specs["truck"], specs["loader"],
                        float(scale), bool(doc.get("calibrated", False)), str(doc.get("compared_with", "")), fill,
                        {str(k): str(v) for k, v in doc.get("sources", {}).items()}, bands)


@cache
def machine_classes() -> dict[str, MachineClass]:
    """Every machine class shipped with earthbench, by name, ``compact`` first."""
    found: dict[str, MachineClass] = {}
    for item in sorted(resources.files(__name__).iterdir(), key=lambda p: (p.name != f"{DEFAULT_CLASS}.toml", p.name)):
        if item.name.endswith(".toml") and item.is_file():
            mc = parse_class(item.read_text(encoding="utf-8"), f"machine class file {item.name}")
            found[mc.name] = mc
    return found


def machine_class(name: str) -> MachineClass:
    """The machine class ``name``; an unknown name suggests the close ones."""
    known = machine_classes()
    if name not in known:
        raise UnknownNameError("machine class name", name, known)
    return known[name]


def _times(v: float, s: float) -> float:
    """``v × s`` rounded to 1e-9 m, so that 0.05 × 1.5 is 0.075 on every machine."""
    return round(v * s, 9)


def _scaled_pose(p: Pose | None, s: float) -> Pose | None:
    return None if p is None else Pose(_times(p.x, s), _times(p.y, s), p.yaw)


def _scaled_site(site: Site, s: float) -> Site:
    def poly(points: Any) -> tuple[tuple[float, float], ...]:
        return tuple((_times(x, s), _times(y, s)) for x, y in points)

    return Site(poly(site.dig_area), None if site.floor is None else _times(site.floor, s),
                tuple(poly(k) for k in site.keep_outs), site.open_outside)


def fit(scenario: Scenario, mc: MachineClass, target: float | None = None) -> Scenario:
    """``scenario`` (generated for the compact class) made one of class ``mc``: every length and
    height × ``mc.scale`` (the grid's cells too, so the heights keep their array), the class's
    specs for each machine present, and ``target`` (bank m³) as its task when given. Refuses a
    truck that cannot carry the target or machines that start closer than their clearance."""
    s = mc.scale
    sc = scenario
    if mc.name != DEFAULT_CLASS or s != 1.0:
        t = sc.terrain
        z = np.round(np.asarray(t.z) * s, 4) + 0.0  # rounded as generators round, so a digest is the same everywhere
        terrain = Heightmap((_times(t.origin[0], s), _times(t.origin[1], s)), _times(t.resolution, s), z)
        site = _scaled_site(sc.site, s)
        m = sc.machines
        machines = Machines(
            truck=mc.truck, truck_pose=Pose(_times(m.truck_pose.x, s), _times(m.truck_pose.y, s), m.truck_pose.yaw),
            excavator=None if m.excavator is None else mc.excavator, excavator_pose=_scaled_pose(m.excavator_pose, s),
            loader=None if m.loader is None else mc.loader, loader_pose=_scaled_pose(m.loader_pose, s),
            machine_class=mc.name,
        )
        sc = sc.replace(terrain=terrain, site=site, machines=machines)
    if target is not None:
        sc = sc.replace(task=dataclasses.replace(sc.task, target_volume=float(target)))
    _check_fit(sc)
    return sc


def _check_fit(sc: Scenario) -> None:
    m = sc.machines
    if m.truck.capacity < sc.task.target_volume:
        raise ScenarioError(f"the {m.machine_class} class's truck carries {m.truck.capacity:g} m³, less than the target "
                            f"{sc.task.target_volume:g} m³")
    for name in ("excavator", "loader"):
        spec, pose = getattr(m, name), getattr(m, f"{name}_pose")
        if spec is not None and pose is not None:
            d = float(np.hypot(pose.x - m.truck_pose.x, pose.y - m.truck_pose.y))
            if d < spec.clearance:
                raise ScenarioError(f"in the {m.machine_class} class the {name} and the truck start {d:.3f} m apart, "
                                    f"closer than the clearance {spec.clearance:g} m")
