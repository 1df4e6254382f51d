"""From an ensemble to a decision: requirements, failure probabilities, tolerance allocation.

:mod:`mcchain.decision.stats` holds the statistics (pure functions of counts and samples),
:mod:`mcchain.decision.requirements` the evaluation of ``[[requirement]]`` on an ensemble,
:mod:`mcchain.decision.summary` the per-requirement table ``mcchain export --requirements``
writes, :mod:`mcchain.decision.sequential` the interval of an ``until`` run (a confidence
sequence) and :mod:`mcchain.decision.until` the run that grows until decided. Nothing here
uses numba.
"""
