"""The running layer (docs/DESIGN.md §2, §6): running cases in fenced processes (``harness``), a
plan played back frame by frame (``playback``: the page's viewer, ``show --animate``) and the
figures drawn from runs (``figures``, ``scaling``). Above the results it writes; below publishing."""
