"""Looking at results: rerun playback of samples and report plots of an ensemble.

* :mod:`mcchain.viz.playback` — a sample in rerun: :func:`~mcchain.viz.playback.log_samples`,
  the default layout and the recording's sink; :mod:`mcchain.viz.show` — ``mcchain show``:
  :func:`~mcchain.viz.show.show_run`;
* :mod:`mcchain.viz.live` — ``mcchain run --rerun``: the samples of each chunk streamed to
  rerun while the run computes them, drawn as ``mcchain show`` draws them;
* :mod:`mcchain.viz.report` — ``mcchain report``: matplotlib PNGs and Sobol indices;
* :mod:`mcchain.viz.geometry` — body outlines and world positions from a Model;
* :mod:`mcchain.viz.contact` — per joint its model and state over time, the journal orbit;
  :mod:`mcchain.viz.report_contact`, :mod:`mcchain.viz.history` — the report's contact and
  time-history figures (helpers in :mod:`mcchain.viz.figures`).

The sample queries both commands share live in :mod:`mcchain.ensemble.queries`, the model
of a run's samples in :mod:`mcchain.ensemble.describe`. rerun, matplotlib and SALib are
imported only when a figure or recording is made.
"""
