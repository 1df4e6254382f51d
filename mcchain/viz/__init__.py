"""Looking at results: rerun playback of samples and report plots of an ensemble.

* :mod:`mcchain.viz.playback` — ``mcchain show`` and :func:`~mcchain.viz.playback.log_samples`
  (also used to stream samples live during ``mcchain run --rerun``);
* :mod:`mcchain.viz.report` — ``mcchain report``: matplotlib PNGs and Sobol indices;
* :mod:`mcchain.viz.geometry` — body outlines and world positions from a Model.

rerun, matplotlib and SALib are imported only when a figure or recording is made.
"""
