"""Time-stepping kernels: method coefficients (data) and the batch kernels of every method.

Two kinds of kernels live here:

* **Lane kernels, generated per topology** (explicit Runge–Kutta with fixed steps, with or
  without projection; embedded Runge–Kutta with per-sample step control). The templates
  below hold the time loop; :class:`~mcchain.kernels.lanes.Emitter` fills in the
  straight-line evaluation of one lane. :func:`lane_kernels` returns the compiled module of a
  topology (cached on disk, see :func:`mcchain.kernels.lanes.load_module`).
* **Per-sample kernels** (generalized-α, index 3): one sample per ``prange`` iteration, built
  on the per-sample kernels of ``joints.py``/``forces.py``/``linalg.py``.

Rules every kernel keeps (PERFORMANCE.md, STYLE.md): no allocation inside time loops, no
reduction across samples (sample i's history is bit-identical alone, in any chunk, on any
thread count), never raise — failures set status bits with the time they happened and the
sample's state becomes NaN from then on (outputs after that time are NaN).
"""

from __future__ import annotations

import heapq
import math
import re
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numba import njit, prange

from mcchain.kernels.config import JIT, PJIT
from mcchain.kernels.forces import (
    applied_forces,
    applied_stiffness_add,
    damper_stiffness_add,
    kinetic_energy,
    mass_diagonal,
    potential_energy,
    spring_vectors,
)
from mcchain.kernels.joints import (
    add_pair_outer,
    constraint_gamma,
    constraint_hessian_add,
    constraint_jacobian,
    constraint_residual,
    joint_forces,
)
from mcchain.kernels.lanes import Emitter, Topology, load_module
from mcchain.kernels.linalg import lu_factor, lu_solve
from mcchain.status import CONTACT_LOST, DIVERGED, FAILURE_BITS, SINGULAR

# ---------------------------------------------------------------------------------------------
# Coefficients (Butcher tableaux as data; identities tested in tests/test_simulate_methods.py)


@dataclass(frozen=True)
class Tableau:
    """Explicit Runge–Kutta tableau: stages c, matrix A (strictly lower), weights b.

    ``b_error`` (embedded pairs): b − b̂, the weights of the local error estimate; ``order``
    is the order of b, ``error_order`` the order of b̂.
    """

    name: str
    c: np.ndarray
    A: np.ndarray
    b: np.ndarray
    order: int
    b_error: np.ndarray | None = None
    error_order: int | None = None

    @property
    def nstage(self) -> int:
        return len(self.c)


RK4 = Tableau(
    name="rk4",
    c=np.array([0.0, 0.5, 0.5, 1.0]),
    A=np.array(
        [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
    ),
    b=np.array([1.0, 2.0, 2.0, 1.0]) / 6.0,
    order=4,
)
"""The classical fourth-order Runge–Kutta method."""

_DP_B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0])
_DP_BHAT = np.array(
    [5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]
)
DOPRI5 = Tableau(
    name="dopri5",
    c=np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0]),
    A=np.array(
        [
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0, 0.0],
            [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0, 0.0],
            [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0, 0.0],
            [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0, 0.0],
            [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0],
        ]
    ),
    b=_DP_B,
    order=5,
    b_error=_DP_B - _DP_BHAT,
    error_order=4,
)
"""Dormand–Prince 5(4), first same as last (the last stage is the next step's first)."""


@dataclass(frozen=True)
class GeneralizedAlpha:
    """Generalized-α coefficients (Chung & Hulbert; Arnold & Brüls 2007) from ρ∞ ∈ [0, 1]."""

    rho_inf: float
    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float

    @classmethod
    def from_rho(cls, rho_inf: float) -> GeneralizedAlpha:
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        gamma = 0.5 + af - am
        beta = 0.25 * (gamma + 0.5) ** 2
        return cls(rho_inf, am, af, gamma, beta)


# ---------------------------------------------------------------------------------------------
# Lane kernel templates. A line "@@name" is replaced by the block ``name`` at its indentation;
# ``@[row]`` / ``@[row,i]`` by the work-array element of lane ``l`` in that row; tokens NDOF,
# NCON1, ... by numbers.
#
# Vectorising (PERFORMANCE.md, and measured here): every hot lane loop reads and writes ONE
# flat work array ``W`` whose rows are LMAX apart, a literal. LLVM then sees constant
# distances between rows and vectorises without run-time alias checks; with several arrays
# (or rows a run-time stride apart) it needs more checks than it allows and gives up. The
# parameters are copied into W once per lane group for the same reason. The trip count (the
# lane count) stays a run-time value, so the loop is vectorised rather than unrolled.


def _simd_doubles() -> int:
    """Doubles in one SIMD register of this CPU: 8 with AVX-512, else 4 (AVX2)."""
    from llvmlite import binding

    return 8 if binding.get_host_cpu_features().get("avx512f") else 4


LMAX = _simd_doubles()
"""Largest lane count of a lane group, and the row length of the work array: one SIMD
register of doubles, so W is contiguous and a lane loop touches each element once. Measured
here (AVX2, rk4, ns per instance-step, side by side): rows of 64 doubles, 512 bytes apart,
all fell into an eighth of the L1 sets and long chains thrashed the cache (16-bar chain,
1 thread: 1,518 ns; rows of 72 doubles: 1,231; rows of 8: 1,139; of 4: 1,166), and the
32-bar chain's work rows (~830 of them) fit in L1 only with rows of 4 (1 thread: 3,218 ns
with rows of 8, 2,704 with 4). The clearance double pendulum and four-bar (2 threads) are as
fast or faster: 51.7 / 48.6 / 48.3 ns and 122.1 / 107.4 / 108.8 ns with rows of 72 (32
lanes), 8 and 4."""

