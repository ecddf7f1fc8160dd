"""Built-in suite files (``*.toml``), registered through the ``earthbench.suites`` entry point.

Every ``NAME.toml`` here is the suite ``NAME``; see :mod:`earthbench.results.suite` for the format.
"""
