"""Generated lane kernels: the Python that writes kernel source for one scene topology, and
the compiler that turns it into machine code.

Importing this package never imports numba (:func:`mcchain.codegen.generate.lane_kernels`
does, for numba's LLVM code generator). A group of ``lanes`` instances is
advanced in lockstep with the instance index innermost, the lane count a run-time argument,
the step one fused function body and sin/cos a branch-free polynomial (PERFORMANCE.md). To
get a fused body without paying for what a scene does not have, the straight-line code for
one lane is generated from the scene's topology — never from parameter values, which are read
per lane from the packed array ``P``.

Modules, one job each:

* ``topology``: :class:`~mcchain.codegen.topology.Topology` (the hashable structure of a
  model) and :func:`~mcchain.codegen.topology.pack_parameters` (``P``, one slot per
  parameter).
* ``lane_text``: the base of the lane's code: the lines being written, the parameter names,
  the contact-law rows, the kernels' functions inlined as text (``inline``).
* ``kinematics``: the constraint equations of one lane (points, B's non-zeros, Φ, Φ̇, γ).
* ``sparse_ldl``: the Schur complement S = B M⁻¹ Bᵀ, its sparse LDLᵀ and the solves.
* ``emitter``: the blocks of one lane built on those two (applied forces, the contact law's
  rows, the index-1 acceleration, the constraint projection, the outputs).
* ``sincos``: the branch-free sine/cosine the lanes inline.
* ``layout``: the rows of the flat work array ``W`` and their length ``LMAX``.
* ``contact_blocks``: the lanes' bookkeeping of contact-law joints (onsets, separations,
  the switches of model auto, re-seats, summaries), put into the templates' blocks.
* ``templates``: the texts of the time loops the emitter's blocks are put into.
* ``tracking``: per-step tracking in the lanes (the continuous peaks), at the templates'
  ``@@track_*`` hooks.
* ``schedule``: demand-order scheduling of the generated lane loops.
* ``native``: the generated text translated to LLVM IR in one pass and compiled with numba's
  code generator (no type inference: seconds where ``@njit`` took minutes), called through
  ``ctypes``, its machine code cached on disk.
* ``cache``: the on-disk cache of generated module texts, and importing one (the lanes
  compiled by ``@njit`` instead, ``MCCHAIN_LANE_COMPILER=numba``: the reference).
* ``generate``: :func:`~mcchain.codegen.generate.generate_source` and
  :func:`~mcchain.codegen.generate.lane_kernels`, the entry points, per topology and variant
  (the functions one method calls: ``accel``, ``rk4``, ``rk4-projection``, ``rk45``).
"""