_HEADER = '''\
"""Generated by mcchain.kernels.integrators for one scene topology. Do not edit."""
import math

import numpy as np
from numba import njit, prange

# error_model="numpy": x / 0 gives inf/nan instead of a raise (which blocks vectorising).
# fastmath "contract" only: a·b + c may become one fused multiply-add (≈ 1.25× faster lanes,
# rounding no worse). No reassociation or finite-math assumptions, so NaN still propagates to
# the failure checks, and every lane runs the same instructions: results stay bit-identical
# across thread counts, lane counts and chunk sizes (tested).
JIT = dict(cache=True, fastmath={"contract"}, nogil=True, error_model="numpy")
PJIT = dict(JIT, parallel=True)
'''

_ACCEL_KERNEL = '''
@njit(**JIT)
def accel(P, Q, V, t, balpha2, bbeta2, tau, qdd_out, lam_out, chk_out, sing_out):
    """Index-1 accelerations of every column of Q, V (ndof, n) with parameters P (nslot, n)."""
    s0 = 0
    for l in range(Q.shape[1]):
        @@load_params_p
        @@load_state_qv
        @@accel
        @@store_accel
'''

_OUTPUT_KERNEL = '''
@njit(**JIT)
def outputs(P, Q, V, LAM, t_now, jf_out, cf_out, dtq_out, cerr_out, en_out):
    """Outputs of every column of Q, V (ndof, n), LAM (ncon, n) at time t_now."""
    s0 = 0
    for l in range(Q.shape[1]):
        @@load_params_p
        @@load_state_qv
        @@load_lam_arr
        @@outputs
        @@store_outputs_py
'''

_GROUP_SETUP = """
        s0 = g * lanes
        nl = min(lanes, nsample - s0)
        W = np.zeros(NROW * LMAXV)
        st = np.zeros(lanes, np.uint32)
        tdv = np.full(lanes, np.nan)
        tsg = np.full(lanes, np.nan)
        tcl = np.full(lanes, np.nan)
        for l in range(nl):
            for k in range(NSLOT):
                W[(PROW + k) * LMAXV + l] = P[k, s0 + l]
            st[l] = status[s0 + l]
            tdv[l] = t_div[s0 + l]
            tsg[l] = t_sing[s0 + l]
            tcl[l] = t_cl[s0 + l]
            dead = (st[l] & FAILBITS) != 0
            for i in range(NDOF):
                W[(QROW + i) * LMAXV + l] = np.nan if dead else Q0[i, s0 + l]
                W[(VROW + i) * LMAXV + l] = np.nan if dead else V0[i, s0 + l]
"""

_GROUP_FINISH = """
        for l in range(nl):
            status[s0 + l] = st[l]
            t_div[s0 + l] = tdv[l]
            t_sing[s0 + l] = tsg[l]
            t_cl[s0 + l] = tcl[l]
"""

_ERK_ARGS = """P, Q0, V0, t0, h, nstep, out_every, A, bw, cc, balpha2, bbeta2, ctol, tau,
            robust, project, ptol, max_newton, lanes,
            out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en,
            status, t_div, t_sing, t_cl"""

_ERK_KERNEL = (
    f'''
@njit(**PJIT)
def erk_run({_ERK_ARGS}):
    """Fixed-step explicit Runge–Kutta (NSTAGE stages) over lane groups; see integrators.py."""
    lanes = max(1, min(lanes, LMAXV))
    ngroup = (Q0.shape[1] + lanes - 1) // lanes
    for g in prange(ngroup):
        erk_group(np.int64(g), {_ERK_ARGS})


@njit(**JIT)
def erk_group(g, {_ERK_ARGS}):
    """One lane group of :func:`erk_run` (kept out of the prange body: numba's parallel
    passes copy the loop body's IR many times, which is slow for generated code)."""
    nsample = Q0.shape[1]
    if True:'''
    + _GROUP_SETUP
    + """
        for n in range(nstep + 1):
            t = t0 + n * h
            nst = NSTAGE if n < nstep else 1
            for s in range(nst):
                ts = t + cc[s] * h
                # A strictly sub-diagonal tableau (RK4): a stage needs only the previous one,
                # and the step's increment is accumulated as the stages go.
                ah = A[s, s - 1] * h if s > 0 else 0.0
                bh = bw[s] * h
                keep = 0.0 if s == 0 else 1.0
                for l in range(nl):  # lanes: schedule
                    @@load_params
                    @@load_stage_sub
                    @@accel_stage
                    @@store_stage
                    @@accumulate
                    @[sga] = @[sga] + sing
                if s > 0:
                    continue
                # Failures, once per step at its start (scalar; cheap): max |Φ| of the state,
                # and rank loss in any stage since the last check (so a singular stage is
                # flagged at the end of its step).
                for l in range(nl):
                    alive = (st[l] & FAILBITS) == 0
                    bad_div = alive and not (@[chkc] <= ctol)
                    bad_sing = alive and (not robust) and @[sga] > 0.0
                    @[sga] = 0.0
                    if bad_div:
                        st[l] |= DIVERGED_BIT
                        tdv[l] = ts
                    if bad_sing:
                        st[l] |= SINGULAR_BIT
                        tsg[l] = ts
                    if bad_div or bad_sing:
                        @@kill_lane
                    elif alive and (st[l] & CONTACT_BIT) == 0:
                        @@contact_check_c
                if n % out_every == 0:
                    group_outputs_SUFFIX(
                        W, 0, nl, s0, n // out_every, t, LAMCROW, out_q, out_v, out_jf, out_cf,
                        out_dtq, out_cerr, out_en,
                    )
            if n == nstep:
                break
            for l in range(nl):
                @@combine
            if project:
                group_project_SUFFIX(W, nl, t + h, ptol, max_newton, tau)"""
    + _GROUP_FINISH
)

_PROJECT_CALL = """
            if project:
                group_project_SUFFIX(W, nl, t + h, ptol, max_newton, tau)"""

