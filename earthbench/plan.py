"""The plan format: time-stamped actions per machine (``"schema": "earthbench.plan/1"``).

A plan is what a planner returns and the only thing the referee judges. Reading a plan
document checks its *form* (known actions, fields present, finite numbers, times that run
forward) and raises :class:`PlanFormatError` naming the action and the field; whether the
plan is *physically* possible is the referee's business, not the parser's.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from .errors import PlanFormatError, read_document

PLAN_SCHEMA = "earthbench.plan/1"


@dataclass(frozen=True)
class Move:
    """A path of samples ``(t, x, y, yaw)`` for one machine, straight or on an arc between them."""

    machine: str
    path: tuple[tuple[float, float, float, float], ...]
    kind: ClassVar[str] = "move"

    @property
    def t_start(self) -> float:
        return self.path[0][0]

    @property
    def t_end(self) -> float:
        return self.path[-1][0]


@dataclass(frozen=True)
class Dig:
    """A backhoe stroke: bucket enters at ``contact``, drags ``drag_length`` along ``heading``.

    The cut is flat at ``z(contact) − depth``; ``heading`` is the drag direction (radians,
    counter-clockwise from +x), usually pointing from the contact toward the machine.
    """

    machine: str
    t_start: float
    t_end: float
    contact: tuple[float, float]
    heading: float
    depth: float
    drag_length: float
    kind: ClassVar[str] = "dig"


@dataclass(frozen=True)
class Dump:
    """Empty the bucket of ``machine`` into the truck."""

    machine: str
    t_start: float
    t_end: float
    kind: ClassVar[str] = "dump"


@dataclass(frozen=True)
class Charge:
    """A wheel-loader charge: from ``entry`` = ``(x, y, yaw)`` (the loader's pose when it starts),
    drive ``penetration`` metres along ``yaw`` into the pile with the bucket flat on the floor.

    The loader ends the charge at ``entry + penetration · (cos yaw, sin yaw)``, same yaw.
    """

    machine: str
    t_start: float
    t_end: float
    entry: tuple[float, float, float]
    penetration: float
    kind: ClassVar[str] = "charge"

    @property
    def end(self) -> tuple[float, float, float]:
        x, y, yaw = self.entry
        return (x + self.penetration * math.cos(yaw), y + self.penetration * math.sin(yaw), yaw)


Action = Move | Dig | Dump | Charge
ACTION_TYPES: dict[str, type] = {c.kind: c for c in (Move, Dig, Dump, Charge)}


@dataclass(frozen=True)
class Prediction:
    """The planner's own claims, kept only to report its model error; never used to score."""

    volume: float | None = None
    makespan: float | None = None


@dataclass(frozen=True)
class Plan:
    """An ordered tuple of actions plus the planner's predictions and free-form ``info``."""

    actions: tuple[Action, ...] = ()
    predicted: Prediction = Prediction()
    info: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @property
    def makespan(self) -> float:
        return max((a.t_end for a in self.actions), default=0.0)

    # -- JSON ---------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        acts = []
        for a in self.actions:
            d: dict[str, Any] = {"type": a.kind, "machine": a.machine}
            if isinstance(a, Move):
                d["path"] = [list(s) for s in a.path]
            else:
                d["t_start"], d["t_end"] = a.t_start, a.t_end
                if isinstance(a, Dig):
                    d.update(contact=list(a.contact), heading=a.heading, depth=a.depth, drag_length=a.drag_length)
                elif isinstance(a, Charge):
                    d.update(entry=list(a.entry), penetration=a.penetration)
            acts.append(d)
        pred = {k: v for k, v in (("volume", self.predicted.volume), ("makespan", self.predicted.makespan)) if v is not None}
        return {"schema": PLAN_SCHEMA, "actions": acts, "predicted": pred, "info": self.info}

    def to_json(self, path: str | Path | None = None) -> str:
        text = json.dumps(self.to_dict(), indent=1, default=_json_default)
        if path is not None:
            Path(path).write_text(text)
        return text

    @classmethod
    def from_dict(cls, doc: Any) -> Plan:
        if not isinstance(doc, dict):
            raise PlanFormatError(f"a plan must be a JSON object, got {type(doc).__name__}")
        schema = doc.get("schema")
        if schema != PLAN_SCHEMA:
            raise PlanFormatError(f"plan schema must be {PLAN_SCHEMA!r}, got {schema!r}")
        raw = doc.get("actions")
        if not isinstance(raw, list):
            raise PlanFormatError("plan field 'actions' must be a list of actions")
        actions = tuple(_parse_action(n, a) for n, a in enumerate(raw))
        pred_doc = doc.get("predicted") or {}
        if not isinstance(pred_doc, dict):
            raise PlanFormatError("plan field 'predicted' must be an object with 'volume' and/or 'makespan'")
        pred = Prediction(
            volume=_opt_number(pred_doc, "volume", "predicted"),
            makespan=_opt_number(pred_doc, "makespan", "predicted"),
        )
        info = doc.get("info") or {}
        if not isinstance(info, dict):
            raise PlanFormatError("plan field 'info' must be an object")
        return cls(actions, pred, info)

    @classmethod
    def from_json(cls, source: str | Path) -> Plan:
        """A plan from JSON text (a ``str``) or from a file (a :class:`~pathlib.Path`).

        A ``str`` is only ever text: a plan whose text happens to be a file name is judged as
        that text, never as the file it names.
        """
        if isinstance(source, Path):
            source = read_document(source, "plan", PlanFormatError)
        try:
            return cls.from_dict(json.loads(source))
        except json.JSONDecodeError as exc:
            raise PlanFormatError(f"plan is not valid JSON: {exc}") from None
        except RecursionError:
            raise PlanFormatError("plan JSON is nested too deeply") from None
        except PlanFormatError:
            raise
        except ValueError as exc:  # e.g. an integer too long to convert
            raise PlanFormatError(f"plan is not valid JSON: {exc}") from None


def _json_default(o: Any) -> Any:
    if hasattr(o, "item"):
        return o.item()
    if hasattr(o, "tolist"):
        return o.tolist()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def _where(n: int, kind: str) -> str:
    return f"action {n} ({kind})"


def _number(d: dict, key: str, where: str, *, positive: bool = False, nonneg: bool = False) -> float:
    if key not in d:
        raise PlanFormatError(f"{where}: missing field {key!r}")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise PlanFormatError(f"{where}: field {key!r} must be a number, got {v!r}")
    try:
        v = float(v)
    except OverflowError:  # an integer beyond the largest float (a 401-digit time)
        raise PlanFormatError(f"{where}: field {key!r} must be finite, got an integer of {len(str(abs(v)))} digits") from None
    if not math.isfinite(v):
        raise PlanFormatError(f"{where}: field {key!r} must be finite, got {v}")
    if positive and v <= 0:
        raise PlanFormatError(f"{where}: field {key!r} must be positive, got {v}")
    if nonneg and v < 0:
        raise PlanFormatError(f"{where}: field {key!r} must not be negative, got {v}")
    return v


def _opt_number(d: dict, key: str, where: str) -> float | None:
    return None if d.get(key) is None else _number(d, key, where)


def _vector(d: dict, key: str, where: str, n: int) -> tuple[float, ...]:
    v = d.get(key)
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise PlanFormatError(f"{where}: field {key!r} must be a list of {n} numbers, got {v!r}")
    return tuple(_number({key: c}, key, where) for c in v)


def _interval(d: dict, where: str) -> tuple[float, float]:
    t0 = _number(d, "t_start", where, nonneg=True)
    t1 = _number(d, "t_end", where, nonneg=True)
    if t1 < t0:
        raise PlanFormatError(f"{where}: t_end {t1} is before t_start {t0}")
    return t0, t1


def _parse_action(n: int, d: Any) -> Action:
    if not isinstance(d, dict):
        raise PlanFormatError(f"action {n}: must be an object, got {type(d).__name__}")
    kind = d.get("type")
    if kind not in ACTION_TYPES:
        raise PlanFormatError(f"action {n}: unknown type {kind!r}; known types: {', '.join(ACTION_TYPES)}")
    where = _where(n, kind)
    machine = d.get("machine")
    if not isinstance(machine, str) or not machine:
        raise PlanFormatError(f"{where}: field 'machine' must be a machine id such as 'excavator', got {machine!r}")
    if kind == "move":
        raw = d.get("path")
        if not isinstance(raw, list) or len(raw) < 2:
            raise PlanFormatError(f"{where}: field 'path' must be a list of at least 2 [t, x, y, yaw] samples")
        path = tuple(_vector({"path": s}, "path", f"{where} sample {k}", 4) for k, s in enumerate(raw))
        for k, (s0, s1) in enumerate(zip(path, path[1:])):
            if s0[0] < 0:
                raise PlanFormatError(f"{where} sample {k}: time must not be negative, got {s0[0]}")
            if s1[0] <= s0[0]:
                raise PlanFormatError(f"{where} sample {k + 1}: times must increase, got {s0[0]} then {s1[0]}")
        return Move(machine, path)  # type: ignore[arg-type]
    t0, t1 = _interval(d, where)
    if kind == "dig":
        return Dig(
            machine,
            t0,
            t1,
            _vector(d, "contact", where, 2),  # type: ignore[arg-type]
            _number(d, "heading", where),
            _number(d, "depth", where, positive=True),
            _number(d, "drag_length", where, positive=True),
        )
    if kind == "charge":
        return Charge(
            machine,
            t0,
            t1,
            _vector(d, "entry", where, 3),  # type: ignore[arg-type]
            _number(d, "penetration", where, positive=True),
        )
    return Dump(machine, t0, t1)
