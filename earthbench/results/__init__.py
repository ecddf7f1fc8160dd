"""The results layer (docs/DESIGN.md §2, §7, §8): the scoring rule (``scoring``), the run's records
(``records``) and the store that keeps them (``store``), suites and their identity (``suite``,
``suite_checks``, ``identity``), aggregates over runs (``aggregate``, ``generalisation``), labels,
the progress line, the machine classes' calibration and the provenance of the code that ran. A
metric plugin builds on this layer; the harness writes into it."""