_ADAPTIVE_ARGS = """P, Q0, V0, t0, t_out, h0, A, bw, be, cc, order_err, rtol, atol, hmin,
                 max_steps, balpha2, bbeta2, ctol, tau, lanes,
                 out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en,
                 status, t_div, t_sing, t_cl, nsteps_out"""

_ADAPTIVE_KERNEL = (
    f'''
@njit(**PJIT)
def adaptive_run({_ADAPTIVE_ARGS}):
    """Embedded Runge–Kutta (NSTAGE stages, FSAL) with per-sample step control.

    Every lane has its own time and step; a step never crosses the lane's next output time
    and lands on it exactly. A lane whose step would fall below ``hmin`` or that exceeds
    ``max_steps`` attempts is flagged DIVERGED.
    """
    lanes = max(1, min(lanes, LMAXV))
    ngroup = (Q0.shape[1] + lanes - 1) // lanes
    for g in prange(ngroup):
        adaptive_group(np.int64(g), {_ADAPTIVE_ARGS})


@njit(**JIT)
def adaptive_group(g, {_ADAPTIVE_ARGS}):
    """One lane group of :func:`adaptive_run`."""
    nsample = Q0.shape[1]
    nout = t_out.shape[0]
    expo = -1.0 / (order_err + 1.0)
    if True:'''
    + _GROUP_SETUP
    + """
        iout = np.zeros(lanes, np.int64)
        nstp = np.zeros(lanes, np.int64)
        run = np.zeros(lanes, np.bool_)
        hl = np.zeros(lanes)
        for l in range(nl):
            @[tl] = t0
            @[hs] = 0.0
            hl[l] = h0
            run[l] = True
        # First stage at the start; later steps reuse the last stage (FSAL).
        group_first_stage_SUFFIX(W, nl, A, balpha2, bbeta2, tau)
        while True:
            # Failures, contact and outputs at each lane's current (accepted) state.
            nrun = 0
            for l in range(nl):
                if not run[l]:
                    continue
                alive = (st[l] & FAILBITS) == 0
                if alive and not (@[chk] <= ctol):
                    st[l] |= DIVERGED_BIT
                    tdv[l] = @[tl]
                    alive = False
                if alive and @[sg] > 0.0:
                    st[l] |= SINGULAR_BIT
                    tsg[l] = @[tl]
                    alive = False
                if not alive:
                    @@kill_lane
                elif (st[l] & CONTACT_BIT) == 0:
                    ts = @[tl]
                    @@contact_check
                if iout[l] < nout and @[tl] == t_out[iout[l]]:
                    group_outputs_SUFFIX(
                        W, l, l + 1, s0, iout[l], @[tl], LAMROW, out_q, out_v, out_jf, out_cf,
                        out_dtq, out_cerr, out_en,
                    )
                    iout[l] += 1
                if iout[l] >= nout or not alive:
                    # Finished or dead: the rest of a dead lane's history stays NaN.
                    run[l] = False
                    nsteps_out[s0 + l] = nstp[l]
                else:
                    nrun += 1
            if nrun == 0:
                break
            # One attempted step on every running lane: stages 1 .. NSTAGE-1.
            for l in range(nl):
                if run[l]:
                    @[hs] = min(hl[l], t_out[iout[l]] - @[tl])
                else:
                    @[hs] = 0.0
            for s in range(1, NSTAGE):
                @@stage_coefs_lane
                keep = 0.0 if s == 1 else 1.0
                for l in range(nl):  # lanes: schedule
                    hh = @[hs]
                    ts = @[tl] + cs * hh
                    @@stage_coefs_per_lane
                    @@load_params
                    @@load_stage
                    @@accel_stage
                    @@store_stage
                    @[sga] = @[sga] * keep + sing
                for i in range(2 * NDOF):
                    src = (KCROW + i) * LMAXV
                    dst = (K0ROW + 2 * NDOF * s + i) * LMAXV
                    for l in range(nl):
                        W[dst + l] = W[src + l]
            # Error estimate, acceptance, next step.
            for l in range(nl):
                if not run[l]:
                    continue
                hh = @[hs]
                @@error_norm
                nstp[l] += 1
                ok = en <= 1.0
                fac = 0.9 * en**expo if en > 0.0 else 5.0
                fac = min(5.0, max(0.2, fac))
                if not ok:
                    fac = min(fac, 1.0)
                target = t_out[iout[l]]
                landed = hh == target - @[tl]
                cut = hh < hl[l]
                if ok:
                    @@accept
                    @[tl] = target if landed else @[tl] + hh
                    # A step cut short to land on an output time keeps the controller's step.
                    hl[l] = max(hl[l], hh * fac) if cut else hh * fac
                else:
                    hl[l] = hh * fac
                if (not (hl[l] >= hmin)) or nstp[l] > max_steps:
                    @[chk] = np.inf"""
    + _GROUP_FINISH
)


_OUTPUT_HELPER = '''
@njit(**JIT)
def group_outputs_SUFFIX(W, lo, hi, s0, it, t_now, lamrow, out_q, out_v, out_jf, out_cf,
                         out_dtq, out_cerr, out_en):
    """Outputs of lanes lo..hi-1 at time t_now into history index ``it``."""
    for l in range(lo, hi):
        @@load_params
        @@load_state
        @@load_lam_dyn
        @@outputs
        @@store_outputs
'''

