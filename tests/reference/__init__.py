"""Pure-Python references the tests and benchmarks hold the package to (not shipped).

* :mod:`reference.corner_qp`: the exact corner QP by enumeration of free sets (extended
  precision), formerly ``grfguard.estimate.corner_qp``;
* :mod:`reference.nnls_split`: the compliance split by ``scipy.optimize.nnls`` with a
  penalty row, formerly the Python stages' solver.

* :mod:`reference.vfs_stages` (``PythonVFS``), :mod:`reference.vfs_com`,
  :mod:`reference.vfs_legs`: the virtual force sensor's stages in numpy, formerly
  ``VirtualForceSensor(..., compiled=False)`` and ``grfguard.estimate.{com,legs}``; the
  compiled kernels (``grfguard.kernels.vfs``, ``vfs_paper``) run every setting and are
  held to these;
* :mod:`reference.corner_split`: the batch corner QP around the compiled solver, formerly
  ``grfguard.estimate.compliance`` and ``grfguard.kernels.split``.
"""
