"""What every figure of the leaderboard shares: matplotlib loaded on first use with the Agg
backend (publishing needs no display, and importing the core stays light), one colour per
planner, and text that matplotlib draws literally."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def planner_colours(solvers: Iterable[str]) -> dict[str, Any]:
    """A stable colour per planner label (sorted, tab10)."""
    cmap = pyplot().get_cmap("tab10")
    return {s: cmap(i % 10) for i, s in enumerate(sorted(solvers))}


def mpl_text(text: Any) -> str:
    """Text matplotlib draws literally (``$`` would start mathtext)."""
    return str(text).replace("$", r"\$")