_HELPERS = (
    _OUTPUT_HELPER
    + '''

@njit(**JIT)
def group_project_SUFFIX(W, nl, tp, ptol, max_newton, tau):
    """Project q onto Φ(q, tp) = 0 (Newton, M-weighted minimum-norm steps; stops at
    ``ptol``, on stagnation or after ``max_newton``), then v onto Φ̇ = 0, at the projected q."""
    for l in range(nl):
        @[act] = 1.0
        @[pmax] = np.inf
    for itn in range(max_newton + 1):
        last = 1.0 if itn == max_newton else 0.0
        for l in range(nl):  # lanes: schedule
            @@load_params
            @@load_state
            @@projection
            @@apply_projection
        nact = 0
        for l in range(nl):
            nact += 1 if @[act] > 0.0 else 0
        if nact == 0:
            break


@njit(**JIT)
def group_first_stage_SUFFIX(W, nl, A, balpha2, bbeta2, tau):
    """Stage 0 at each lane's start (adaptive methods: later steps reuse their last stage)."""
    s = 0
    @@stage_coefs_zero
    for l in range(nl):
        ts = @[tl]
        @@stage_coefs_per_lane
        @@load_params
        @@load_stage
        @@accel_stage
        @@store_stage
        @@accept_zero
'''
)


class _Layout:
    """Rows of the flat work array W (each LMAX long) of one lane group."""

    def __init__(self, topo: Topology, nstage: int):
        self.rows: dict[str, int] = {}
        self.size = 0
        ncon1 = max(topo.ncon, 1)
        self.add("P", len(topo.slots()))
        self.add("q", topo.ndof)
        self.add("v", topo.ndof)
        for j in range(nstage):  # stage j: kq_j then kv_j, 2 ndof consecutive rows
            self.add(f"kq{j}", topo.ndof)
            self.add(f"kv{j}", topo.ndof)
        self.add("kqc", topo.ndof)  # current stage, then copied to its rows
        self.add("kvc", topo.ndof)
        self.add("aq", topo.ndof)  # accumulated increment of a fixed step
        self.add("av", topo.ndof)
        self.add("qn", topo.ndof)
        self.add("vn", topo.ndof)
        self.add("lam", ncon1)
        self.add("lamc", ncon1)
        for name in ("chk", "sg", "chkc", "sgc", "sga", "act", "pmax", "hs", "tl"):
            self.add(name, 1)

    def add(self, name: str, count: int) -> None:
        self.rows[name] = self.size
        self.size += count

    def at(self, name: str, i: int = 0) -> str:
        return f"W[{(self.rows[name] + i) * LMAX} + l]"


def _fill(template: str, blocks: dict[str, str], tokens: dict[str, str], lay: _Layout) -> str:
    out = []
    for line in template.splitlines():
        stripped = line.strip()
        if stripped.startswith("@@"):
            indent = len(line) - len(stripped)
            block = blocks[stripped[2:]]
            out.extend((" " * indent + b) if b else "" for b in block.splitlines())
        else:
            out.append(line)
    text = "\n".join(out)
    text = re.sub(
        r"@\[(\w+)(?:,(\d+))?\]", lambda m: lay.at(m.group(1), int(m.group(2) or 0)), text
    )
    for key, value in tokens.items():
        text = re.sub(rf"\b{key}\b", value, text)
        text = text.replace(f"_{key}(", f"_{value}(")
    return text


