"""The STL-TAMP paper's "Separate" baseline (Fig. 5b), registered as ``separate``: tasks chosen by
a rule, motions and times by the STL-TAMP local NLP of :mod:`earthbench_planners.stl_tamp`."""
