"""codegen: the fixed-step kernel's stage rows (``mcchain.codegen.fixed_step``): each stage
writes its k into rows of its own, and the step's combine rounds as the loop kernel does."""

from __future__ import annotations

import numpy as np

from mcchain.codegen.fixed_step import fixed_step_blocks
from mcchain.codegen.layout import Layout
from mcchain.codegen.native import NativeModule
from mcchain.codegen.topology import Topology
from mcchain.kernels.config import fma
from mcchain.kernels.tableaux import RK4
from mcchain.testing.scenes import DOUBLE_PENDULUM, model_of, straight_chain_text

LANES = 16


def _topology() -> Topology:
    text = straight_chain_text(**DOUBLE_PENDULUM, clearance={1: 5e-4})
    return Topology.from_model(model_of(text, nsample=4))


def _combine_module(topo: Topology, lay: Layout) -> NativeModule:
    """The generated combine (its coefficients, then the lane loop) as a function of its own,
    compiled as the lane kernels are (``contract``: products may fuse into sums)."""
    blocks = fixed_step_blocks(topo, RK4.nstage, lay)
    body = "\n".join("        " + line for line in blocks["combine"].splitlines())
    coefs = "\n".join("    " + line for line in blocks["combine_coefs"].splitlines())
    source = (
        "import numpy as np\nfrom mcchain.kernels.config import fma\n\n\n"
        f"def combine(W, bw, hn, nl):\n{coefs}\n"
        f"    for l in range(nl):  # lanes: independent\n{body}\n"
    )
    return NativeModule(source, "mcchain_test_stage_rows_combine")


def test_layout__the_fixed_steps_stage_rows_are_where_the_kernel_reads_them():
    """The template's offsets: stage j's rows at kq0 + 2 ndof j, its v' rows ndof after its
    q' rows; no rows of a current stage or an accumulated increment."""
    topo = _topology()
    lay = Layout(topo, RK4.nstage, LANES, fixed_step=True)
    for j in range(RK4.nstage):
        assert lay.rows[f"kq{j}"] == lay.rows["kq0"] + 2 * topo.ndof * j
        assert lay.rows[f"kv{j}"] == lay.rows[f"kq{j}"] + topo.ndof
    assert not {"kqc", "kvc", "aq", "av"} & set(lay.rows)
    assert {"kqc", "kvc"} <= set(Layout(topo, RK4.nstage, LANES, adaptive=True).rows)
    assert lay.stage_at(topo.ndof + 1, "kr") == f"W[kr + {(topo.ndof + 1) * LANES} + l]"


def test_combine__rounds_each_product_then_sums_from_the_first_stage():
    """Compiled with contraction, the combine is bit for bit the loop kernel's order
    (``dq = 0.0 + b₀h k₀``, then ``dq = dq + b_j h k_j``, each product rounded; q + dq),
    signed zeros included; the fused forms LLVM could have chosen differ on these data."""
    topo = _topology()
    lay = Layout(topo, RK4.nstage, LANES, fixed_step=True)
    rng = np.random.default_rng(20261129)
    W = rng.normal(size=lay.size * LANES) * np.exp(rng.normal(scale=4.0, size=lay.size * LANES))
    W[rng.random(W.size) < 0.05] = -0.0
    W[rng.random(W.size) < 0.05] = 0.0
    hn = 1e-4 / 3.0
    bw = np.asarray(RK4.b, dtype=float)
    before = W.copy()
    _combine_module(topo, lay).combine(W, bw, hn, LANES)

    ndof = topo.ndof
    fused_apart = 0
    for shift, state in ((0, "q"), (ndof, "v")):
        for i in range(ndof):
            for lane in range(LANES):
                ks = [before[(lay.rows[f"kq{j}"] + shift + i) * LANES + lane] for j in range(4)]
                bh = [float(b * hn) for b in bw]
                dq = 0.0 + bh[0] * ks[0]
                for j in range(1, 4):
                    dq = dq + bh[j] * ks[j]
                x = before[(lay.rows[state] + i) * LANES + lane]
                got = W[(lay.rows[state] + i) * LANES + lane]
                assert np.float64(x + dq).tobytes() == np.float64(got).tobytes()
                fused = fma(bh[0], ks[0], 0.0)
                for j in range(1, 4):
                    fused = fma(bh[j], ks[j], fused)
                fused_apart += x + fused != got
    assert fused_apart > 0  # the data tell the roundings apart
