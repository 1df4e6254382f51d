"""The fixed-step kernel's stage rows (templates.ERK_KERNEL): where a stage's k goes, who reads it.

Stage s writes its k = (q', v') = (v, q̈) once, into rows of its own (kq{s}, kv{s}; the stage
loop's ``kw``); the next stage, and the turning loop before it, read the previous stage's
rows (``kr``); the step's combine forms the increment from the rows of all the stages, so
the stage stores each k once (its body is bound by its stores:
benchmarks/results/roofline/reading.md).
"""

from __future__ import annotations

from mcchain.codegen.layout import Layout
from mcchain.codegen.topology import Topology

FIXED_STEP_VARIANTS = ("rk4", "rk4-projection")
"""The variants whose module is the fixed-step kernel (templates.ERK_KERNEL)."""


def fixed_step_blocks(topo: Topology, nstage: int, lay: Layout) -> dict[str, str]:
    """Blocks ``load_stage_sub`` (the stage's state, from the previous stage's k),
    ``combine_coefs`` and ``combine`` (the step's new state) of the fixed-step kernel.

    The combine rounds as the loop kernel does (mcchain.kernels.explicit, uncontracted):
    each p_j = b_j h k_j rounded on its own, the sum from the first stage on, then the
    state plus the sum, q + (((p0 + p1) + p2) + p3), every row alike. ``fma(b, k, 0.0)``
    is that rounded product in a form LLVM cannot fuse into the sum (a product ``b * k``
    would be: ``fastmath={"contract"}``): b·k rounded, +0.0 where it is −0.0, as the loop
    kernel's 0.0 + b h k (tests/test_codegen_stage_rows.py).
    """
    ndof = topo.ndof
    load = []
    for i in range(ndof):
        load += [
            f"q{i} = {lay.at('q', i)} + ah * {lay.stage_at(i, 'kr')}",
            f"v{i} = {lay.at('v', i)} + ah * {lay.stage_at(ndof + i, 'kr')}",
        ]
    base = [lay.rows[f"kq{j}"] for j in range(nstage)]
    combine = []
    for x, shift in (("q", 0), ("v", ndof)):
        for i in range(ndof):
            terms = [f"fma(bh{j}, W[{(base[j] + shift + i) * lay.lmax} + l], 0.0)"
                     for j in range(nstage)]  # fmt: skip
            total = terms[0]
            for term in terms[1:]:
                total = f"({total} + {term})"
            combine.append(f"{lay.at(x, i)} = {lay.at(x, i)} + {total}")
    return {
        "load_stage_sub": "\n".join(load),
        "combine_coefs": "\n".join(f"bh{j} = bw[{j}] * hn" for j in range(nstage)),
        "combine": "\n".join(combine),
    }
