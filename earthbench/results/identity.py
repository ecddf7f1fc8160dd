"""Pinned suite identity: a known suite name always means the registered suite's world.

A store is a file anyone can write. Without this check a store could hold an easier world
(a fuller bucket, no scan noise) under the name ``standard-realistic``, and a merge into a
fresh store would list it under the genuine name. So ``merge`` and ``verify`` check every
suite version a store lists (:func:`problems`):

* a name of a registered suite (built in, or installed through the ``earthbench.suites``
  entry points) must carry that suite's digest; a different digest is refused, naming both;
* a sealed version (:mod:`earthbench.seal`) must be named ``PUBLIC~sealed-C`` after its own
  commitment, and, when PUBLIC is registered, be drawn from the registered digest (the sealed
  scenarios themselves are checked against the key once it is revealed: ``verify --key``);
* a name that claims a sealed draw without a commitment is refused;
* any other name (a suite file of one's own, or a ``NAME~variant-D`` name that says it is a
  variant) is stored as it is.

``earthbench merge --as-variant`` stores a known name with another digest as
``NAME~variant-D`` (D: its digest's first 12 hex digits) instead of refusing it
(:func:`variant_name`).
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import dataclass

from ..errors import EarthbenchError
from ..seal import public_name, sealed_name

VARIANT_MARK = "~variant-"


@dataclass(frozen=True)
class Version:
    """A stored suite version, as the check reads it."""

    name: str
    digest: str
    where: str
    sealed_from: str | None = None
    public_digest: str | None = None
    commitment: str | None = None


def variant_name(name: str, digest: str) -> str:
    """The name a different world under a known name is stored as with ``--as-variant``."""
    return f"{name}{VARIANT_MARK}{digest[:12]}"


@functools.cache
def registered_digest(name: str) -> str | None:
    """The digest of the registered suite ``name`` (None: no such suite is registered)."""
    from .suite import known_suites, registered_suite

    if name not in known_suites():
        return None
    try:
        return registered_suite(name).digest
    except EarthbenchError:
        return None  # a broken installed suite pins nothing


def problem(v: Version) -> str:
    """Why ``v`` may not be stored under its name ('' when it may)."""
    if v.sealed_from:
        if not v.commitment or v.name != sealed_name(v.sealed_from, v.commitment):
            return (f"{v.where}: suite {v.name!r} says it was sealed from {v.sealed_from!r}, but its name is not the one its "
                    f"commitment gives ({sealed_name(v.sealed_from, v.commitment or '')!r})")
        want = registered_digest(v.sealed_from)
        if want is not None and v.public_digest != want:
            return (f"{v.where}: suite {v.name!r} was drawn from a suite {v.sealed_from!r} with digest {str(v.public_digest)[:12]}…, "
                    f"but the registered suite {v.sealed_from!r} has digest {want[:12]}…: a sealed draw of another world")
        return ""
    if public_name(v.name) is not None:
        return f"{v.where}: suite {v.name!r} is named as a sealed draw but carries no seal (no public suite, no commitment)"
    want = registered_digest(v.name)
    if want is not None and v.digest != want:
        return (f"{v.where}: suite {v.name!r} has digest {v.digest[:12]}…, but the registered suite {v.name!r} has digest "
                f"{want[:12]}…: a different world under a known name (store it as {variant_name(v.name, v.digest)!r} "
                "with --as-variant, or rerun it with the registered suite)")
    return ""


def problems(versions: Iterable[Version]) -> list[str]:
    """Every stored suite version that may not be stored under its name."""
    return [p for v in versions if (p := problem(v))]


def renamed(v: Version) -> str:
    """The name ``v`` is stored under with ``--as-variant``: a variant name when its known name
    means another world, its own name otherwise."""
    if v.sealed_from or public_name(v.name) is not None:
        return v.name
    want = registered_digest(v.name)
    return variant_name(v.name, v.digest) if want is not None and v.digest != want else v.name
