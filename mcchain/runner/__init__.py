"""The run: plan, execute, store (see :mod:`mcchain.runner.pipeline`)."""

DEFAULT_OUT = "runs"
"""The folder of run folders (``mcchain run --out``, ``mcchain runs --out``)."""
