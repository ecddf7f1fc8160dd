"""The planner interface every plugin implements.

A planner is a class with a name, a version, the tracks it supports and a frozen ``Config``
dataclass; ``plan(scenario)`` returns a :class:`~earthbench.plan.Plan`. The harness, not the
planner, times the call, and the referee, not the planner, decides what the plan achieved.

A planner may also run *closed loop* (docs/DESIGN.md §6): when its configuration says
``closed_loop = True``, the harness calls :meth:`Planner.step` with an :class:`Observation`
of the world after the actions executed so far and executes the actions it returns on the
truth before it calls again, until the planner returns None ("done") or the step cap ends
the run. Open and closed loop are two configurations with their own hashes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from .errors import PluginError
from .plan import Plan
from .world import LATER, Heightmap, Pose, Scenario, canonical_json


def closed_loop_setting() -> Any:
    """The ``closed_loop`` field of a planner's ``Config`` (default False).

    Left out of the configuration (and so of its hash) while False, so a planner that gains
    a closed-loop mode keeps the hash, and the stored runs, of its open-loop configuration.
    """
    return dataclasses.field(default=False, metadata=LATER)


@dataclass(frozen=True)
class Observation:
    """What a closed-loop planner is told before each step; everything comes from the harness.

    ``scenario`` is the planner's view of the world now: the terrain as observed after the
    executed actions, the machines at their current poses, the task's full target. ``t`` is
    the plan time the executed actions end at, plus the scan after them on a scanned site
    (:func:`earthbench.sensing.scan_seconds`); the next actions may not start earlier;
    ``loaded`` the volume the truck reports holding (m³), ``turn`` the excavator's upper body
    relative to its base yaw (rad; what the next swing starts from), ``bucket`` the volume
    still in the bucket (m³; more than 0 after a dump into a full truck), ``step`` 0 on the
    first call.
    """

    scenario: Scenario
    step: int = 0
    t: float = 0.0
    loaded: float = 0.0
    turn: float = 0.0
    bucket: float = 0.0

    @property
    def remaining(self) -> float:
        """m³ still to load for the task's target."""
        return max(self.scenario.task.target_volume - self.loaded, 0.0)

    @property
    def truck_full(self) -> bool:
        """The last dump left material in the bucket: the truck takes no more."""
        return self.bucket > 1e-9

    def to_dict(self, *, compact: bool = False) -> dict[str, Any]:
        """The harness's message. ``compact``: only what changes from step to step (the terrain
        and the poses), to be read against the scenario of the first observation."""
        d: dict[str, Any] = {"step": self.step, "t": self.t, "loaded": self.loaded, "turn": self.turn, "bucket": self.bucket}
        if compact:
            m = self.scenario.machines
            d["terrain"] = self.scenario.terrain.to_dict()
            d["poses"] = {mid: dataclasses.asdict(m.pose(mid)) for mid in m.ids}
        else:
            d["scenario"] = self.scenario.to_dict()
        return d

    @classmethod
    def from_dict(cls, doc: dict[str, Any], first: Scenario | None = None) -> Observation:
        """Read the harness's message: a bare scenario document is the first observation, a
        compact one is read against ``first`` (that observation's scenario)."""
        if "step" not in doc:
            return cls(Scenario.from_dict(doc))
        if "scenario" in doc:
            sc = Scenario.from_dict(doc["scenario"])
        elif first is not None:
            poses: dict[str, Any] = {f"{mid}_pose": Pose(**p) for mid, p in doc["poses"].items()}
            sc = dataclasses.replace(
                first, terrain=Heightmap.from_dict(doc["terrain"]), machines=dataclasses.replace(first.machines, **poses)
            )
        else:
            raise ValueError("a compact observation needs the first observation's scenario")
        return cls(sc, int(doc["step"]), float(doc["t"]), float(doc["loaded"]), float(doc["turn"]), float(doc.get("bucket", 0.0)))


@dataclass(frozen=True)
class SharedFolder:
    """A folder outside its own files that a planner's cases read, read only: e.g. a cache its
    runs fill outside the sandbox (docs/plugins.md "Folders a planner reads").

    ``env`` is the variable that says where the folder is (``EARTHBENCH_`` and capitals);
    ``default`` where it is when the variable is unset: ``earthbench/NAME`` (or deeper) under the
    user's cache folder (``$XDG_CACHE_HOME``, else ``~/.cache``). The harness resolves both on the machine
    that runs the case (the case has no ``HOME`` of the user's), gives the case the variable
    (the folder's absolute path, or ``off`` when the user set it so) and shows it the folder
    read only, if it exists. A sandboxed case sees nothing else outside its own files.
    """

    env: str
    default: str


