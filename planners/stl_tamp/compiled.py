"""An NLP's functions as compiled C: built once per machine in the planner's preparation, loaded
by every case in milliseconds (docs/DESIGN.md §6 "Preparation", §11).

A fresh case otherwise loads its NLPs from :mod:`.nlp_cache` (CasADi's serialization, about a
second for the two NLPs of a plan) and IPOPT then evaluates the derivatives on CasADi's SX
virtual machine. Here each function of a built NLP (the NLP itself, its three derivatives and
the helpers) is written out by CasADi's code generator and compiled by the system's C compiler
into a shared library of its own, so the functions compile in parallel (one compiler per core
of the preparation's budget) and a case opens them with :func:`casadi.external`. The NLP
function itself is kept serialized instead: IPOPT's interface builds the gradient for
the parameters' multipliers from it, which needs a function CasADi can differentiate; it is
small (a few hundredths of a second to load) and evaluates only f and g.

The compiled code computes what the virtual machine computes, operation for operation: no
``-march``, no fast-math and ``-ffp-contract=off`` (no fused multiply-adds), so the values are
the same to the bit and so are the plans. The flags per function (:data:`FLAGS`): ``-O1`` where
it pays and compiles in seconds; the large Hessians at ``-O1`` too when their instruction count
is below :data:`O1_LIMIT`, else ``-O0`` (gcc's time and memory at ``-O1`` grow faster than the
code on a straight-line function of half a million operations: §11).
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

#: The functions of a :class:`~.model.PhaseNLP` that are compiled: all it evaluates but the NLP
#: function itself, which is loaded serialized (see the module's docstring).
NAMES = ("grad_f", "jac_g", "hess_lag", "tip", "rho", "vol", "pz", "bounds")
#: Flags every compilation shares: a shared object whose arithmetic is the virtual machine's.
BASE_FLAGS = ("-shared", "-fPIC", "-ffp-contract=off", "-fno-fast-math")
#: Instructions above which a function is compiled at -O0 (see the module's docstring).
O1_LIMIT = 250_000


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


def flags(fn: Any) -> tuple[str, ...]:
    """The optimisation level of one function (see :data:`O1_LIMIT`)."""
    level = "-O1" if fn.n_instructions() <= O1_LIMIT else "-O0"
    return (level, *BASE_FLAGS)


def _lib(folder: Path, name: str, fn_name: str) -> Path:
    return folder / f"{name}.{fn_name}.so"


def _oracle(folder: Path, name: str) -> Path:
    """The NLP function itself, serialized (not compiled): IPOPT's interface differentiates it
    once more (for the parameters' multipliers), which compiled code cannot be."""
    return folder / f"{name}.nlp.casadi"


def build(fns: dict[str, Any], folder: Path, name: str, *, jobs: int = 1,
          log: Callable[[str], None] | None = None) -> dict[str, float]:
    """Compile ``fns`` (the built functions of one NLP, keyed as :data:`NAMES`) into ``folder``
    under ``name``; returns each function's compile seconds. Raises RuntimeError naming the
    function when the compiler fails. A library already there is kept (same name, same code)."""
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler (set $CC or install gcc): stl-tamp's NLPs cannot be compiled")
    folder.mkdir(parents=True, exist_ok=True)
    if not _oracle(folder, name).exists():
        tmp_oracle = folder / f".{name}.nlp.tmp"
        fns["nlp"].save(str(tmp_oracle))
        os.replace(tmp_oracle, _oracle(folder, name))
    todo = [k for k in NAMES if k in fns and not _lib(folder, name, k).exists()]
    work = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=folder))
    try:
        sources = {}
        for k in todo:  # code generation is quick and holds the GIL: one after the other
            c_name = f"stl_tamp_{name}_{k}.c"  # a C identifier, whatever the key starts with
            cg = ca.CodeGenerator(c_name, {"with_header": False})
            cg.add(fns[k])
            cg.generate(str(work) + os.sep)
            sources[k] = work / c_name

        def one(k: str) -> tuple[str, float]:
            t0 = time.perf_counter()
            tmp = work / f"{k}.so"
            res = subprocess.run([cc, *flags(fns[k]), str(sources[k]), "-o", str(tmp), "-lm"],
                                 capture_output=True, text=True)
            if res.returncode != 0:
                raise RuntimeError(f"{cc} failed on {name}.{k}: {res.stderr.strip()[-500:]}")
            os.replace(tmp, _lib(folder, name, k))
            dt = time.perf_counter() - t0
            if log is not None:
                log(f"compiled {name}.{k} ({fns[k].n_instructions()} instructions) in {dt:.1f} s")
            return k, dt

        # the largest first, so the last to finish is a small one
        order = sorted(todo, key=lambda k: -fns[k].n_instructions())
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            return dict(pool.map(one, order))
    finally:
        shutil.rmtree(work, ignore_errors=True)


def load(folder: Path | None, name: str, expect: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The compiled functions of ``name`` in ``folder``, or None unless every one is there.
    ``expect`` (optional): functions whose input and output sparsity the compiled ones must have."""
    if folder is None:
        return None
    paths = {k: _lib(folder, name, k) for k in NAMES}
    if not all(p.is_file() for p in paths.values()) or not _oracle(folder, name).is_file():
        return None
    out = {}
    try:
        for k, p in paths.items():
            out[k] = ca.external(_fn_name(k), str(p))
        out["nlp"] = ca.Function.load(str(_oracle(folder, name)))
    except RuntimeError:
        return None
    if expect is not None:
        for k, f in expect.items():
            g = out.get(k)
            if g is not None and not _same_signature(f, g):
                return None
    return out


def _fn_name(key: str) -> str:
    """The CasADi name of each function (as :meth:`~.model.PhaseNLP._build` names them)."""
    return {"hess_lag": "nlp_hess_l", "jac_g": "nlp_jac_g", "grad_f": "nlp_grad_f"}.get(key, key)


def _same_signature(f: Any, g: Any) -> bool:
    return f.n_in() == g.n_in() and f.n_out() == g.n_out() \
        and all(f.sparsity_in(i) == g.sparsity_in(i) for i in range(f.n_in())) \
        and all(f.sparsity_out(i) == g.sparsity_out(i) for i in range(f.n_out()))


def digest(folder: Path) -> str:
    """sha256 over the names and bytes of every file under ``folder`` (sorted)."""
    h = hashlib.sha256()
    for p in sorted(q for q in folder.rglob("*") if q.is_file()):
        h.update(str(p.relative_to(folder)).encode() + b"\0" + p.read_bytes())
    return h.hexdigest()
