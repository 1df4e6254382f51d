"""Numba kernels: arrays and scalars in, arrays and status bits out. Never raise.

Modules: ``config`` (numba options), ``joints`` (constraints Φ, B, γ and their second
derivatives), ``forces`` (applied forces F, ∂F/∂q, energy), ``linalg`` (small dense solvers
that report failure instead of raising), ``statics`` (assembly, equilibrium, modes),
``lanes``/``integrators`` (time stepping).
"""