@dataclass(frozen=True)
class PrepareProgress:
    """How far a preparation is (:meth:`Planner.report_progress`): ``done`` of ``total`` steps,
    working on ``what`` (one short line, e.g. the NLP being compiled)."""

    done: int
    total: int
    what: str = ""


@dataclass(frozen=True)
class NoConfig:
    """The configuration of a planner that has no settings."""


class Planner(ABC):
    """Base class of planners. Subclass, set the class attributes, implement :meth:`plan`."""

    name: ClassVar[str] = ""
    version: ClassVar[str] = "0"
    tracks: ClassVar[tuple[str, ...]] = ("backhoe",)
    Config: ClassVar[type] = NoConfig
    #: The folders outside its own files its cases read (see :class:`SharedFolder`); declared
    #: like the preparation, so the harness, which knows no planner by name, can show them.
    reads: ClassVar[tuple[SharedFolder, ...]] = ()

    def __init__(self, config: Any = None, **overrides: Any):
        if config is None:
            try:
                config = self.Config(**overrides)
            except TypeError as exc:
                fields = ", ".join(f.name for f in dataclasses.fields(self.Config)) or "(none)"
                raise PluginError(f"bad configuration for planner {self.name!r}: {exc}. Its settings: {fields}") from None
        elif overrides:
            config = dataclasses.replace(config, **overrides)
        self.config = config

    #: The folder this configuration's preparation wrote (read only; docs/DESIGN.md §6
    #: "Preparation"), set by the harness before the first :meth:`plan` or :meth:`step` call;
    #: None when the planner declares no preparation or runs without one (e.g. in a script).
    prepared: Path | None = None

    def prepare(self, folder: Path, jobs: int = 1) -> dict[str, Any] | None:
        """Optional, scenario-blind preparation: write into ``folder`` whatever later cases of
        this planner, version and configuration may load on this machine (e.g. compiled code).

        A planner declares a preparation by overriding this method. The harness runs it once
        per planner, version, configuration, earthbench version and machine, before that
        planner's first case, in a fenced process with its own budget (``[budget] prepare_s``,
        ``prepare_memory_mb``), with no scenario and no store; ``jobs`` is the number of cores
        it may keep busy. Returns a small JSON-able summary (kept with the folder) or None.
        Its time is reported beside the solve times, never inside them. It may say how far it
        is with :meth:`report_progress`.
        """
        return None

    #: Where :meth:`report_progress` goes: set by the harness on the instance whose
    #: :meth:`prepare` it calls; None (nowhere) otherwise.
    progress_sink: Callable[[PrepareProgress], None] | None = None

    def report_progress(self, done: int, total: int, what: str = "") -> None:
        """From :meth:`prepare`, optionally: ``done`` of ``total`` steps are finished and ``what``
        (one short line) is under way, e.g. ``report_progress(3, 12, "NLP dig 2x3")``. The
        harness shows it with an estimate of the time left (docs/running.md "Preparation"); it is
        never stored, may be called as often as convenient (the harness keeps up to ten a
        second) and does nothing outside a preparation."""
        if self.progress_sink is not None:
            self.progress_sink(PrepareProgress(int(done), int(total), str(what)))

    @classmethod
    def prepares(cls) -> bool:
        """Whether this planner declares a preparation (overrides :meth:`prepare`)."""
        return getattr(cls.prepare, "__func__", cls.prepare) is not Planner.prepare

    @abstractmethod
    def plan(self, scenario: Scenario) -> Plan:
        """Return a plan for ``scenario``. May raise; the harness records it as an error."""

    def step(self, observation: Observation) -> Plan | None:
        """Closed loop: the next actions (a non-empty plan starting no earlier than
        ``observation.t``, e.g. up to the next dump), or None when the planner is done.

        Called only when :attr:`closed_loop`; the harness times each call and executes the
        actions on the truth before the next one. May raise; the harness records it as an error.
        """
        raise NotImplementedError(f"planner {self.name!r} has no closed-loop mode (no step method)")

    @property
    def closed_loop(self) -> bool:
        """Whether the harness runs this configuration step by step (its ``closed_loop`` setting)."""
        return bool(getattr(self.config, "closed_loop", False))

    def supports(self, scenario: Scenario) -> bool:
        return scenario.track in self.tracks

    @property
    def config_dict(self) -> dict[str, Any]:
        """The configuration as JSON data (fields marked ``LATER`` left out at their defaults)."""
        config = self.config
        if dataclasses.is_dataclass(config) and not isinstance(config, type):
            return json.loads(canonical_json(config))
        return dict(config)

    @property
    def config_hash(self) -> str:
        """First 16 hex digits of sha256 over the canonical JSON of the configuration."""
        return hashlib.sha256(canonical_json(self.config_dict).encode()).hexdigest()[:16]

    def __repr__(self) -> str:
        return f"<planner {self.name} {self.version} config={self.config_hash}>"
