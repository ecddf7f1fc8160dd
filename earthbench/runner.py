"""Deprecated: the harness moved to :mod:`earthbench.harness` in 0.2.0 (``from earthbench.harness import run_suite``)."""

from .lazy import moved_module

__getattr__ = moved_module(__name__, "earthbench.harness")
