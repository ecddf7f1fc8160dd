"""Deprecated: moved to :mod:`earthbench.harness.dask_executor` in 0.2.0."""

from .lazy import moved_module

__getattr__ = moved_module(__name__, "earthbench.harness.dask_executor")
