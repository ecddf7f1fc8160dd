"""Hierarchical STL-TAMP planner (Satoh, Takano, Oyama): registered as ``stl-tamp``.

- :mod:`.problem` — the NLP's shape, solution and state layout (no CasADi),
- :mod:`.model` — the system model and the parametric NLP (one per process and shape; CasADi),
- :mod:`.guess` — IK-based initial guesses (and the bounded fallback),
- :mod:`.hierarchy` — Algorithm 1's areas, the global layer's seeds and the NLP cache,
- :mod:`.convert` — from solution to referee-valid actions,
- :mod:`.planner` — :class:`StlTampPlanner` and its :class:`Config`.

Importing the package loads no CasADi: ``PhaseNLP`` is looked up on first use
(docs/DESIGN.md §10), the first solve pays that import.
"""

from typing import Any

from .convert import ConversionError
from .hierarchy import StlTampSolveError
from .planner import Config, StlTampPlanner, TargetTooLargeError
from .problem import Shape, Solution

__all__ = ["Config", "ConversionError", "PhaseNLP", "Shape", "Solution", "StlTampPlanner", "StlTampSolveError",
           "TargetTooLargeError"]


def __getattr__(name: str) -> Any:
    if name != "PhaseNLP":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from .model import PhaseNLP

    return PhaseNLP