def _blocks(topo: Topology, nstage: int, lay: _Layout) -> dict[str, str]:
    em = Emitter(topo)
    ndof, ncon = topo.ndof, topo.ncon
    at = lay.at
    b: dict[str, str] = {}

    def block(name: str) -> None:
        b[name] = em.take(0)

    # prb: the sum of the accelerations, so a non-finite one reaches the failure check (as
    # a running sum: each term is consumed where it is made).
    probe = (
        ["prb = 0.0"]
        if ndof == 0
        else ["prb = qdd0", *(f"prb = prb + qdd{i}" for i in range(1, ndof))]
    )
    # Python-facing kernels (arrays P, Q, V; not the hot path).
    em.load_params(lambda k: f"P[{k}, l]")
    block("load_params_p")
    em.emit(
        *(f"q{i} = Q[{i}, l]" for i in range(ndof)), *(f"v{i} = V[{i}, l]" for i in range(ndof))
    )
    block("load_state_qv")
    em.emit(*(f"lam{r} = LAM[{r}, l]" for r in range(ncon)))
    block("load_lam_arr")
    em.acceleration()
    block("accel")
    em.emit(
        *(f"qdd_out[{i}, l] = qdd{i}" for i in range(ndof)),
        *(f"lam_out[{r}, l] = lam{r}" for r in range(ncon)),
        *probe,
        "chk_out[l] = phimax + prb * 0.0",
        "sing_out[l] = sing",
    )
    block("store_accel")
    em.outputs(t="t_now")
    block("outputs")
    store = []
    for k in range(topo.njoint):
        store += [f"jf_out[{2 * k}, l] = jfx{k}", f"jf_out[{2 * k + 1}, l] = jfy{k}"]
        store += [f"cf_out[{k}, l] = cf{k}"]
    store += [f"dtq_out[{d}, l] = dtq{d}" for d in range(topo.ndriver)]
    store += ["cerr_out[l] = phimax", "en_out[l] = energy"]
    em.emit(*store)
    block("store_outputs_py")

    # Lane kernels: everything in W.
    em.load_params(lambda k: at("P", k))
    block("load_params")
    em.emit(
        *(f"q{i} = {at('q', i)}" for i in range(ndof)),
        *(f"v{i} = {at('v', i)}" for i in range(ndof)),
    )
    block("load_state")
    em.emit(*(f"lam{r} = {at('lam', r)}" for r in range(ncon)))
    block("load_lam")
    em.emit(*(f"lam{r} = W[(lamrow + {r}) * {LMAX} + l]" for r in range(ncon)))
    block("load_lam_dyn")
    em.emit(*(f"ah{j} = A[s, {j}] * h" for j in range(nstage)))
    block("stage_coefs")
    em.emit("cs = cc[s]", *(f"aa{j} = A[s, {j}]" for j in range(nstage)))
    block("stage_coefs_lane")
    em.emit(*(f"aa{j} = A[0, {j}]" for j in range(nstage)), "hh = 0.0")
    block("stage_coefs_zero")
    em.emit(*(f"ah{j} = aa{j} * hh" for j in range(nstage)))
    block("stage_coefs_per_lane")
    for i in range(ndof):
        qt = " + ".join(f"ah{j} * {at(f'kq{j}', i)}" for j in range(nstage))
        vt = " + ".join(f"ah{j} * {at(f'kv{j}', i)}" for j in range(nstage))
        em.emit(f"q{i} = {at('q', i)} + ({qt})", f"v{i} = {at('v', i)} + ({vt})")
    block("load_stage")
    em.acceleration(t="ts")
    block("accel_stage")

    em.emit(
        *(f"{at('kqc', i)} = v{i}" for i in range(ndof)),
        *(f"{at('kvc', i)} = qdd{i}" for i in range(ndof)),
        *(f"{at('lamc', r)} = lam{r}" for r in range(ncon)),
        *probe,
        f"{at('chkc')} = phimax + prb * 0.0",
        f"{at('sgc')} = sing",
    )
    block("store_stage")
    em.emit(
        *(f"{at('kq0', i)} = {at('kqc', i)}" for i in range(ndof)),
        *(f"{at('kv0', i)} = {at('kvc', i)}" for i in range(ndof)),
        *(f"{at('lam', r)} = {at('lamc', r)}" for r in range(ncon)),
        f"{at('chk')} = {at('chkc')}",
        f"{at('sg')} = {at('sgc')}",
    )
    block("accept_zero")
    em.emit(
        *(f"{at(x, i)} = np.nan" for x in ("q", "v", "kq0", "kv0") for i in range(ndof)),
        *(f"{at(x, r)} = np.nan" for x in ("lam", "lamc") for r in range(ncon)),
    )
    block("kill_lane")
    for row, name in (("lam", "contact_check"), ("lamc", "contact_check_c")):
        lines = []
        for r in topo.clearance_rows:
            lines += [
                f"if {at(row, r)} <= 0.0 and (st[l] & CONTACT_BIT) == 0:",
                "    st[l] |= CONTACT_BIT",
                "    tcl[l] = ts",
            ]
        em.emit(*(lines or ["pass"]))
        block(name)
    em.outputs(t="t_now")
    block("outputs")
    store = []
    for i in range(ndof):
        store += [f"out_q[s0 + l, it, {i}] = q{i}", f"out_v[s0 + l, it, {i}] = v{i}"]
    for k in range(topo.njoint):
        store += [
            f"out_jf[s0 + l, it, {2 * k}] = jfx{k}",
            f"out_jf[s0 + l, it, {2 * k + 1}] = jfy{k}",
            f"out_cf[s0 + l, it, {k}] = cf{k}",
        ]
    store += [f"out_dtq[s0 + l, it, {d}] = dtq{d}" for d in range(topo.ndriver)]
    store += ["out_cerr[s0 + l, it] = phimax", "out_en[s0 + l, it] = energy"]
    em.emit(*store)
    block("store_outputs")
    em.emit(
        *(f"{at(x, i)} = {at(x, i)} + {at('a' + x, i)}" for x in ("q", "v") for i in range(ndof))
    )
    block("combine")
    em.emit(
        *(f"{at('aq', i)} = {at('aq', i)} * keep + bh * v{i}" for i in range(ndof)),
        *(f"{at('av', i)} = {at('av', i)} * keep + bh * qdd{i}" for i in range(ndof)),
    )
    block("accumulate")
    for i in range(ndof):
        em.emit(
            f"q{i} = {at('q', i)} + ah * {at('kqc', i)}",
            f"v{i} = {at('v', i)} + ah * {at('kvc', i)}",
        )
    block("load_stage_sub")
    em.projection_terms(t="tp")
    block("projection")
    # Masks as exact 0/1 factors: q + 1·dq = q + dq and q + 0·dq = q (no branches).
    em.emit(
        f"act = {at('act')}",
        f"conv = ((phimax <= ptol) | (last > 0.0) | (phimax >= 0.5 * {at('pmax')})"
        " | (phimax != phimax)) * 1.0",
        "upd_q = act * (1.0 - conv)",
        "upd_v = act * conv",
        *(f"{at('q', i)} = q{i} + upd_q * dq{i}" for i in range(ndof)),
        *(f"{at('v', i)} = v{i} + upd_v * dv{i}" for i in range(ndof)),
        f"{at('act')} = upd_q",
        f"{at('pmax')} = phimax",
    )
    block("apply_projection")
    # Adaptive: new state and error norm (scaled as scipy's RK45: atol + rtol·max(|y|, |y_new|)).
    em.emit("en = 0.0")
    for i in range(ndof):
        for x in ("q", "v"):
            new = " + ".join(f"bw[{j}] * {at(f'k{x}{j}', i)}" for j in range(nstage))
            err = " + ".join(f"be[{j}] * {at(f'k{x}{j}', i)}" for j in range(nstage))
            em.emit(
                f"{at(x + 'n', i)} = {at(x, i)} + hh * ({new})",
                f"e_ = hh * ({err}) / (atol + rtol * max(abs({at(x, i)}), abs({at(x + 'n', i)})))",
                "en += e_ * e_",
            )
    em.emit(f"en = math.sqrt(en / {2 * ndof})", "en = en if en == en else np.inf")
    block("error_norm")
    em.emit(
        *(f"{at(x, i)} = {at(x + 'n', i)}" for x in ("q", "v") for i in range(ndof)),
        *(f"{at('kq0', i)} = {at(f'kq{nstage - 1}', i)}" for i in range(ndof)),
        *(f"{at('kv0', i)} = {at(f'kv{nstage - 1}', i)}" for i in range(ndof)),
        *(f"{at('lam', r)} = {at('lamc', r)}" for r in range(ncon)),
        f"{at('chk')} = {at('chkc')}",
        f"{at('sg')} = {at('sga')}",
    )
    block("accept")
    return b


