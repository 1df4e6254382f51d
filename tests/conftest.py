"""Test-wide settings.

Processes the tests start never run their kernels interpreted on a cold cache
(``MCCHAIN_INTERPRET_COLD=0``) nor start the compile-ahead helper
(``MCCHAIN_COMPILE_AHEAD=0``), unless a test asks for it.

mcchain's cache (``MCCHAIN_CACHE_DIR``: native machine code, generated text, designs) is a
temporary folder of the session unless the environment names one (``.ci/run`` does, to keep
it between CI runs): a test never writes to the developer's ``~/.cache/mcchain``.

Hypothesis: under CI (``CI`` set, as ``.ci/run`` does) every property test is derandomized,
so a CI run cannot fail on a draw that a developer's run never made; the example database is
off there too. Developers' runs keep random draws (and the database) to find new failures.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

# A ``mcchain run`` the tests start as a process keeps the compiled kernels, whatever the
# cache holds: the interpreted first run (mcchain.compiled.first_run) has tests of its own.
os.environ.setdefault("MCCHAIN_INTERPRET_COLD", "0")
# Nor does a run on a cold cache start the compile-ahead helper process
# (mcchain.compiled.ahead): the suite's workers keep both cores busy, so a third process
# compiling beside them only adds its start (about 2 s of CPU) and, where it meets a kernel
# another worker is compiling, that compile again (a cold profile: 12.8 s of CPU in the
# helper of test_decision_whatif's first run). test_compile_ahead turns it on where it
# checks it.
os.environ.setdefault("MCCHAIN_COMPILE_AHEAD", "0")


def pytest_configure(config: pytest.Config) -> None:
    """mcchain's bytecode written once, by the run's first process (xdist's controller, or the
    only one): an installed package has it (pip and uv write it), an editable checkout gets
    it at its first import, unless ``PYTHONDONTWRITEBYTECODE`` is set (this project's machines
    set it), when every process the suite starts (its workers, the runs it starts as
    processes, Dask's workers) would compile mcchain's modules from source again: about
    0.1-0.3 s of CPU each. Python reads bytecode whatever that variable says."""
    if hasattr(config, "workerinput"):  # an xdist worker: the controller has written it
        return
    import compileall

    import mcchain

    compileall.compile_dir(Path(mcchain.__file__).parent, quiet=1)


LONGEST_FIRST = (
    "test_contact_start.py",  # first compiles: assembly, radau, the loop kernels, generalized-α
    # meanwhile, on the other worker: files that load no kernel (the statistics of the
    # decisions, runs of a fake solver, generated text), about 30 s of CPU, so that the two
    # workers do not compile the same kernels at once: test_contact_start compiles the
    # assembly kernel first (12-25 s), which test_decision_whatif's run needs too
    "test_decision_allocation.py",
    "test_runs_fakes.py",
    "test_codegen_golden.py",
    "test_layering.py",
    "test_decision_sequential.py",
    "test_decision_stats.py",
    "test_decision_whatif.py",  # a run of the pinned bar: assembly (loaded), modes
    "test_runs_pipeline.py",  # end to end through the command line, Dask, kills, memory
    "test_native.py",  # numba's compile of a lane module (the reference of the native compiler)
    "test_outputs_reference.py",  # minimal-coordinate (sympy, scipy) references
    "test_runs_histories.py",
    "test_validate_interpreted.py",
    "test_compile_ahead.py",  # a cold run in a process of its own, on an empty cache
    "test_decision_subset.py",  # its rare events on a bar solve statics (assembly: compiled)
    "test_outputs_shared_ideal.py",
    "test_simulate_accuracy.py",
    "test_slider_drivers.py",
    "test_simulate_methods.py",
    "test_contact_dynamics.py",
    "test_radau.py",
    "test_peaks.py",
    "test_simulate_stability.py",
    "test_viz_report_page.py",
    "test_outputs_scene.py",
    "test_scene_configs.py",
    "test_simulate_grid.py",
    "test_decision_requirements.py",
)
"""Test files in the order they start, before all others (in collection order), ranked by
the CPU time of a cold run (benchmarks/results/ci/ci.md), but that the second worker starts
with files that compile nothing while the first compiles the kernels most files share: two
workers compiling the same kernel at once each pay its whole compile (the Radau kernel, 20 s,
when test_native's Radau check started beside test_contact_start). ``--dist loadfile`` hands
each worker the next file when it is free: the longest files started last kept one worker
busy minutes after the other had finished; started first, the short files fill the gap.
xdist itself would reorder files by their number of tests (its ``--loadscope-reorder``, on by
default, which ran the few-test long files last): pyproject's ``--no-loadscope-reorder``
keeps this order. Order only: each file's tests run as they would alone."""


LONG_HINT = "python -m pytest -q --long -m long"
"""The command that runs the long references alone (README, Development)."""


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--long",
        action="store_true",
        help=f"also run the long references (marked long; alone: {LONG_HINT})",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Leave out the long references unless ``--long`` is given (deselected, counted in the
    summary and named at its end: never silently), then run :data:`LONGEST_FIRST`'s files
    first, in that order (a stable sort: the tests of a file keep their order, the other
    files theirs).

    A test marked ``long`` repeats at length a check that a shorter test of the default run
    makes too (e.g. the same integration over a tenth of the horizon): leaving it out drops
    no behaviour from the default run, only the long horizon."""
    if not config.getoption("--long"):
        long = [item for item in items if item.get_closest_marker("long")]
        if long:
            config.hook.pytest_deselected(items=long)
            items[:] = [item for item in items if not item.get_closest_marker("long")]
            config.stash[_LONG_LEFT_OUT] = len(long)
            if hasattr(config, "workeroutput"):  # an xdist worker: tell the controller
                config.workeroutput["long_left_out"] = len(long)

    def rank(item: pytest.Item) -> int:
        name = item.path.name
        return LONGEST_FIRST.index(name) if name in LONGEST_FIRST else len(LONGEST_FIRST)

    items.sort(key=rank)


_LONG_LEFT_OUT = pytest.StashKey[int]()


@pytest.hookimpl(optionalhook=True)  # pytest-xdist's hook
def pytest_testnodedown(node: Any, error: Any) -> None:
    """xdist's controller: each worker collected the same tests and left out as many."""
    left_out = getattr(node, "workeroutput", {}).get("long_left_out", 0)
    if left_out:
        node.config.stash[_LONG_LEFT_OUT] = left_out


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    left_out = config.stash.get(_LONG_LEFT_OUT, 0)
    if left_out:
        terminalreporter.write_line(
            f"long references deselected: {left_out} (shorter tests check the same; "
            f"run them: {LONG_HINT})"
        )


@pytest.fixture(scope="session", autouse=True)
def _temporary_mcchain_cache(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """``MCCHAIN_CACHE_DIR`` in a temporary folder where the environment sets none (the
    module's docstring); the processes the tests start inherit it.

    One folder for the whole run, shared by its xdist workers (``pytest-N/mcchain-cache``,
    beside the workers' own ``popen-gw*`` folders): a scene's lane kernels compiled by one
    worker are loaded by the others instead of compiled again. Sharing is safe: every cache
    file is written to a temporary name and renamed into place (:mod:`mcchain.codegen.cache`,
    :mod:`mcchain.codegen.native`), so a reader sees a whole file or none, and two writers
    of one key write the same bytes."""
    if os.environ.get("MCCHAIN_CACHE_DIR"):
        yield
        return
    if os.environ.get("PYTEST_XDIST_WORKER"):
        # the run's folder (pytest-of-<user> is private to the user: mode 0700)
        folder = tmp_path_factory.getbasetemp().parent / "mcchain-cache"
        folder.mkdir(exist_ok=True)
    else:
        folder = tmp_path_factory.mktemp("mcchain-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("MCCHAIN_CACHE_DIR", str(folder))
        yield


@pytest.fixture
def dask_scheduler(_temporary_mcchain_cache: Any) -> Any:
    """The address of a Dask cluster for one test's runs on an existing scheduler: two
    process workers, one compute thread each (the environment ``--dask local`` gives its
    workers), closed at the end of the test. A cluster costs about 5 s of CPU to start (two
    interpreters importing distributed, numba and xarray) and its workers and scheduler
    keep ticking while it idles (about 8 s of CPU a minute here): a test's runs share one,
    and none outlives its test. The workers inherit this process's environment (the
    session's ``MCCHAIN_CACHE_DIR``)."""
    import logging

    from dask.distributed import LocalCluster

    from mcchain.runner.executors import WORKER_ENV

    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        # its scheduler's HTTP server on a free port, not the default 8787 that a
        # cluster started beside it (``--dask local``) would then move with a warning
        scheduler_kwargs={"dashboard_address": ":0"},
        env=dict(WORKER_ENV),
        silence_logs=logging.ERROR,
    ) as cluster:
        yield cluster.scheduler_address


@pytest.fixture
def mcchain(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> Callable[..., Any]:
    """The CLI run in this process: ``mcchain(*args, cwd=...)`` returns its exit code and
    output (:func:`test_cli_commands.in_process`)."""
    from test_cli_commands import in_process

    return in_process(monkeypatch, capsys)
