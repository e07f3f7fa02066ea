"""Pure-Python references the tests and benchmarks hold the package to (not shipped).

* :mod:`reference.corner_qp`: the exact corner QP by enumeration of free sets (extended
  precision), formerly ``grfguard.estimate.corner_qp``;
* :mod:`reference.nnls_split`: the compliance split by ``scipy.optimize.nnls`` with a
  penalty row, formerly the Python stages' solver.

The Python stages of the virtual force sensor themselves (``VirtualForceSensor(...,
compiled=False)``) stay in the package: they run the settings the compiled kernel does
not cover.
"""
