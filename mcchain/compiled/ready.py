"""What a run asks of the compile lifecycle: are its kernels ready, and what happens until
they are? (:meth:`Kernels.for_run`, once, before anything is written.)

The answer is one of three, and :class:`Kernels` carries it through the run:

* in the cache (a warm run): the warm-up (:meth:`Kernels.warm`) loads them;
* not yet compiled, and the run compiles them: with two cores a helper process compiles
  beside the scene check (:class:`mcchain.compiled.ahead.CompileAhead`); either way the
  compile notice says so at the start (:func:`announce_compile`), and the warm-up waits for
  the helper and loads or compiles the rest (:func:`compile_notice` times it);
* not yet compiled, and the run interprets them (a small statics run:
  :class:`mcchain.compiled.first_run.FirstRun`, chosen by the console script): its note
  says so and what compiles them for the next runs (:mod:`mcchain.compiled.background`).

What compiled the kernels a process ran is recorded with its results
(:func:`kernel_compiler`, :func:`kernel_target`, :func:`interpreted`).

This module imports only the standard library at import time.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mcchain.compiled.ahead import CompileAhead
    from mcchain.compiled.first_run import FirstRun
    from mcchain.model import Model
    from mcchain.runner.steps import SolveFn


@dataclass
class Kernels:
    """The kernels of one run (see the module's docstring).

    Attributes:
        compiled: the run solves with mcchain's kernels (not a test's solver or loader, not
            on Dask, whose workers warm their own): only then is the cache looked at.
        ahead: the helper process of a cold compiled run (None: warm, or not compiled here).
        first_run: the run interprets the kernels (None: it compiles or loads them).
        provenance: what compiled them, as the run records it (:func:`compiled_by`; set by
            :meth:`after_checks`).
    """

    compiled: bool = False
    ahead: CompileAhead | None = None
    first_run: FirstRun | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def for_run(
        cls,
        scene_path: str | Path,
        seed: int | None,
        samples: int | None,
        *,
        compiled: bool,
        first_run: FirstRun | None = None,
    ) -> Kernels:
        """The kernels of a new run of the scene at ``scene_path`` (with the run's ``--seed``
        and ``--samples``): on a cold cache, a compiled run reads the scene's keys (a bad
        one is refused here, in its one line), then starts its helper process and prints
        the compile notice, before the scene check compiles assembly."""
        if not compiled or first_run is not None:
            return cls(compiled, first_run=first_run if compiled else None)
        kernels = cls(compiled)
        if Path(scene_path).is_file():
            from mcchain.compiled.ahead import CompileAhead, assembly_is_cached

            if not assembly_is_cached():
                # A scene its keys refuse gets its one line alone, without the notice and
                # before a helper process starts on it (the keys need no compiled kernel).
                from mcchain.scene import load_scene

                load_scene(scene_path)
            kernels.ahead = CompileAhead.start(Path(scene_path), seed, samples)
            if kernels.ahead is not None:
                announce_compile(ahead=kernels.ahead.process is not None)
        return kernels

    def after_checks(
        self,
        kernels: str | None,
        nsample: int,
        scene_path: str | Path = "",
        seed: int | None = None,
        samples: int | None = None,
        background_off: str | None = None,
    ) -> tuple[list[str], list[str]]:
        """Once the run's checks passed: what compiled the kernels of its ``[simulate]
        kernels`` (``kernels``, None without ``[simulate]``) is noted in :attr:`provenance`,
        and what the run says of them is returned, as (warnings, notes): a background compile
        of this cache that failed (shown once, by the first compiled run after it); an
        interpreted run of ``nsample`` samples says so, and what compiles its kernels
        meanwhile (it may start that background compile now, with the run's scene, seed and
        samples: :func:`mcchain.compiled.background.background_note`; ``background_off``:
        what switched it off, ``--no-background-compile`` or the user's settings file)."""
        self.provenance = compiled_by(kernels)
        if not self.compiled:
            return [], []
        from mcchain.compiled.background import background_failure_note, background_note

        failed = background_failure_note()
        warnings = [] if failed is None else [failed]
        if self.first_run is None:
            return warnings, []
        background = background_note(Path(scene_path), seed, samples, background_off)
        return warnings, [self.first_run.note(nsample, background)]

    def warm(self, first: Model, scene: Any, solve: SolveFn) -> None:
        """Compile or load the kernels before the first chunk by solving ``first``, the
        first samples of the run (:func:`mcchain.runner.executors.warm_model`), after the
        helper process compiled its share; the compile notice if it takes long."""
        ahead = self.ahead
        with compile_notice(announced_at=None if ahead is None else ahead.started):
            if ahead is not None:
                ahead.compile_beside(first, scene)
                ahead.wait()
            solve(first, scene)

    def stop(self) -> None:
        """End the helper process if it still runs (the run failed before its warm-up)."""
        if self.ahead is not None:
            self.ahead.stop()


# -- the compile notice -------------------------------------------------------------------------

COMPILE_NOTICE_AFTER = 1.0
"""Seconds of kernel warm-up after which the compile notice is printed (a warm cache loads
in less, so a warm run prints nothing)."""


def kernel_cache_folders() -> str:
    """Where compiled kernels are kept, as the notice names them."""
    from mcchain.compiled.caches import mcchain_cache
    from mcchain.kernels.config import numba_cache

    return (
        f"numba: {numba_cache()} (NUMBA_CACHE_DIR); lane kernels: {mcchain_cache('native')} "
        "(MCCHAIN_CACHE_DIR)"
    )


@contextmanager
def compile_notice(
    after: float = COMPILE_NOTICE_AFTER, stream: Any = None, announced_at: float | None = None
) -> Iterator[None]:
    """Print one line on stderr if the block (the kernel warm-up) is still running after
    ``after`` seconds: what is compiled, that it happens once, and where it is cached; then
    how long it took. ``announced_at``: the line was printed then (:func:`announce_compile`),
    only the time is printed, counted from then."""
    import threading

    stream = sys.stderr if stream is None else stream
    t0 = time.perf_counter() if announced_at is None else announced_at
    said = threading.Event()
    if announced_at is not None:
        said.set()

    def say() -> None:
        said.set()
        announce_compile(stream)

    timer = threading.Timer(after, say)
    timer.daemon = True
    if announced_at is None:
        timer.start()
    try:
        yield
    finally:
        timer.cancel()
        if announced_at is None:
            timer.join()  # a notice being printed ends before the ready line
        if said.is_set():
            print(f"kernels ready in {time.perf_counter() - t0:.1f} s", file=stream, flush=True)


def announce_compile(stream: Any = None, ahead: bool = False) -> None:
    """The compile notice's line (``ahead``: two processes compile, see
    :mod:`mcchain.compiled.ahead`)."""
    how = " (in two processes)" if ahead else ""
    print(
        f"compiling the kernels of this scene's analyses and topology{how}: once per "
        f"installation and topology, then loaded from the cache ({kernel_cache_folders()})",
        file=sys.stderr if stream is None else stream,
        flush=True,
    )


# -- what compiled them ---------------------------------------------------------------------------


def interpreted() -> bool:
    """Whether this process runs the kernels interpreted (:mod:`mcchain.compiled.first_run`)."""
    from mcchain.kernels import config

    return config.INTERPRETED


def kernel_compiler(kernels: str | None) -> str:
    """What compiled the kernels this process runs for a run on ``kernels`` (its ``[simulate]
    kernels``, None without ``[simulate]``), as ``run.json``'s sessions and the ensemble's
    attributes record it: ``"interpreted"`` (:mod:`mcchain.compiled.first_run`: plain
    Python, no compile), ``"native"`` (the generated lane kernels of a ``[simulate]`` on
    ``kernels = "lanes"`` through :mod:`mcchain.codegen.native`) or ``"numba"`` (the
    hand-written kernels, and the lane kernels with ``MCCHAIN_LANE_COMPILER=numba`` or
    where this NumPy's layout sends them to numba: their last bits may differ)."""
    if interpreted():
        return "interpreted"
    if kernels is None or kernels == "loop":
        return "numba"
    from mcchain.codegen.native import lane_compiler

    return lane_compiler()


def kernel_target(kernels: str | None) -> dict[str, Any] | None:
    """The CPU the generated lane kernels were generated and compiled for (their text
    depends on its SIMD width: :func:`mcchain.codegen.layout.target_cpu`), or None where
    the run on ``kernels`` uses none."""
    if interpreted() or kernels is None or kernels == "loop":
        return None
    import hashlib

    from mcchain.codegen.layout import LMAX, target_cpu

    name, features = target_cpu()
    digest = hashlib.sha256(features.encode()).hexdigest()[:16]
    return {"cpu": name, "features_sha256": digest, "lane_width": LMAX}


def compiled_by(kernels: str | None) -> dict[str, Any]:
    """What compiled the kernels of a run on ``kernels`` in this process, as its session of
    ``run.json`` records it: ``kernels_interpreted``, ``kernel_compiler``, ``kernel_target``."""
    return {
        "kernels_interpreted": interpreted(),
        "kernel_compiler": kernel_compiler(kernels),
        "kernel_target": kernel_target(kernels),
    }
