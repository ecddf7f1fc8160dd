"""What a suite file's values must be (docs/DESIGN.md §2, the suite): only known keys (a typo names
the close ones), and a family's generator parameters of the types its signature names, on a grid
no larger than the suite allows."""

from __future__ import annotations

import difflib
import inspect
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ..errors import SuiteError


def refuse_unknown(keys: Iterable[str], allowed: Iterable[str], where: str) -> None:
    """A :class:`SuiteError` for the first key not ``allowed``, suggesting the close names."""
    allowed = list(allowed)
    for k in keys:
        if k not in allowed:
            close = difflib.get_close_matches(k, allowed, n=3, cutoff=0.5)
            hint = f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise SuiteError(f"{where}: unknown key {k!r}.{hint} Allowed keys: {', '.join(allowed)}.")


def check_params(gen: Any, params: dict[str, Any], where: str, path: str, max_cells: int) -> dict[str, Any]:
    """Check a family's parameters against the generator's signature, before anything is generated.

    Unknown names, values of the wrong type (by the parameter's annotation) and a grid of more
    than ``max_cells`` cells (:data:`earthbench.results.suite.MAX_CELLS`) (``size`` / ``resolution``) are refused; a relative ``path``
    resolves against the suite file's folder. Returns the parameters to generate with.
    """
    params = dict(params)
    try:
        sig = inspect.signature(gen)
    except (TypeError, ValueError):
        return params
    ps = list(sig.parameters.values())
    if not any(p.kind is p.VAR_KEYWORD for p in ps):
        names = [p.name for p in ps[2:] if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
        refuse_unknown(params, names, f"{where} params")
    for key, value in params.items():
        p = sig.parameters.get(key)
        if p is not None and isinstance(p.annotation, str) and not _fits(value, p.annotation):
            raise SuiteError(f"{where} params: {key} must be {p.annotation}, got {type(value).__name__} {value!r:.60}")
    size = params.get("size", _default(sig, "size"))
    res = params.get("resolution", _default(sig, "resolution"))
    if isinstance(size, (list, tuple)) and len(size) == 2 and all(isinstance(v, (int, float)) for v in (*size, res or 0)) and res:
        if res <= 0 or min(size) <= 0:
            raise SuiteError(f"{where} params: size and resolution must be positive, got size {list(size)}, resolution {res}")
        cells = math.ceil(size[0] / res) * math.ceil(size[1] / res)
        if cells > max_cells:
            raise SuiteError(f"{where} params: size {list(size)} m at resolution {res} m is {cells:.3g} cells, "
                             f"over the limit of {max_cells:,} cells per heightmap")
    if isinstance(params.get("path"), str) and path and not Path(params["path"]).is_absolute():
        params["path"] = str((Path(path).parent / params["path"]).resolve())
    return params


def _default(sig: inspect.Signature, name: str) -> Any:
    p = sig.parameters.get(name)
    return None if p is None or p.default is p.empty else p.default


def _fits(value: Any, annotation: str) -> bool:
    """Whether a TOML value fits a parameter annotation such as ``float | tuple[float, float]``.

    Understands int, float, str, bool, None and tuple/list of those; anything else passes.
    """
    parts = _split(annotation, "|")
    for part in parts:
        part = part.strip()
        head, _, inner = part.partition("[")
        inner = inner[:-1] if inner.endswith("]") else inner
        if head == "int" and isinstance(value, int) and not isinstance(value, bool):
            return True
        if head == "float" and isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return True
        if head == "str" and isinstance(value, str):
            return True
        if head == "bool" and isinstance(value, bool):
            return True
        if head in ("tuple", "list") and isinstance(value, (list, tuple)):
            if not inner:
                return True
            args = _split(inner, ",")
            if head == "list" or (len(args) == 2 and args[1].strip() == "..."):
                if all(_fits(v, args[0]) for v in value):
                    return True
            elif len(args) == len(value) and all(_fits(v, a) for v, a in zip(value, args)):
                return True
        if head not in ("int", "float", "str", "bool", "tuple", "list", "None"):
            return True  # an annotation this check does not understand
    return False


def _split(text: str, sep: str) -> list[str]:
    """Split on ``sep`` outside brackets."""
    out, depth, cur = [], 0, ""
    for ch in text:
        depth += ch == "["
        depth -= ch == "]"
        if ch == sep and depth == 0:
            out.append(cur)
            cur = ""
        else:
            cur += ch
    return [*out, cur]
