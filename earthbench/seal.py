"""Sealed draws: a suite's scenarios drawn from a secret key, so no planner can have seen them.

A public suite's scenarios come from public, deterministic generators and seeds: anyone can
regenerate the hidden truth of a realistic scenario or precompute a plan for every exact one.
A *sealed* run of the suite keeps its families, generators, parameters, targets and budget but
draws every random choice from a key only the person running the board holds
(docs/sealed-evaluation.md):

* the terrain seed, the hidden soil's seed and the scan's noise seed of each public seed of a
  family are HMAC-SHA256 of the key and ``SUITE/FAMILY/sSEED\\nPURPOSE`` (:meth:`SealKey.derive`),
  each 63 bits, shared by the family's targets as the public seed is (a ``/1`` key derived them
  per scenario, from ``SUITE/FAMILY/sSEED/vTARGET``);
* and nothing else. Whatever a sealed draw changes beyond what the public suite's own seeds
  change is a feature a case could tell it by (the keys of 0.2.0 and 0.3.0, schema
  :data:`LEGACY_SCHEMA`, also moved each site rigidly with :class:`SiteTransform`: one look at
  the map's origin told sealed from public). A sealed scenario is a sample of the generator's
  own distribution; a generator whose seed changes nothing (``file``) has nothing to seal.
  A legacy key still draws as it did, so a revealed one regenerates its draw and its commitment.

What is *not* re-drawn: a family's fixed parameters (a sensing ``bias`` of 0.02 m stays 0.02 m,
a material stays loam): those define the suite's world, and re-drawing them would change the
world rather than the draw.

``earthbench seal SUITE --key FILE`` writes a fresh key and prints the commitment
(:func:`commitment`: sha256 over the key, the public suite's digest and the sorted sealed
scenario digests). The sealed suite is named ``SUITE~sealed-C`` (C: the commitment's first 12
hex digits), so its runs sit beside the public ones in a store and on a board. Revealing the key
file afterwards lets anyone check the commitment, regenerate every sealed scenario and re-judge
every plan (``earthbench verify STORE --key FILE``).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import EarthbenchError, read_document
from . import compat
from .world import Heightmap, Machines, Pose, Scenario, Site

#: The key file's schema, which also names how its draw is made: ``/2`` keys draw only the seeds;
#: ``/1`` keys (0.2.0 and 0.3.0) also moved each site with :class:`SiteTransform`, and still do,
#: so a revealed ``/1`` key regenerates its draw and reproduces its commitment. New keys are ``/2``.
SEAL_SCHEMA = "earthbench.seal/2"
LEGACY_SCHEMA = "earthbench.seal/1"
SCHEMAS = (SEAL_SCHEMA, LEGACY_SCHEMA)
KEY_BYTES = 32
#: The most :meth:`SiteTransform.draw` shifts a site in x and in y (m), in whole cells of its terrain.
MAX_SHIFT_M = 50.0
TRANSFORMS = ("shift", "rotate", "mirror")
#: What joins a public suite's name and a commitment in a sealed suite's name.
SEALED_MARK = "~sealed-"


class SealError(EarthbenchError):
    """A key file that cannot be used: unreadable, for another suite, or not matching its commitment."""


def sealed_name(public: str, commitment: str) -> str:
    """The name a sealed suite is stored and published under: ``PUBLIC~sealed-C12``."""
    return f"{public}{SEALED_MARK}{commitment[:12]}"


def public_name(name: str) -> str | None:
    """The public suite a sealed suite's name was drawn from (None: not a sealed name)."""
    head, mark, tail = name.rpartition(SEALED_MARK)
    return head if mark and head and len(tail) == 12 and all(c in "0123456789abcdef" for c in tail) else None


def commitment(key: bytes, public_digest: str, sealed_digests: list[str] | tuple[str, ...], schema: str = SEAL_SCHEMA) -> str:
    """sha256 over the key's schema, the key, the public suite's digest and the sorted sealed scenario digests.

    Published before the run, it binds the board to one key and one set of worlds without
    revealing either; the key's 256 random bits keep a guess at the worlds from confirming it.
    """
    h = hashlib.sha256(f"{schema}\n{key.hex()}\n{public_digest}\n".encode())
    for d in sorted(sealed_digests):
        h.update(f"{d}\n".encode())
    return h.hexdigest()


