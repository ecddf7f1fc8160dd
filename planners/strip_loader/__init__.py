"""``strip-loader``: the wheel loader scrapes a strip along the pile with the truck moving beside
it (:mod:`.planner`, the strip's geometry in :mod:`.strip`)."""
