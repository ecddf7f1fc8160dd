"""Terrain generators, terrain loaders and suite definitions.

Every generator is a callable ``(seed, target_volume, **params) -> Scenario`` registered in
the ``earthbench.terrains`` entry-point group. Generation is seeded with numpy's
``default_rng`` and heights are rounded to 0.1 mm, so a seed gives the same digest everywhere.
"""
