"""stl-tamp's preparation: its NLPs compiled to C, once per machine (docs/DESIGN.md §6 "Preparation")."""

from __future__ import annotations

import itertools
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .planner import StlTampPlanner


def compile_nlps(planner: StlTampPlanner, folder: Path, jobs: int = 1) -> dict[str, Any]:
    """Compile the NLPs of ``planner.prepared_shapes()`` into ``folder`` (:mod:`.compiled`), the
    compilers ``jobs`` at a time; returns what was compiled and how long it took (per NLP, and per
    machine class in ``classes``: the wall seconds of its NLPs)."""
    from . import compiled
    from .model import build_functions

    out: dict[str, Any] = {"compiler": compiled.compiler_version(), "nlps": {}, "classes": {}}
    if compiled.compiler() is None:  # nothing to compile with: cases load their NLPs as before
        out["note"] = "no C compiler: the NLPs stay uncompiled (the same plans, solved more slowly)"
        return out
    # with FATROP, each NLP twice: stage by stage for FATROP, classic for IPOPT's fallback
    layouts = (False, True) if planner.config.solver == "fatrop" else (False,)
    builds = list(itertools.product(planner.prepared_shapes(), layouts))
    for i, ((label, shape, exc, truck), staged_layout) in enumerate(builds):
        label += " staged" if staged_layout else ""
        planner.report_progress(i, len(builds), f"NLP {label}: building and compiling")
        t0 = time.perf_counter()
        name, fns = build_functions(shape, exc, truck, staged_layout)
        t_build = time.perf_counter() - t0
        took = compiled.build(fns, folder, name, jobs=jobs, log=lambda m: print(m, flush=True), staged=staged_layout)
        out["nlps"][label] = {"key": name, "build_s": round(t_build, 2), "compile_s": {k: round(v, 2) for k, v in took.items()}}
        machine_class = label.split()[0]
        out["classes"][machine_class] = round(out["classes"].get(machine_class, 0.0) + time.perf_counter() - t0, 1)
        print(f"{label}: built in {t_build:.1f} s, compiled in {sum(took.values()):.1f} s of compiler time", flush=True)
    planner.report_progress(len(builds), len(builds), "done")
    return out
