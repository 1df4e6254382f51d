"""The run: plan, execute, store (see :mod:`mcchain.runner.pipeline`)."""