def _tokens(topo: Topology, nstage: int, lay: _Layout) -> dict[str, str]:
    return {
        "NDOF": str(topo.ndof),
        "NSLOT": str(len(topo.slots())),
        "NSTAGE": str(nstage),
        "NROW": str(lay.size),
        "LMAXV": str(LMAX),
        "PROW": str(lay.rows["P"]),
        "QROW": str(lay.rows["q"]),
        "VROW": str(lay.rows["v"]),
        "LAMROW": str(lay.rows["lam"]),
        "LAMCROW": str(lay.rows["lamc"]),
        "K0ROW": str(lay.rows["kq0"]),
        "KCROW": str(lay.rows["kqc"]),
        "FAILBITS": str(FAILURE_BITS),
        "DIVERGED_BIT": str(DIVERGED),
        "SINGULAR_BIT": str(SINGULAR),
        "CONTACT_BIT": str(CONTACT_LOST),
    }


def generate_source(topo: Topology) -> str:
    """Source of the lane-kernel module of ``topo`` (RK4 and Dormand–Prince stage counts)."""
    parts = [_HEADER, f"# topology: {topo!r}\n"]
    sub = RK4.A[np.tril_indices(RK4.nstage, -2)]
    assert not sub.any(), "the fixed-step kernel needs a strictly sub-diagonal tableau"
    for template, tableau, suffix in (
        (_ACCEL_KERNEL, RK4, ""),
        (_OUTPUT_KERNEL, RK4, ""),
        # Two variants, so that plain RK4 never compiles the (large) projection code.
        (_ERK_KERNEL.replace(_PROJECT_CALL, "") + _OUTPUT_HELPER, RK4, "erk"),
        (_ERK_KERNEL.replace("erk_", "erk_project_") + _HELPERS, RK4, "erkp"),
        (_ADAPTIVE_KERNEL + _HELPERS, DOPRI5, "dp"),
    ):
        lay = _Layout(topo, tableau.nstage)
        blocks = _blocks(topo, tableau.nstage, lay)
        tokens = {**_tokens(topo, tableau.nstage, lay), "SUFFIX": suffix}
        parts.append(schedule_lane_loops(_fill(template, blocks, tokens, lay)))
    return "\n".join(parts)


_NAME = re.compile(r"\b[A-Za-z_]\w*\b")
_ASSIGN = re.compile(r"^(\w+)\s*([-+*]?)=\s*(.*)$")
_ROW = re.compile(r"W\[[^\]]+\]")


def schedule_lane_loops(text: str) -> str:
    """Reorder the body of every lane loop marked ``# lanes: schedule`` so that each value is
    computed just before its first use.

    Why: the emitter writes stage by stage over all bodies (every sin/cos, then every joint,
    ...), so on a long chain most values stay live across the whole body and the register
    allocator spills them; demand order shortens the live ranges (rk4, 1 thread: 8-bar chain
    843 -> 713 ns, 16-bar 1,955 -> 1,588 ns per instance-step; the double pendulum is
    unchanged). The body is straight-line code: names are renamed to single assignments,
    then the lines are emitted depth-first from the stores to W, in their original order;
    loads and stores of the same W element keep their order. Values are the same
    expressions, so results do not change.
    """
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.rstrip().endswith("# lanes: schedule"):
            out.append(line)
            i += 1
            continue
        indent = _indent(line)
        j = i + 1
        while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > indent):
            j += 1
        body = [b.strip() for b in lines[i + 1 : j] if b.strip()]
        pad = " " * _indent(lines[i + 1])
        out.append(line[: line.index("#")].rstrip())
        out.extend(pad + b for b in _demand_order(body))
        i = j
    return "\n".join(out)


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _demand_order(body: list[str]) -> list[str]:
    """The lines of ``body`` renamed to single assignments (``x__2``) in demand order, with
    stores and running accumulations as early as their inputs allow."""
    version: dict[str, int] = {}
    defined_by: dict[str, int] = {}
    last_store: dict[str, int] = {}
    reads_since_store: dict[str, list[int]] = {}
    texts: list[str] = []
    deps: list[set[int]] = []
    chained: list[int | None] = []
    stores: list[int] = []
    for line in body:
        m = _ASSIGN.match(line)
        if m:
            name, op, rhs = m.groups()
            expr, target = (f"{name} {op} ({rhs})" if op else rhs), None
        else:  # W[...] = expression
            target, expr = (x.strip() for x in line.split("=", 1))
            name = None
        k = len(texts)
        need: set[int] = set()
        running = name is not None and name in version and re.search(rf"\b{name}\b", expr)
        chained.append(defined_by[name] if running else None)

        def rename(match: re.Match[str], need: set[int] = need) -> str:
            word = match.group(0)
            if word not in version:
                return word
            need.add(defined_by[word])
            return f"{word}__{version[word]}"

        expr = _NAME.sub(rename, expr)
        for row in _ROW.findall(expr):
            if row in last_store:
                need.add(last_store[row])
            reads_since_store.setdefault(row, []).append(k)
        if name is not None:
            version[name] = version.get(name, 0) + 1
            defined_by[name] = k
            texts.append(f"{name}__{version[name]} = {expr}")
        else:
            need.update(r for r in reads_since_store.get(target, []) if r != k)
            if target in last_store:
                need.add(last_store[target])
            reads_since_store[target] = []
            last_store[target] = k
            stores.append(k)
            texts.append(f"{target} = {expr}")
        deps.append(need)
    done = [False] * len(texts)
    order: list[int] = []
    for root in stores + list(range(len(texts))):
        stack = [(root, False)]
        while stack:
            node, expanded = stack.pop()
            if done[node]:
                continue
            if expanded:
                done[node] = True
                order.append(node)
                continue
            stack.append((node, True))
            stack.extend((d, False) for d in sorted(deps[node], reverse=True) if not done[d])
    # Stores and running accumulations (x = x + term, max(x, term); and their start values)
    # consume values and make nothing else need them: each goes right after the last line
    # it needs (lowest line first when several become ready), so the values die there
    # instead of living to the end of the body.
    sinks = set(stores) | {k for k, c in enumerate(chained) if c is not None}
    sinks |= {c for c in chained if c is not None}
    missing = {k: len(deps[k]) for k in sinks}
    sinks_after: dict[int, list[int]] = {}
    for k in sinks:
        for d in deps[k]:
            sinks_after.setdefault(d, []).append(k)
    ready = [k for k in sinks if missing[k] == 0]
    heapq.heapify(ready)
    placed = [False] * len(texts)
    result: list[int] = []

    def place(node: int) -> None:
        for dep in sorted(deps[node]):  # a sink this line needs is not placed yet
            if not placed[dep]:
                place(dep)
        if placed[node]:
            return
        result.append(node)
        placed[node] = True
        for sink in sinks_after.get(node, ()):
            missing[sink] -= 1
            if missing[sink] == 0:
                heapq.heappush(ready, sink)

    for node in order:
        if node not in sinks:
            place(node)
        while ready:
            sink = heapq.heappop(ready)
            if not placed[sink]:
                place(sink)
    for node in order:  # sinks nothing led to (none in generated bodies)
        if not placed[node]:
            place(node)
    return [texts[k] for k in result]


