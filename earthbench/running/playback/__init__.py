"""Playback: a plan's effect step by step, for the page's replay viewer, the figures and
``earthbench show --animate`` (docs/DESIGN.md §5). One module per job: :mod:`.frames` (the
referee's state after each action, from its one judgement), :mod:`.geometry` (where the machines
and the bucket are), :mod:`.selection` (which runs the page replays), :mod:`.viewer` (the packed
replays and the page's section); every name imports from the package."""

from __future__ import annotations

from .frames import Change, Step, changes, replay
from .geometry import bucket_footprint, bucket_path, machine_paths, pose_at
from .selection import pick_runs
from .viewer import CSS, QUANTUM, SCRIPT, replay_data, viewer_html, viewer_section

__all__ = [
    "CSS", "QUANTUM", "SCRIPT", "Change", "Step", "bucket_footprint", "bucket_path", "changes", "machine_paths", "pick_runs",
    "pose_at", "replay", "replay_data", "viewer_html", "viewer_section",
]
