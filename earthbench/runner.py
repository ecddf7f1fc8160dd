"""Deprecated: the harness moved to :mod:`earthbench.harness` in 0.2.0 (``from earthbench.harness import run_suite``)."""

from . import compat

__getattr__ = compat.forward(__name__)