_MODULES: dict[Topology, ModuleType] = {}


def lane_kernels(topo: Topology) -> ModuleType:
    """The compiled lane kernels of a topology: ``accel``, ``outputs``, ``erk_run``,
    ``adaptive_run`` (numba compiles each on first call; machine code cached on disk)."""
    module = _MODULES.get(topo)
    if module is None:
        module = load_module(generate_source(topo))
        _MODULES[topo] = module
    return module


# ---------------------------------------------------------------------------------------------
# Generalized-α, index 3 (Arnold & Brüls 2007), one sample per prange iteration.


@njit(**PJIT)
def generalized_alpha_run(
    km, Q0, V0, t0, h, nstep, out_every, ncon, alpha_m, alpha_f, gam, beta, ctol, tau,
    max_newton, out_q, out_v, out_jf, out_cf, out_dtq, out_cerr, out_en,
    status, t_div, t_sing, t_cl,
):  # fmt: skip
    """Generalized-α on M q̈ + Bᵀλ = F, Φ(q, t) = 0 for every sample.

    Each step: predict q̈_{n+1} = q̈_n, λ_{n+1} = λ_n, then Newton on the residuals
    (M q̈ + Bᵀλ − F, Φ) with the iteration matrix [[β′M + γ′C + K, Bᵀ], [B, 0]] (exact K
    from the joints' second derivatives and the load stiffness), constraint rows and λ
    scaled by β′ (Arnold & Brüls §3.3). LU with partial pivoting; a pivot ≤ ``tau`` × the
    largest entry flags SINGULAR, no convergence in ``max_newton`` iterations DIVERGED.
    """
    nsample, ndof = Q0.shape
    nsys = ndof + ncon
    bp = (1.0 - alpha_m) / (beta * h * h * (1.0 - alpha_f))
    gp = gam / (beta * h)
    for sample in prange(nsample):
        s = np.int64(sample)  # one index type for the callees (see config.PJIT)
        if status[s] & FAILURE_BITS:
            continue
        q = Q0[s].copy()
        v = V0[s].copy()
        m = np.zeros(ndof)
        F = np.zeros(ndof)
        qdd = np.zeros(ndof)
        acc = np.zeros(ndof)
        qdd_old = np.zeros(ndof)
        lam = np.zeros(max(ncon, 1))
        phi = np.zeros(max(ncon, 1))
        B = np.zeros((max(ncon, 1), ndof))
        Kmat = np.zeros((nsys, nsys))
        rhs = np.zeros(nsys)
        piv = np.zeros(nsys, np.int64)
        jf = np.zeros((km.joint_body_a.shape[0], 2))
        cf = np.zeros(km.joint_body_a.shape[0])
        mass_diagonal(km, s, m)
        st = status[s]
        # Consistent start: q̈_0, λ_0 from the index-1 KKT system (γ from the joints).
        gamma = np.zeros(max(ncon, 1))
        _index1(km, s, q, v, t0, m, F, B, gamma, Kmat, rhs, piv, ndof, ncon)
        for i in range(ndof):
            qdd[i] = rhs[i]
            acc[i] = rhs[i]
        for r in range(ncon):
            lam[r] = rhs[ndof + r]
        for n in range(nstep + 1):
            t = t0 + n * h
            constraint_residual(km, s, q, t, phi)
            err = 0.0
            for r in range(ncon):
                err = max(err, abs(phi[r]))
            for i in range(ndof):
                err += 0.0 * (q[i] + v[i])
            if not (err <= ctol):
                st |= DIVERGED
                t_div[s] = t
                break
            for k in range(km.joint_body_a.shape[0]):
                if km.joint_kind[k] != 0 and lam[km.joint_row[k]] <= 0.0 and not st & CONTACT_LOST:
                    st |= CONTACT_LOST
                    t_cl[s] = t
            if n % out_every == 0:
                it = n // out_every
                joint_forces(km, s, q, lam, jf, cf)
                for i in range(ndof):
                    out_q[s, it, i] = q[i]
                    out_v[s, it, i] = v[i]
                for k in range(jf.shape[0]):
                    out_jf[s, it, 2 * k] = jf[k, 0]
                    out_jf[s, it, 2 * k + 1] = jf[k, 1]
                    out_cf[s, it, k] = cf[k]
                for d in range(km.driver_row.shape[0]):
                    out_dtq[s, it, d] = -lam[km.driver_row[d]]
                out_cerr[s, it] = err
                out_en[s, it] = kinetic_energy(km, s, v) + potential_energy(km, s, q)
            if n == nstep:
                break
            # Predictor.
            tn = t + h
            for i in range(ndof):
                qdd_old[i] = qdd[i]
                anew = (qdd[i] - alpha_m * acc[i]) / (1.0 - alpha_m)
                q[i] += h * v[i] + h * h * ((0.5 - beta) * acc[i] + beta * anew)
                v[i] += h * ((1.0 - gam) * acc[i] + gam * anew)
                acc[i] = anew
            converged = False
            singular = False
            pivot = np.inf
            for _ in range(max_newton):
                applied_forces(km, s, q, v, F)
                constraint_residual(km, s, q, tn, phi)
                constraint_jacobian(km, s, q, B)
                for i in range(nsys):
                    rhs[i] = 0.0
                    for j in range(nsys):
                        Kmat[i, j] = 0.0
                for i in range(ndof):
                    res = m[i] * qdd[i] - F[i]
                    for r in range(ncon):
                        res += B[r, i] * lam[r]
                    rhs[i] = -res
                    Kmat[i, i] = bp * m[i]
                for r in range(ncon):
                    rhs[ndof + r] = -bp * phi[r]
                    for i in range(ndof):
                        Kmat[ndof + r, i] = bp * B[r, i]
                        Kmat[i, ndof + r] = bp * B[r, i]
                # K = ∂(Bᵀλ)/∂q − ∂F/∂q, C = −∂F/∂q̇ (dampers), into the top-left block.
                _tangent_add(km, s, q, v, lam, gp, Kmat)
                scale = 0.0
                for i in range(nsys):
                    for j in range(nsys):
                        scale = max(scale, abs(Kmat[i, j]))
                if not lu_factor(Kmat, nsys, piv, tau):
                    singular = True
                    break
                pivot = np.inf
                for i in range(nsys):
                    pivot = min(pivot, abs(Kmat[i, i]) / scale)
                lu_solve(Kmat, nsys, piv, rhs)
                dmax = 0.0
                qmax = 0.0
                for i in range(ndof):
                    q[i] += rhs[i]
                    v[i] += gp * rhs[i]
                    qdd[i] += bp * rhs[i]
                    dmax = max(dmax, abs(rhs[i]))
                    qmax = max(qmax, abs(q[i]))
                for r in range(ncon):
                    lam[r] += bp * rhs[ndof + r]
                if dmax <= 1e-13 * (1.0 + qmax):
                    converged = True
                    break
            if not converged and pivot < math.sqrt(tau):
                # Newton failing beside a near-zero pivot: rank loss, not a blow-up.
                singular = True
            if singular:
                st |= SINGULAR
                t_sing[s] = tn
                break
            if not converged:
                st |= DIVERGED
                t_div[s] = tn
                break
            for i in range(ndof):
                acc[i] += (1.0 - alpha_f) / (1.0 - alpha_m) * qdd[i]
                acc[i] -= (1.0 - alpha_f) / (1.0 - alpha_m) * qdd_old[i]
        status[s] = st


