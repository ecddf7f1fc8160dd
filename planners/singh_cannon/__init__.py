"""Singh–Cannon multi-resolution planners (Singh & Cannon, 1998).

``backhoe`` (with ``backhoe_model``) holds the bench-loading planner of section 3.1; the
wheel-loader planner of section 3.2 lives in its own module beside it.
"""
