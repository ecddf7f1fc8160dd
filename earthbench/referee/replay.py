"""Deprecated: the judge's replay state moved to :mod:`earthbench.referee.state` after 0.2.0, named for
what it holds; the rules documented here in 0.1 (``bodies_touch``, ``off_map_excess``,
``reach_of``, ``rectangles_touch``) are in :mod:`earthbench.rules` since 0.2."""

from ..lazy import moved_getattr, moved_module

__getattr__ = moved_getattr(__name__, dict.fromkeys(("bodies_touch", "off_map_excess", "reach_of", "rectangles_touch"), "earthbench.rules"),
                            fallback=moved_module(__name__, "earthbench.referee.state"))
