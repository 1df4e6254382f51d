"""Numba kernels: arrays and scalars in, arrays and status bits out. Never raise.

Modules: ``config`` (numba options), ``joints`` (constraints Φ, B, γ and their second
derivatives), ``forces`` (applied forces F, ∂F/∂q, energy), ``linalg`` (small dense solvers
that report failure instead of raising), ``assembly`` (initial states projected onto the
constraints, shared Schur-complement solves), ``statics`` (equilibrium, modes), ``contact``
(the contact force law of clearance joints that separate),
``tableaux`` (method coefficients and the adaptive step controller's constants),
``implicit`` (generalized-α time stepping), ``sincos`` (the branch-free sine/cosine of the
generated kernels). The lane kernels of the explicit methods are generated per topology by
:mod:`mcchain.codegen`.
"""
