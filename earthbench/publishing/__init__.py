"""The publishing layer (docs/DESIGN.md §2, §9): checking and merging stores (``verify``,
``merge``), the best known plan of each scenario (``best``), the leaderboard (``publish``, drawn
by ``board``) and comparing runs (``compare``). Nothing below this layer imports it."""
