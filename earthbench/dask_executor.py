"""Deprecated: moved to :mod:`earthbench.harness.dask_executor` in 0.2.0."""

from . import compat

__getattr__ = compat.forward(__name__)