@dataclass(frozen=True)
class SealKey:
    """A secret key for one public suite version, and the commitment to its draw."""

    suite: str
    suite_digest: str
    key: bytes
    commitment: str = ""
    created_at: str = ""
    #: The suite file the key was made from; where :func:`public_suite` finds an unregistered suite.
    path: str = ""
    #: How the draw is made (:data:`SEAL_SCHEMA`; :data:`LEGACY_SCHEMA`: a 0.2.0 or 0.3.0 key, sites moved).
    schema: str = SEAL_SCHEMA

    def derive(self, public_id: str, purpose: str) -> int:
        """A 63-bit seed for one random choice of one scenario: HMAC-SHA256(key, id and purpose)."""
        mac = hmac.new(self.key, f"{public_id}\n{purpose}".encode(), hashlib.sha256).digest()
        return int.from_bytes(mac[:8], "big") >> 1

    @property
    def name(self) -> str:
        """The sealed suite's name."""
        return sealed_name(self.suite, self.commitment)

    def to_json(self) -> str:
        return json.dumps({"schema": self.schema, "suite": self.suite, "suite_digest": self.suite_digest,
                           "key": self.key.hex(), "commitment": self.commitment, "created_at": self.created_at,
                           "path": self.path}, indent=1) + "\n"

    def write(self, path: str | Path) -> None:
        """Write the key file, readable by its owner only; an existing file is never overwritten."""
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            raise SealError(f"{str(path)!r} exists; a key file is never overwritten (choose another path)") from None
        except OSError as exc:
            raise SealError(f"cannot create the key file {str(path)!r}: {exc.strerror}") from None
        with os.fdopen(fd, "w") as f:
            f.write(self.to_json())

    @classmethod
    def read(cls, path: str | Path) -> SealKey:
        """Read and check a key file (``earthbench seal`` wrote it)."""
        text = read_document(Path(path), "key file", SealError)
        try:
            doc = json.loads(text)
            if doc.get("schema") not in SCHEMAS:
                raise SealError(f"{str(path)!r} is not an earthbench key file (schema {doc.get('schema')!r}, expected {SEAL_SCHEMA!r})")
            key = bytes.fromhex(doc["key"])
            out = cls(str(doc["suite"]), str(doc["suite_digest"]), key, str(doc["commitment"]), str(doc.get("created_at", "")),
                      str(doc.get("path", "")), str(doc["schema"]))
        except SealError:
            raise
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise SealError(f"{str(path)!r} is not a readable key file: {type(exc).__name__}: {exc}") from None
        if len(key) != KEY_BYTES:
            raise SealError(f"{str(path)!r}: the key must be {KEY_BYTES} bytes, got {len(key)}")
        return out


# -- the site transform ----------------------------------------------------------------------------


@dataclass(frozen=True)
class SiteTransform:
    """A rigid motion of a whole site: mirror x about the map's centre (first), then turn by
    ``quarter_turns`` × 90° counter-clockwise about it, then shift by ``shift`` (m)."""

    quarter_turns: int = 0
    mirror: bool = False
    shift: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def draw(cls, seed: int, allowed: tuple[str, ...], resolution: float) -> SiteTransform:
        """A transform drawn from ``seed`` among the ``allowed`` motions (sealed draws used it up to 0.3.0)."""
        rng = np.random.default_rng(seed)
        turns, mirror = int(rng.integers(4)), bool(rng.integers(2))
        cells = int(MAX_SHIFT_M // resolution)
        dx, dy = (float(k) * resolution for k in rng.integers(-cells, cells + 1, size=2))
        return cls(turns if "rotate" in allowed else 0, mirror and "mirror" in allowed,
                   (dx, dy) if "shift" in allowed else (0.0, 0.0))

    def to_dict(self) -> dict[str, Any]:
        return {"quarter_turns": self.quarter_turns, "mirror": self.mirror, "shift": list(self.shift)}

    def apply(self, sc: Scenario) -> Scenario:
        """``sc`` moved: terrain, dig area, keep-outs and every machine pose."""
        t = sc.terrain
        xmin, xmax, ymin, ymax = t.extent
        cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
        z = np.asarray(t.z)
        if self.mirror:
            z = z[:, ::-1]
        for _ in range(self.quarter_turns % 4):
            z = z[::-1].T  # a quarter turn counter-clockwise with y up: (x, y) -> (-y, x)
        ny, nx = z.shape
        r = t.resolution
        origin = (cx - nx * r / 2 + self.shift[0], cy - ny * r / 2 + self.shift[1])

        def point(p: tuple[float, float]) -> tuple[float, float]:
            x, y = p[0] - cx, p[1] - cy
            if self.mirror:
                x = -x
            for _ in range(self.quarter_turns % 4):
                x, y = -y, x
            return (_tidy(x + cx + self.shift[0]), _tidy(y + cy + self.shift[1]))

        def poly(ps: tuple[tuple[float, float], ...]) -> tuple[tuple[float, float], ...]:
            out = tuple(point(p) for p in ps)
            return out[::-1] if self.mirror else out  # keep the winding

        def pose(p: Pose | None) -> Pose | None:
            if p is None:
                return None
            yaw = (math.pi - p.yaw) if self.mirror else p.yaw
            yaw = math.remainder(yaw + self.quarter_turns * math.pi / 2, 2 * math.pi)
            x, y = point((p.x, p.y))
            return Pose(x, y, _tidy(yaw))

        m = sc.machines
        machines = Machines(truck=m.truck, truck_pose=pose(m.truck_pose) or m.truck_pose, excavator=m.excavator,
                            excavator_pose=pose(m.excavator_pose), loader=m.loader, loader_pose=pose(m.loader_pose))
        site = Site(poly(sc.site.dig_area), sc.site.floor, tuple(poly(k) for k in sc.site.keep_outs), sc.site.open_outside)
        return sc.replace(terrain=Heightmap((_tidy(origin[0]), _tidy(origin[1])), r, z), site=site, machines=machines)


def _tidy(v: float) -> float:
    """Round a transformed coordinate to 1e-9 m, so a sealed scenario has one digest on every machine."""
    return round(float(v), 9) + 0.0


__getattr__ = compat.forward(__name__)  # new_key, open_sealed: moved to earthbench.results.suite (earthbench.compat)
