"""Deprecated: the judge's replay state moved to :mod:`earthbench.referee.state` after 0.2.0, named for
what it holds; the rules documented here in 0.1 (``bodies_touch``, ``off_map_excess``,
``reach_of``, ``rectangles_touch``) are in :mod:`earthbench.rules` since 0.2."""

from .. import compat

__getattr__ = compat.forward(__name__)
