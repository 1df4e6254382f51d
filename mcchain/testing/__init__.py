"""What the tests and the benchmarks share: scenes, closed forms, dense references.

* :mod:`~mcchain.testing.factory` — one seeded factory of scenes (random chains, the seed bar);
* :mod:`~mcchain.testing.scenes` — named scenes (swinging bar, four-bar, double pendulums,
  parallelogram, straight chains);
* :mod:`~mcchain.testing.closed_forms` — analytic answers;
* :mod:`~mcchain.testing.dense` — slow, obvious dense NumPy/SciPy references;
* :mod:`~mcchain.testing.minimal` — minimal-coordinate references (sympy, test extra);
* :mod:`~mcchain.testing.contact` — the contact law's independent scipy reference (radial
  impact, free journal in a bearing, event-located onsets);
* :mod:`~mcchain.testing.comparisons` — which fast result is held to which reference, and how
  closely: one table for the tests' assertions and the benchmarks' error axes.

Nothing here is imported by the rest of the package.
"""
