"""Singh and Cannon's coarse-to-fine planners (backhoe and wheel loader)."""
