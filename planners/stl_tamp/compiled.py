"""An NLP's functions as compiled C: built once per machine in the planner's preparation, loaded
by every case in milliseconds (docs/DESIGN.md §6 "Preparation", §11).

A fresh case otherwise loads its NLPs from :mod:`.nlp_cache` (CasADi's serialization, about a
second for the two NLPs of a plan) and IPOPT then evaluates every function on CasADi's SX
virtual machine. Here every function IPOPT's interface evaluates (f, g, their derivatives, the
Hessian of the Lagrangian, and the gradient it forms for the multipliers at the end of a solve)
and the planner's helpers are written out by CasADi's code generator, one C file each, compiled
by the system's C compiler in parallel (one compiler per core of the preparation's budget) and
linked into one shared library per NLP. A case opens it with :func:`casadi.external`: the
oracle ``nlp`` loaded from the library makes ``nlpsol`` find the other functions there by
their names, so nothing is differentiated or deserialized in the case.

The compiled code computes what the virtual machine computes, operation for operation: no
``-march``, no fast-math and ``-ffp-contract=off`` (no fused multiply-adds), so the values are
the same to the bit and so are the plans. The flags per function: ``-O1`` when its instruction
count is below :data:`O1_LIMIT`, else ``-O0`` (gcc's time and memory at ``-O1`` grow faster than
the code on a straight-line function of half a million operations: the global Hessian took 25 s
and 2.6 GB at ``-O0``, 212 s and 3.4 GB at ``-O1``), and ``-O0`` for the function evaluated
once per solve (:data:`ONCE`).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import casadi as ca

#: What IPOPT's interface evaluates (CasADi's names for the functions an ``nlpsol`` derives from
#: its oracle, the oracle ``nlp`` itself first) and the helpers a :class:`~.model.PhaseNLP` calls.
SOLVER_NAMES = ("nlp", "nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l", "nlp_grad")
HELPER_NAMES = ("tip", "rho", "vol", "pz", "bounds")
NAMES = SOLVER_NAMES + HELPER_NAMES
#: Flags every compilation shares: position-independent code whose arithmetic is the virtual
#: machine's (no fused multiply-adds, no fast-math, no -march).
BASE_FLAGS = ("-fPIC", "-ffp-contract=off", "-fno-fast-math")
#: Instructions above which a function is compiled at -O0 (see the module's docstring).
O1_LIMIT = 250_000
#: Evaluated once per solve (the multipliers of the parameters) or never (the oracle, which
#: only tells ``nlpsol`` where the others are): not worth -O1's compile time.
ONCE = ("nlp_grad", "nlp")
#: This module's code, part of a library's name: other flags or layout, another library.
_SOURCE = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:8]


def compiler() -> str | None:
    """The C compiler: ``$CC``, else ``cc``/``gcc`` on the path; None when there is none."""
    for cand in (os.environ.get("CC"), "cc", "gcc"):
        if cand and shutil.which(cand):
            return shutil.which(cand)
    return None


def compiler_version(cc: str | None = None) -> str:
    """The first line of ``cc --version`` (part of the preparation's key: another compiler,
    another folder)."""
    cc = cc or compiler()
    if cc is None:
        return "none"
    try:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (out.stdout.splitlines() or ["unknown"])[0]


def flags(key: str, fn: Any) -> tuple[str, ...]:
    """The optimisation level of one function (see :data:`O1_LIMIT` and :data:`ONCE`)."""
    level = "-O1" if fn.n_instructions() <= O1_LIMIT and key not in ONCE else "-O0"
    return (level, *BASE_FLAGS)


def library(folder: Path, name: str) -> Path:
    """The one shared library of an NLP: every function of :data:`NAMES`."""
    return folder / f"{name}.{_SOURCE}.so"


def solver_functions(fns: dict[str, Any]) -> dict[str, Any]:
    """The oracle and the functions an IPOPT ``nlpsol`` of ``fns`` evaluates, by CasADi's names:
    the NLP's own derivatives (``hess_lag``, ``jac_g``, ``grad_f``) under the names the solver
    gives them, and those it derives (f, g, and the gradient for the multipliers)."""
    derivs = {k: fns[k] for k in ("hess_lag", "jac_g", "grad_f") if k in fns}
    S = ca.nlpsol("stl_tamp", "ipopt", fns["nlp"], {"ipopt": {"print_level": 0, "sb": "yes"}, "print_time": False, **derivs})
    out = {"nlp": fns["nlp"]}
    for k in SOLVER_NAMES[1:]:
        out[k] = S.get_function(k)
    return out


def build(fns: dict[str, Any], folder: Path, name: str, *, jobs: int = 1,
          log: Callable[[str], None] | None = None) -> dict[str, float]:
    """Compile the functions of one built NLP (``fns``, as :meth:`~.model.PhaseNLP._build` keys
    them) into ``folder`` as one library named ``name``: each function is its own C file, the
    files compile ``jobs`` at a time, then one link. Returns each function's compile seconds.
    Raises RuntimeError naming the function when the compiler fails. A library already there
    is kept (same name, same code)."""
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler (set $CC or install gcc): stl-tamp's NLPs cannot be compiled")
    folder.mkdir(parents=True, exist_ok=True)
    if library(folder, name).exists():
        return {}
    todo = {**solver_functions(fns), **{k: fns[k] for k in HELPER_NAMES}}
    work = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=folder))
    try:
        sources = {}
        for k, fn in todo.items():  # code generation is quick and holds the GIL: one after the other
            c_name = f"stl_tamp_{name}_{k}.c"  # a C identifier, whatever the key starts with
            cg = ca.CodeGenerator(c_name, {"with_header": False})
            cg.add(fn)
            cg.generate(str(work) + os.sep)
            sources[k] = work / c_name

        def one(k: str) -> tuple[str, float]:
            t0 = time.perf_counter()
            res = subprocess.run([cc, "-c", *flags(k, todo[k]), str(sources[k]), "-o", str(work / f"{k}.o")],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                raise RuntimeError(f"{cc} failed on {name}.{k}: {res.stderr.strip()[-500:]}")
            dt = time.perf_counter() - t0
            if log is not None:
                log(f"compiled {name}.{k} ({todo[k].n_instructions()} instructions) in {dt:.1f} s")
            return k, dt

        order = sorted(todo, key=lambda k: -todo[k].n_instructions())  # the largest first
        # a function above O1_LIMIT (a global Hessian: 2.6 GB in gcc at -O0) compiles alone, the
        # rest jobs at a time: two at once held 3.5 GB in the preparation's cgroup
        alone = [k for k in order if todo[k].n_instructions() > O1_LIMIT]
        took = dict(one(k) for k in alone)
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            took.update(pool.map(one, [k for k in order if k not in alone]))
        tmp = work / "lib.so"
        res = subprocess.run([cc, "-shared", *[str(work / f"{k}.o") for k in order], "-o", str(tmp), "-lm"],
                             capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"{cc} failed to link {name}: {res.stderr.strip()[-500:]}")
        os.replace(tmp, library(folder, name))
        return took
    finally:
        shutil.rmtree(work, ignore_errors=True)


def load(folder: Path | None, name: str) -> dict[str, Any] | None:
    """The compiled functions of ``name`` in ``folder`` (``nlp`` is the oracle an ``nlpsol``
    finds the others in), or None when the library is not there or lacks one."""
    if folder is None or not library(folder, name).is_file():
        return None
    try:
        return {k: ca.external(k, str(library(folder, name))) for k in ("nlp", *HELPER_NAMES)}
    except RuntimeError:
        return None
