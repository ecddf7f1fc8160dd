"""Greedy baselines: fullest reachable bucket first (backhoe, :mod:`.backhoe`, registered as
``greedy``) and nearest contour point to the truck (wheel loader, :mod:`.loader`, ``greedy-loader``)."""