@njit(**JIT)
def _tangent_add(km, s, q, v, lam, gp, K_out):
    """K_out[:ndof, :ndof] += ∂(Bᵀλ)/∂q − ∂F/∂q + γ′ C, all exact: the joints' second
    derivatives, the loads' and springs' stiffness, the dampers' position dependence at fixed
    q̇, and C = −∂F/∂q̇ (along the spring; isotropic for rest length 0)."""
    constraint_hessian_add(km, s, q, lam, K_out)
    applied_stiffness_add(km, s, q, K_out)
    damper_stiffness_add(km, s, q, v, K_out)
    for k in range(km.spring_body_a.shape[0]):
        a = km.spring_body_a[k]
        b = km.spring_body_b[k]
        damping = km.spring_damping[s % km.spring_damping.shape[0], k]
        if damping == 0.0:
            continue
        pax, pay, pbx, pby, ux, uy = spring_vectors(km, s, q, k)
        if km.spring_rest_length[s % km.spring_rest_length.shape[0], k] == 0.0:
            add_pair_outer(K_out, gp * damping, a, b, 1.0, 0.0, pax, pay, pbx, pby)
            add_pair_outer(K_out, gp * damping, a, b, 0.0, 1.0, pax, pay, pbx, pby)
        else:
            length = math.hypot(ux, uy)
            add_pair_outer(K_out, gp * damping, a, b, ux / length, uy / length, pax, pay, pbx, pby)


@njit(**JIT)
def _index1(km, s, q, v, t, m, F, B, gamma, Kmat, rhs, piv, ndof, ncon):
    """Solve [[M, Bᵀ], [B, 0]] [q̈; λ] = [F; γ] (dense, for a start state) into ``rhs``."""
    applied_forces(km, s, q, v, F)
    constraint_jacobian(km, s, q, B)
    constraint_gamma(km, s, q, v, gamma)
    nsys = ndof + ncon
    for i in range(nsys):
        rhs[i] = 0.0
        for j in range(nsys):
            Kmat[i, j] = 0.0
    for i in range(ndof):
        Kmat[i, i] = m[i]
        rhs[i] = F[i]
    for r in range(ncon):
        rhs[ndof + r] = gamma[r]
        for i in range(ndof):
            Kmat[ndof + r, i] = B[r, i]
            Kmat[i, ndof + r] = B[r, i]
    if lu_factor(Kmat, nsys, piv, 1e-14):
        lu_solve(Kmat, nsys, piv, rhs)
    else:
        for i in range(nsys):
            rhs[i] = np.nan
