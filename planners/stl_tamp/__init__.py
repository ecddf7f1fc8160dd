"""Hierarchical STL-TAMP planner (Satoh, Takano, Oyama): registered as ``stl-tamp``.

- :mod:`.model` — the system model and the parametric NLP (one per process and shape),
- :mod:`.guess` — IK-based initial guesses (and the bounded fallback),
- :mod:`.hierarchy` — Algorithm 1's areas, the global layer's seeds and the NLP cache,
- :mod:`.convert` — from solution to referee-valid actions,
- :mod:`.planner` — :class:`StlTampPlanner` and its :class:`Config`.
"""

from .convert import ConversionError
from .hierarchy import StlTampSolveError
from .model import PhaseNLP, Shape, Solution
from .planner import Config, StlTampPlanner, TargetTooLargeError

__all__ = ["Config", "ConversionError", "PhaseNLP", "Shape", "Solution", "StlTampPlanner", "StlTampSolveError",
           "TargetTooLargeError"]
