"""The planner interface every plugin implements.

A planner is a class with a name, a version, the tracks it supports and a frozen ``Config``
dataclass; ``plan(scenario)`` returns a :class:`~earthbench.plan.Plan`. The harness, not the
planner, times the call, and the referee, not the planner, decides what the plan achieved.
"""

from __future__ import annotations

import dataclasses
import hashlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

from .errors import PluginError
from .plan import Plan
from .world import Scenario, canonical_json


@dataclass(frozen=True)
class NoConfig:
    """The configuration of a planner that has no settings."""


class Planner(ABC):
    """Base class of planners. Subclass, set the class attributes, implement :meth:`plan`."""

    name: ClassVar[str] = ""
    version: ClassVar[str] = "0"
    tracks: ClassVar[tuple[str, ...]] = ("backhoe",)
    Config: ClassVar[type] = NoConfig

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

    @abstractmethod
    def plan(self, scenario: Scenario) -> Plan:
        """Return a plan for ``scenario``. May raise; the harness records it as an error."""

    def supports(self, scenario: Scenario) -> bool:
        return scenario.track in self.tracks

    @property
    def config_dict(self) -> dict[str, Any]:
        config = self.config
        return dataclasses.asdict(config) if dataclasses.is_dataclass(config) and not isinstance(config, type) else dict(config)

    @property
    def config_hash(self) -> str:
        """First 16 hex digits of sha256 over the canonical JSON of the configuration."""
        return hashlib.sha256(canonical_json(self.config_dict).encode()).hexdigest()[:16]

    def __repr__(self) -> str:
        return f"<planner {self.name} {self.version} config={self.config_hash}>"
