"""The compile lifecycle: where compiled kernels are kept, and getting them ready for a run.

A run asks it one question, once, before anything is written: are my kernels ready, and
what happens until they are? (:meth:`mcchain.compiled.ready.Kernels.for_run`; the answer
warms them before the first chunk and says what compiled them.) Behind it:

* :mod:`~mcchain.compiled.caches` — mcchain's cache folders, and whether numba's cache holds
  a kernel (without importing numba);
* :mod:`~mcchain.compiled.ahead` — a cold compiled run: a helper process compiles beside the
  scene check; ``mcchain cache warm``;
* :mod:`~mcchain.compiled.first_run` — a cold small statics run goes interpreted, chosen by
  a probe of how long it would take;
* :mod:`~mcchain.compiled.background` — meanwhile, a detached process compiles the kernels
  for the next runs;
* :mod:`~mcchain.compiled.report` — ``mcchain cache status`` and ``clear``.

The kernels themselves never import this package (their numba settings, cache folder
included, are :mod:`mcchain.kernels.config`'s).
"""
