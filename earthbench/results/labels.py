"""Readable names of planner configurations (``greedy`` at its defaults, ``greedy[closed_loop]``,
``greedy[min_fill=0.5]`` otherwise) and of machines (:func:`machine_label`), and the spot checks a
board's stamp quotes (:func:`latest_spot_checks`): what publishing and ``verify`` both show.

A configuration's hash tells two configurations apart but says nothing to a reader; its label
names the settings that differ from the planner's defaults (from the installed planner's
``Config``), or — where the planner is not installed — the settings that differ among its stored
configurations. ``runs``, summaries, boards and ``compare`` show it, and ``compare`` selects by it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import pandas as pd

from .records import SpotCheck

if TYPE_CHECKING:  # pragma: no cover
    from .store import Store


def _value(v: Any) -> str:
    if isinstance(v, float):
        return format(v, "g")
    if isinstance(v, str):
        return v
    return json.dumps(v, sort_keys=True, separators=(",", ":"))


def label(planner: str, config: Mapping[str, Any], defaults: Mapping[str, Any] | None) -> str:
    """``planner[setting, key=value, …]`` for the settings of ``config`` not at ``defaults`` (the bare name if none).

    ``defaults`` None: every setting counts as non-default (the caller narrows ``config`` first).
    """
    parts = []
    for k in sorted(config):
        v = config[k]
        if defaults is not None and k in defaults and defaults[k] == v:
            continue
        parts.append(k if v is True else f"{k}={_value(v)}")
    return f"{planner}[{', '.join(parts)}]" if parts else planner


def planner_defaults(planner: str) -> dict[str, Any] | None:
    """The installed planner's default configuration as JSON data, or None when it is not installed."""
    from ..errors import EarthbenchError
    from ..registry import PLANNERS

    try:
        return PLANNERS.get(planner)().config_dict
    except EarthbenchError:
        return None
    except Exception:  # noqa: BLE001 - a plugin's constructor is code we did not write; fall back to the store
        return None


def config_labels(runs: pd.DataFrame) -> dict[tuple[str, str], str]:
    """(planner, config hash) → label, for every configuration in ``runs`` (columns ``planner``,
    ``config_hash`` and, if present, ``config``: the configuration's JSON text)."""
    if runs.empty:
        return {}
    cols = ["planner", "config_hash"] + (["config"] if "config" in runs else [])
    seen = runs[cols].drop_duplicates(["planner", "config_hash"])
    out: dict[tuple[str, str], str] = {}
    for planner, sub in seen.groupby("planner", sort=False):
        configs: dict[str, dict[str, Any]] = {}
        for r in sub.itertuples(index=False):
            try:
                doc = json.loads(getattr(r, "config", None) or "{}")
            except (TypeError, ValueError):
                doc = {}
            configs[str(r.config_hash)] = doc if isinstance(doc, dict) else {}
        defaults = planner_defaults(str(planner))
        if defaults is None:  # not installed here: name what differs among the stored configurations
            keys = {k for c in configs.values() for k in c}
            varying = {k for k in keys if len({json.dumps(c.get(k), sort_keys=True) for c in configs.values()}) > 1}
            labels = {h: label(str(planner), {k: v for k, v in c.items() if k in varying}, None) for h, c in configs.items()}
        else:
            labels = {h: label(str(planner), c, defaults) for h, c in configs.items()}
        # two different configurations must never share a label: add the hash where they would (equal
        # settings under two hashes are two versions of the planner, which the version tells apart)
        for h, text in labels.items():
            twins = {json.dumps(configs[g], sort_keys=True) for g, t in labels.items() if t == text}
            out[(str(planner), h)] = text if len(twins) == 1 else f"{text}#{h[:8]}"
    return out


def machine_label(env: dict[str, Any] | Any) -> str:
    """A machine as readers know it: hostname, CPU model, cores."""
    get = env.get if isinstance(env, dict) else (lambda k: env[k])  # a dict or a stored row
    host, cpu, cores = get("hostname"), get("cpu_model"), get("cores")
    return f"{host or 'unknown host'} ({cpu or 'unknown CPU'}" + (f", {cores} cores)" if cores else ")")


def latest_spot_checks(store: Store) -> list[SpotCheck]:
    """The most recent spot check of each planner version and configuration (none if never checked);
    :meth:`Store.record_spot_checks` keeps them."""
    return [SpotCheck(**fields) for fields in store.latest_spot_checks()]
