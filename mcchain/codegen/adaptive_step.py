"""The adaptive kernel's step rows (templates.ADAPTIVE_KERNEL, STAGE_HELPER): the stage's state,
the step's new state and its error norm.

Each sum names only the stages of a nonzero coefficient (an explicit tableau's last column of
A is zero; Dormand–Prince's b_1, b_6 and b_1 − b̂_1 are zeros): a stage sums the stages its
row of A reads, in a branch of its own, into rows ys before its lane loop; its k goes to its
rows kq_s, kv_s at the run-time offset ``kw``. The new state and the norm are two lane loops
(in one, the compiler kept each k it loaded for both sums on the stack). Coordinates the
stage writes in closed form (``prescribed``: :meth:`mcchain.codegen.emitter.Emitter.
prescribed_coordinates`) take their new state from the last stage's rows ys (its node is
1: the step's end) and are not in the norm (their error is zero).
benchmarks/results/verdict/combine.md.
"""

from __future__ import annotations

from collections.abc import Collection

from mcchain.codegen.layout import Layout
from mcchain.codegen.topology import Topology
from mcchain.kernels.tableaux import Tableau


def stage_state_block(
    topo: Topology, tableau: Tableau, lay: Layout, prescribed: Collection[int] = ()
) -> str:
    """Block ``stage_state`` of the adaptive stage: ``kw``, the offset of the rows its k goes
    to (stage 0's: kqc, which the first stage copies to kq0 for the lanes it starts; stage
    s's: kq_s), and y + h Σ_j a_sj k_j into rows ys for every lane, in a branch per stage
    summing the j < s of a_sj ≠ 0 in the order of j; not the ``prescribed`` columns' q and v
    (the stage writes them)."""
    nstage, ndof = tableau.nstage, topo.ndof
    at = lay.at
    summed = [r for r in range(2 * ndof) if r % ndof not in prescribed]  # q then v rows
    first = f"{lay.rows['kq0']} + {2 * ndof} * s if s > 0 else {lay.rows['kqc']}"
    lines = [f"kw = ({first}) * {lay.lmax}"]
    for s in range(nstage):
        read = [j for j in range(s) if tableau.A[s, j]]
        lines += [f"{'if' if s == 0 else 'elif'} s == {s}:"]
        lines += [f"    aa{j} = A[s, {j}]" for j in read]
        lines += ["    for l in range(nl):  # lanes: independent"]
        lines += [f"        ah{j} = aa{j} * {at('hs')}" for j in read]
        for r in summed:  # kq_j then kv_j: 2 ndof rows each, as q then v
            terms = " + ".join(f"ah{j} * {at(f'kq{j}', r)}" for j in read)
            total = f"{at('q', r)} + ({terms})" if read else at("q", r)
            lines.append(f"        {at('ys', r)} = {total}")
    return "\n".join(lines)


def step_blocks(
    topo: Topology, tableau: Tableau, lay: Layout, prescribed: Collection[int] = ()
) -> dict[str, str]:
    """Blocks ``error_coefs``, ``new_state`` and ``error_norm`` of the adaptive step: the
    weights read, y_new = y + h Σ b_j k_j into rows qn (the ``prescribed`` columns' from the
    last stage's rows ys), and the error norm (scaled as scipy's RK45: atol + rtol·max(|y|,
    |y_new|)) over q0, v0, q1, v1, ... into row en, every lane at once (per lane the same
    operations in the same order as one lane alone). An ideal copy (Topology.reference)
    follows the mechanism's steps: its rows are not in the norm (its terms would be exact
    zeros of the sum), so the mechanism steps as it would alone; nor are the prescribed
    columns', and the sum is still divided by all of the mechanism's rows."""
    nstage, ndof = tableau.nstage, topo.ndof
    at = lay.at
    stride = 2 * ndof
    weights = [j for j in range(nstage) if tableau.b[j]]
    b_error = tableau.b_error
    errors = [] if b_error is None else [j for j in range(nstage) if b_error[j]]
    coefs = [f"bw{j} = bw[{j}]" for j in weights] + [f"be{j} = be[{j}]" for j in errors]
    new = [f"hh = {at('hs')}"]
    for i in range(2 * ndof):
        r = (i % 2) * ndof + i // 2
        if r % ndof in prescribed:
            new.append(f"{at('qn', r)} = {at('ys', r)}")
            continue
        terms = " + ".join(f"bw{j} * {at('kq0', r + stride * j)}" for j in weights)
        new.append(f"{at('qn', r)} = {at('q', r)} + hh * ({terms})")
    own = 3 * topo.own_bodies
    norm = [f"hh = {at('hs')}", "en = 0.0"]
    for i in range(2 * own):
        r = (i % 2) * ndof + i // 2
        if r % ndof in prescribed:
            continue
        terms = " + ".join(f"be{j} * {at('kq0', r + stride * j)}" for j in errors)
        scale = f"atol + rtol * max(abs({at('q', r)}), abs({at('qn', r)}))"
        norm += [f"e{i} = hh * ({terms}) / ({scale})", f"en = en + e{i} * e{i}"]
    norm += [f"en = math.sqrt(en / {2 * own})", f"{at('en')} = en if en == en else np.inf"]
    return {
        "error_coefs": "\n".join(coefs),
        "new_state": "\n".join(new),
        "error_norm": "\n".join(norm),
    }
