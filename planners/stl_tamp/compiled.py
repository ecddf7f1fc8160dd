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
the same to the bit and so are the plans. A function of more than :data:`SPLIT_ABOVE`
instructions is split (:func:`split`) into pieces of :data:`PART_STATEMENTS` statements over a
work array, in C files compiled at ``-O1`` one by one (0.10.1): gcc's time and memory grow faster
than the code on one straight-line function of half a million operations (the 8-phase global
Hessian took 25 s and 2.6 GB at ``-O0``, 212 s and 3.4 GB at ``-O1``, so 0.10.0 compiled it at
``-O0``, where it evaluated 2.5× slower than split at ``-O1`` and took 13 % of a plan's CPU). The
rest: ``-O1``, or ``-O0`` for a function evaluated at most a few times per solve (:data:`ONCE`)
and, whole, for one above :data:`O1_LIMIT` that could not be split.
"""

from __future__ import annotations

import hashlib
import os
import re
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
#: Instructions above which a function that could not be split is compiled at -O0 (see the
#: module's docstring).
O1_LIMIT = 250_000
#: Evaluated once per solve (the multipliers of the parameters), a few times per area (the
#: helpers, for guesses and checks) or never (the oracle, which only tells ``nlpsol`` where the
#: others are): not worth -O1's compile time.
ONCE = ("nlp_grad", "nlp", *HELPER_NAMES, "lift", "layout")
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


#: A function of more than this many instructions is split (:func:`split`): its statements become
#: functions of :data:`PART_STATEMENTS` over a work array, C files of at most
#: :data:`PART_FILE_STATEMENTS` of them, each compiled at ``-O1`` on its own (about 0.2 GB in gcc).
SPLIT_ABOVE = 20_000
PART_STATEMENTS = 2_000
PART_FILE_STATEMENTS = 30_000
_F0 = "static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem) {\n"
_END = "  return 0;\n}\n"
_LOCAL = re.compile(r"\ba(\d+)\b")


def split(source: str, prefix: str, statements: int = PART_STATEMENTS,
          per_file: int = PART_FILE_STATEMENTS) -> list[str] | None:
    """CasADi's C for one SX function (one straight-line ``casadi_f0`` over scalar locals
    ``a0…``) as several C files: the first is the original with ``f0``'s body replaced by calls, in
    order, to functions of at most ``statements`` of its statements each, the rest hold those
    functions, about ``per_file`` statements a file; the locals become a work array that the
    function's ``_work`` asks its caller for. The statements are the same, in the same order, so
    the values are the same to the bit; a compiler handles the pieces in a fraction of the time and
    memory a single function of half a million statements takes it (and can optimise them). None
    when ``source`` is not of that form (then it is compiled whole)."""
    head, found, rest = source.partition(_F0)
    body, end, tail = rest.partition(_END)
    if not found or not end or "casadi_f1" in source:
        return None
    lines = body.splitlines()
    decls = [ln for ln in lines if ln.startswith("  casadi_real ")]
    stmts = [ln for ln in lines if not ln.startswith("  casadi_real ")]
    names = [nm.strip() for ln in decls for nm in ln[len("  casadi_real "):].rstrip(";").split(",")]
    if not stmts or any(not (ln.startswith("  a") or ln.startswith("  if (res[")) for ln in stmts) \
            or any(not re.fullmatch(r"a\d+", nm) for nm in names):
        return None
    n_w = max(int(nm[1:]) for nm in names) + 1 if names else 0
    work = ("  if (sz_w) *sz_w = 0;\n", "  if (sz_w) *sz_w = 0*sizeof(casadi_real);\n")
    if any(tail.count(w) != 1 for w in work):
        return None
    tail = tail.replace(work[0], f"  if (sz_w) *sz_w = {n_w};\n").replace(work[1], f"  if (sz_w) *sz_w = {n_w}*sizeof(casadi_real);\n")
    stmts = [_LOCAL.sub(lambda m: f"w[{int(m.group(1))}]", ln) for ln in stmts]  # a00012 is w[12], not octal
    parts = [stmts[i:i + statements] for i in range(0, len(stmts), statements)]
    sig = "(const casadi_real** arg, casadi_real** res, casadi_real* w)"
    names_p = [f"{prefix}_part{j}" for j in range(len(parts))]
    main = (head + "".join(f"void {nm}{sig};\n" for nm in names_p) + "\n" + _F0
            + "".join(f"  {nm}(arg, res, w);\n" for nm in names_p) + _END + tail)
    step = max(1, per_file // statements)  # functions a file
    out = [main]
    for f in range(0, len(parts), step):
        # the generated helpers (casadi_sq, …) get this file's own prefix and its exported
        # ones (casadi_version, …) are static here: no clash at the link
        text = (f"#define CASADI_CODEGEN_PREFIX\n#define CODEGEN_PREFIX {prefix}_file{f}_\n"
                "#define CASADI_SYMBOL_EXPORT static\n" + head)
        for j in range(f, min(f + step, len(parts))):
            text += f"\nvoid {names_p[j]}{sig} {{\n" + "\n".join(parts[j]) + "\n}\n"
        out.append(text)
    return out


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
          log: Callable[[str], None] | None = None, staged: bool = False) -> dict[str, float]:
    """Compile the functions of one built NLP (``fns``, as :meth:`~.model.PhaseNLP._build` keys
    them) into ``folder`` as one library named ``name``: each function is its own C file (a large
    one several, :func:`split`), the files compile ``jobs`` at a time, then one link. Returns each
    function's compile seconds (its files' sum). Raises RuntimeError naming the function when the
    compiler fails. A library already there is kept (same name, same code). ``staged``: ``fns``
    is the stage-by-stage NLP of :mod:`.staged`, whose solver is FATROP."""
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler (set $CC or install gcc): stl-tamp's NLPs cannot be compiled")
    folder.mkdir(parents=True, exist_ok=True)
    if library(folder, name).exists():
        return {}
    from . import staged as staged_nlp

    solver_fns = staged_nlp.solver_functions(fns) if staged else solver_functions(fns)
    todo = {**solver_fns, **{k: fns[k] for k in (staged_nlp.HELPER_NAMES if staged else HELPER_NAMES)}}
    work = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=folder))
    try:
        units: list[tuple[str, Path, tuple[str, ...]]] = []  # (function, C file, flags)
        for k, fn in todo.items():  # code generation is quick and holds the GIL: one after the other
            stem = f"stl_tamp_{name}_{k}"  # a C identifier, whatever the key starts with
            cg = ca.CodeGenerator(stem + ".c", {"with_header": False})
            cg.add(fn)
            cg.generate(str(work) + os.sep)
            text = (work / (stem + ".c")).read_text()
            pieces = split(text, stem, PART_STATEMENTS, PART_FILE_STATEMENTS) if fn.n_instructions() > SPLIT_ABOVE else None
            if pieces is None:
                units.append((k, work / (stem + ".c"), flags(k, fn)))
                continue
            level = "-O0" if k in ONCE else "-O1"
            for i, piece in enumerate(pieces):
                (work / f"{stem}_{i}.c").write_text(piece)
                units.append((k, work / f"{stem}_{i}.c", (level, *BASE_FLAGS)))

        def one(unit: tuple[str, Path, tuple[str, ...]]) -> tuple[str, float]:
            k, src, fl = unit
            t0 = time.perf_counter()
            res = subprocess.run([cc, "-c", *fl, str(src), "-o", str(src.with_suffix(".o"))], capture_output=True, text=True)
            if res.returncode != 0:
                raise RuntimeError(f"{cc} failed on {name}.{k}: {res.stderr.strip()[-500:]}")
            dt = time.perf_counter() - t0
            if log is not None:
                log(f"compiled {src.name} ({fl[0]}) in {dt:.1f} s")
            return k, dt

        units.sort(key=lambda u: -u[1].stat().st_size)  # the largest first
        # a function that could not be split and is above O1_LIMIT compiles alone (a whole global
        # Hessian: 2.6 GB in gcc at -O0), the rest jobs at a time
        alone = [u for u in units if u[2][0] == "-O0" and todo[u[0]].n_instructions() > O1_LIMIT
                 and u[1].name == f"stl_tamp_{name}_{u[0]}.c"]
        took: dict[str, float] = {}
        for k, dt in [one(u) for u in alone]:
            took[k] = took.get(k, 0.0) + dt
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            for k, dt in pool.map(one, [u for u in units if u not in alone]):
                took[k] = took.get(k, 0.0) + dt
        tmp = work / "lib.so"
        res = subprocess.run([cc, "-shared", *[str(u[1].with_suffix(".o")) for u in units], "-o", str(tmp), "-lm"],
                             capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(f"{cc} failed to link {name}: {res.stderr.strip()[-500:]}")
        os.replace(tmp, library(folder, name))
        return took
    finally:
        shutil.rmtree(work, ignore_errors=True)


def load(folder: Path | None, name: str, helpers: tuple[str, ...] = HELPER_NAMES) -> dict[str, Any] | None:
    """The compiled functions of ``name`` in ``folder`` (``nlp`` is the oracle an ``nlpsol``
    finds the others in), or None when the library is not there or lacks one."""
    if folder is None or not library(folder, name).is_file():
        return None
    try:
        return {k: ca.external(k, str(library(folder, name))) for k in ("nlp", *helpers)}
    except RuntimeError:
        return None
