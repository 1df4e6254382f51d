"""Generated lane kernels: the Python that writes numba source for one scene topology.

Pure Python: importing this package never imports numba (the generated module does, when
:func:`mcchain.codegen.generate.lane_kernels` loads it). A group of ``lanes`` instances is
advanced in lockstep with the instance index innermost, the lane count a run-time argument,
the step one fused function body and sin/cos a branch-free polynomial (PERFORMANCE.md). To
get a fused body without paying for what a scene does not have, the straight-line code for
one lane is generated from the scene's topology — never from parameter values, which are read
per lane from the packed array ``P``.

Modules, one job each:

* ``topology``: :class:`~mcchain.codegen.topology.Topology` (the hashable structure of a
  model) and :func:`~mcchain.codegen.topology.pack_parameters` (``P``, one slot per
  parameter).
* ``emitter``: straight-line code of one lane (index-1 acceleration through the Schur
  complement and its sparse LDLᵀ, the constraint projection, the outputs, sin/cos).
* ``layout``: the rows of the flat work array ``W`` and their length ``LMAX``.
* ``templates``: the texts of the time loops the emitter's blocks are put into.
* ``schedule``: demand-order scheduling of the generated lane loops.
* ``cache``: the on-disk cache of generated modules, and loading one.
* ``generate``: :func:`~mcchain.codegen.generate.generate_source` and
  :func:`~mcchain.codegen.generate.lane_kernels`, the entry points, per topology and variant
  (the functions one method calls: ``accel``, ``rk4``, ``rk4-projection``, ``rk45``).
"""
