"""Publishing, split by job (docs/DESIGN.md §9); :func:`earthbench.publishing.publish.publish` runs them in turn.

* :mod:`.selection` — which runs and versions a board shows;
* :mod:`.tables` — each table's rows, the reproducibility stamp, Markdown and CSV;
* :mod:`.figures` — the figures and the worker processes that draw them;
* :mod:`.page` — the self-contained HTML page.
"""
