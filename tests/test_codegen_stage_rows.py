"""codegen: the fixed-step kernel's stage rows (``mcchain.codegen.fixed_step``): each stage
writes its k into rows of its own, and the step's combine rounds as the loop kernel does; the
adaptive stage's state (``adaptive_step.stage_state_block``): y + h Σ a_sj k_j over the
stages its row of A reads, and no sum of the step multiplies a zero weight."""

from __future__ import annotations

import re

import numpy as np

from mcchain.codegen.adaptive_step import stage_state_block
from mcchain.codegen.fixed_step import fixed_step_blocks
from mcchain.codegen.generate import generate_source
from mcchain.codegen.layout import Layout
from mcchain.codegen.native import NativeModule
from mcchain.codegen.topology import Topology
from mcchain.kernels.config import fma
from mcchain.kernels.tableaux import DOPRI5, RK4
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


def test_combine__fuses_each_stage_into_the_sum_from_the_first_stage():
    """Compiled with contraction, the combine is bit for bit its stated chain (``dq =
    b₀h k₀``, then ``dq = fma(b_j h, k_j, dq)``; q + dq), signed zeros included; the loop
    kernel's order (each product rounded, then summed) differs on these data."""
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
    rounded_apart = 0
    for shift, state in ((0, "q"), (ndof, "v")):
        for i in range(ndof):
            for lane in range(LANES):
                ks = [before[(lay.rows[f"kq{j}"] + shift + i) * LANES + lane] for j in range(4)]
                bh = [float(b * hn) for b in bw]
                fused = np.float64(bh[0]) * np.float64(ks[0])
                for j in range(1, 4):
                    fused = fma(bh[j], ks[j], fused)
                x = before[(lay.rows[state] + i) * LANES + lane]
                got = W[(lay.rows[state] + i) * LANES + lane]
                assert np.float64(x + fused).tobytes() == np.float64(got).tobytes()
                dq = 0.0 + bh[0] * ks[0]
                for j in range(1, 4):
                    dq = dq + bh[j] * ks[j]
                rounded_apart += x + dq != got
    assert rounded_apart > 0  # the data tell the roundings apart


def test_adaptive_stage_state__each_stage_sums_only_the_stages_its_row_reads():
    """Compiled, the block writes stage s's state y + h Σ_j a_sj k_j into rows ys for every s
    (the first stage's: y itself), equal to the sum over the whole row of A (zeros included)
    within a rounding of its terms, and its branch names exactly the k_j of a_sj ≠ 0 (j < s);
    the stage's k goes to kq_s's rows (the first stage's to kqc's)."""
    topo = _topology()
    lay = Layout(topo, DOPRI5.nstage, LANES, adaptive=True)
    text = stage_state_block(topo, DOPRI5, lay)
    body = "\n".join("    " + line for line in text.splitlines())
    source = f"import numpy as np\n\n\ndef state(W, nl, s, A, out):\n{body}\n    out[0] = kw\n"
    module = NativeModule(source, "mcchain_test_stage_rows_adaptive_state")
    rng = np.random.default_rng(20261130)
    ndof = topo.ndof
    for s in range(DOPRI5.nstage):
        W = rng.normal(size=lay.size * LANES)
        h = rng.uniform(1e-6, 1e-3, size=LANES)
        W[lay.rows["hs"] * LANES : (lay.rows["hs"] + 1) * LANES] = h
        before = W.copy()
        kw = np.zeros(1, dtype=np.int64)
        module.state(W, LANES, s, np.ascontiguousarray(DOPRI5.A), kw)
        first = lay.rows["kqc"] if s == 0 else lay.rows[f"kq{s}"]
        assert kw[0] == first * LANES
        for r in range(2 * ndof):
            rows = [before[(lay.rows[f"kq{j}"] + r) * LANES : (lay.rows[f"kq{j}"] + r + 1) * LANES]
                    for j in range(DOPRI5.nstage)]  # fmt: skip
            y = before[(lay.rows["q"] + r) * LANES : (lay.rows["q"] + r + 1) * LANES]
            terms = [DOPRI5.A[s, j] * h * rows[j] for j in range(DOPRI5.nstage)]
            want = y + sum(terms)
            got = W[(lay.rows["ys"] + r) * LANES : (lay.rows["ys"] + r + 1) * LANES]
            scale = np.abs(y) + sum(np.abs(t) for t in terms)
            assert np.all(np.abs(got - want) <= 4e-16 * scale)
        branch = text.split(f"s == {s}:")[1].split("elif")[0]
        read = {int(j) for j in re.findall(r"ah(\d+) \*", branch)}
        assert read == {j for j in range(s) if DOPRI5.A[s, j] != 0.0}


def test_adaptive_step__no_sum_multiplies_a_zero_weight():
    """The rk45 text's new state and error sums name the stages of b ≠ 0 and b − b̂ ≠ 0 only
    (Dormand–Prince: k1 in neither, k6 not in b), and no stage's state reads the last stage
    (A's last column is zero)."""
    text = generate_source(_topology(), "rk45")
    assert re.findall(r"\bbw(\d+) = bw", text) == [str(j) for j in range(7) if DOPRI5.b[j]]
    errors = [str(j) for j in range(7) if DOPRI5.b_error[j]]
    assert re.findall(r"\bbe(\d+) = be", text) == errors
    assert "ah6" not in text and "aa6" not in text
