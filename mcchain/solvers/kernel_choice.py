"""Which kernels integrate a run: ``[simulate] kernels = "auto"`` resolved by a cost model
(the lanes' compile time of a new topology against the loop kernels' extra time per step),
its constants fitted on this project's benchmark machine (``benchmarks/bench_loop.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from mcchain.scene.models import LOOP_METHODS, Simulate

LANE_COMPILE_S_PER_COORDINATE = 0.03
LANE_COMPILE_S_PER_COORDINATE_SQUARED = 0.46e-3
"""Seconds the first run of a new topology spends compiling its rk4 lanes beyond what the
loop kernels need: these two per coordinate (3 per body) and per squared coordinate count,
summed. Fitted to chains of 32 and 64 bars (``benchmarks/bench_loop.py``, 2 cores: 7.1 s
and 22.6 s), within 0.4 s of 16 and 48 bars. The square is LLVM's loop vectoriser, whose
work grows with the square of a stage loop's length."""

LOOP_EXTRA_S_PER_COORDINATE_STEP = 0.27e-6
"""Seconds the loop kernels take beyond the lanes per instance-step, per coordinate:
0.22-0.30 µs for chains of 16-64 bars (same benchmark)."""

AUTO_LOOP_MIN_COMPILE_S = 20.0
"""``kernels = "auto"`` considers the loop kernels only for topologies whose lanes would
compile longer than this: the issue's budget for the first run of a new topology."""

AUTO_LOOP_SHARE = 0.25
"""... and only for runs whose extra time on the loop kernels stays under this share of
that compile, so that rerunning the topology on the loop costs little against compiling
its lanes once (which later runs would reuse)."""


@dataclass(frozen=True)
class KernelChoice:
    """The kernels that integrate a run, and why (one line for the user); ``auto``: chosen
    by ``kernels = "auto"``, not written in the scene."""

    kernels: str
    reason: str
    auto: bool = True

    def note(self) -> str | None:
        """The line a run prints when ``auto`` took the loop kernels (None otherwise)."""
        if self.kernels != "loop" or not self.auto:
            return None
        return (
            f'simulate.kernels: "loop" ({self.reason}); kernels = "lanes" compiles the '
            "lanes once for this topology, the fastest per step"
        )


def choose_kernels(sim: Simulate, ndof: int, nsample: int) -> KernelChoice:
    """Resolve ``[simulate] kernels`` for a run of ``nsample`` instances of ``ndof``
    coordinates. ``"lanes"`` and ``"loop"`` stay as written; ``"auto"`` follows the cost
    model of the constants above. The choice depends on the scene and the sample count only,
    never on what a cache holds, so that a run, its resume and a Dask run agree."""
    if sim.kernels != "auto":
        return KernelChoice(sim.kernels, "as set in the scene", auto=False)
    if sim.method not in LOOP_METHODS:
        return KernelChoice("lanes", f"auto: {sim.method} runs on the lanes only")
    compile_s = (
        LANE_COMPILE_S_PER_COORDINATE * ndof + LANE_COMPILE_S_PER_COORDINATE_SQUARED * ndof**2
    )
    work = nsample * max(1, round(sim.t_end / sim.dt))
    extra_s = LOOP_EXTRA_S_PER_COORDINATE_STEP * ndof * work
    estimate = (
        f"the lanes of {ndof} coordinates compile in about {compile_s:.0f} s; "
        f"{work:.3g} instance-steps take about {extra_s:.2g} s more on the loop"
    )
    if compile_s <= AUTO_LOOP_MIN_COMPILE_S or extra_s >= AUTO_LOOP_SHARE * compile_s:
        return KernelChoice("lanes", f"auto: {estimate}")
    return KernelChoice("loop", f"auto: {estimate}")
