"""The run as one pipeline: plan -> execute -> store, with observers and solve steps.

Read it top to bottom:

* **plan** (:mod:`~mcchain.runner.plan`): ``start_run``, ``resume_run`` and ``extend_run``
  check everything before anything is written — the job (:mod:`~mcchain.runner.job`: scene,
  model, settings), the disk (:mod:`~mcchain.runner.resources`), the kernels (the compile
  lifecycle, :mod:`mcchain.compiled`, answers one question: :class:`mcchain.compiled.ready.
  Kernels`) — then make the run folder (:mod:`~mcchain.runner.runs`) and a
  :class:`~mcchain.runner.pipeline.Plan`: the job, the folder, the observers in order
  (:func:`~mcchain.runner.observers.observers_for`), where and how chunks are solved.
* **execute** (:mod:`~mcchain.runner.executors`): the chunks the folder lacks are solved here
  or on Dask, each handed to the store, then to the observers.
* **store** (:mod:`~mcchain.runner.store`): part files, their merge into ``ensemble.nc``,
  ``run.json`` (and the failure of a run that fails, keeping its finished chunks); what the
  run says at its end is :mod:`~mcchain.runner.summary`'s, from ``run.json``.

:func:`~mcchain.runner.pipeline.run_pipeline` is the loop; it calls the observers at fixed
points and they never call back into it (:mod:`~mcchain.runner.steps` is the protocol).

Where a new part goes:

* **Something that watches the run** (a progress display, a live view, a summary, a check
  that the run needs more samples): an :class:`~mcchain.runner.steps.Observer` subclass that
  overrides the hooks it needs (``on_start``, ``on_chunk_done``, ``more_samples``,
  ``on_chunks_done``, ``on_merged``), added to the list of
  :func:`~mcchain.runner.observers.observers_for` (in its module if it belongs to another
  package, as :class:`mcchain.viz.live.LiveRun` and :class:`mcchain.decision.until.Until`
  do). It may keep its own entry of ``run.json`` up to date (``run.record``,
  ``run.session``); the pipeline writes the file. For example, the count of samples seen::

      class SamplesSeen(Observer):
          def on_start(self, run):
              run.session["samples_seen"] = 0

          def on_chunk_done(self, run, chunk):
              run.session["samples_seen"] += chunk.stop - chunk.start

  (Moving the files made before an ``--extend`` aside is such an observer, with
  ``on_merged``, in the list ``extend_run`` makes: :class:`mcchain.runner.stale.Extension`.)
* **Something that completes a chunk's solve** where the solve runs (this process or a Dask
  worker), e.g. solving the failed samples of a chunk again at a tighter tolerance: a
  :data:`~mcchain.runner.steps.SolveStep`, ``step(model_chunk, scene, outputs) -> outputs``
  (picklable), in the plan's ``solve_steps`` (:func:`~mcchain.runner.observers.
  solve_steps_for`; the retry of failed samples, :class:`mcchain.solvers.retry.RetryFailed`,
  is one); what it returns is what the store writes and
  the observers see. (Outputs relative to the ideal mechanism are part of the solve itself:
  :func:`mcchain.solvers.solve_chunk`.)
* **Something about what is stored** (as ``[storage] histories = "none" | "failed"``,
  :func:`~mcchain.runner.store.kept_histories`): the store's
  :class:`~mcchain.runner.store.PartWriter`, which makes each part file's variables, and the
  disk estimate that counts them (:func:`~mcchain.runner.resources.stored_sample_bytes`);
  what readers make of it, in :mod:`mcchain.ensemble.histories`.

The modules import only the standard library at import time (``mcchain runs`` and
``mcchain --help`` never compile a kernel); each stage imports what it needs when it comes.
See ``docs/architecture.md`` for the package as a whole.
"""

DEFAULT_OUT = "runs"
"""The folder of run folders (``mcchain run --out``, ``mcchain runs --out``)."""
