"""The lane-kernel modules of a topology: their source text and the loaded modules.

One module per variant (:data:`VARIANTS`: ``accel``, ``rk4``, ``rk4-projection``, ``rk45``),
holding only the functions that variant's entry points call.
:func:`generate_source` fills the templates (``templates.py``) with the emitter's blocks
(``emitter.py``) for the work-array rows of ``layout.py``, then schedules the lane loops
(``schedule.py``); :func:`lane_kernels` compiles the text (``native.py``; with
``MCCHAIN_LANE_COMPILER=numba``, writes it to the cache and imports it: ``cache.py``).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import re
import sys
from types import ModuleType

import numpy as np

from mcchain.codegen import templates
from mcchain.codegen.adaptive_step import stage_state_block, step_blocks
from mcchain.codegen.cache import copied_functions, load_module
from mcchain.codegen.contact_blocks import contact_blocks
from mcchain.codegen.emitter import Emitter
from mcchain.codegen.fixed_step import FIXED_STEP_VARIANTS, fixed_step_blocks
from mcchain.codegen.history import history_prefetches, history_stores
from mcchain.codegen.lane_text import FORCE_KERNELS
from mcchain.codegen.layout import (
    ADAPTIVE_ROW_MEANINGS,
    CONTACT_ROW_MEANINGS,
    FIXED_STEP_ROW_MEANINGS,
    LMAX,
    OUTPUT_ROW_MEANINGS,
    Layout,
    row_length,
    row_meanings,
    target_cpu,
)
from mcchain.codegen.native import NativeModule, array_layout_ok
from mcchain.codegen.output_blocks import Signature, output_blocks, output_functions
from mcchain.codegen.schedule import INTERLEAVE_CONSTANT, schedule_lane_loops
from mcchain.codegen.sincos import (
    ROTATION_BOUND,
    SHORT_ROTATION_BOUND,
    rotated_sincos_code,
    sincos_code,
)
from mcchain.codegen.topology import Topology
from mcchain.codegen.tracking import tracking_blocks, tracking_functions
from mcchain.compiled.caches import generated_text
from mcchain.contact import (
    CONTACT_STEP_LIMIT,
    RESEAT_NEWTON,
    RESEAT_TOLERANCE,
)
from mcchain.kernels.tableaux import (
    CAP_MARGIN,
    DOPRI5,
    KEEP_MARGIN,
    MAX_FACTOR,
    MIN_FACTOR,
    RK4,
    SAFETY,
    Tableau,
)
from mcchain.status import (
    CONTACT_LOST,
    CONTACT_STEP_TOO_LARGE,
    DIVERGED,
    FAILURE_BITS,
    SINGULAR,
)


def _fill(template: str, blocks: dict[str, str], tokens: dict[str, str], lay: Layout) -> str:
    out: list[str] = []
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


def _blocks(
    topo: Topology, tableau: Tableau, lay: Layout, outputs: Signature = ()
) -> dict[str, str]:
    fixed_step = lay.fixed_step  # the fixed-step kernel's blocks (templates.ERK_KERNEL)
    nstage = tableau.nstage
    em = Emitter(topo)
    em.parallel_pivots = em.cancel_gravity = em.scaled_rows = fixed_step
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
    b["invariant_rows"] = ""
    if fixed_step and "gdet" in lay.rows:
        b["invariant_rows"] = _ground_determinants(em, lay)
    if fixed_step:
        em.unit_rows = em.unit_normal_rows()
    cj = {k: j for j, k in enumerate(topo.contact_joints)}
    em.contact_source(lambda name, k: at(name, cj[k]))
    em.emit(
        *(f"q{i} = {at('q', i)}" for i in range(ndof)),
        *(f"v{i} = {at('v', i)}" for i in range(ndof)),
    )
    block("load_state")
    em.emit(*(f"lam{r} = {at('lam', r)}" for r in range(ncon)))
    block("load_lam")
    em.emit(*(f"lam{r} = W[(lamrow + {r}) * {lay.lmax} + l]" for r in range(ncon)))
    block("load_lam_dyn")
    b["stage_state"] = b["load_stage"] = ""
    prescribed: list[int] = []  # the adaptive stage's coordinates in closed form
    if not fixed_step:  # the adaptive stage's state: rows ys (adaptive_step.py), closed forms
        if em.prescribe:
            prescribed = [c for _, _, c in em.prescribed_coordinates()]
        b["stage_state"] = stage_state_block(topo, tableau, lay, prescribed)
        summed = [i for i in range(ndof) if i not in prescribed]
        em.emit(*(f"q{i} = {at('ys', i)}" for i in summed))
        em.emit(*(f"v{i} = {at('ys', ndof + i)}" for i in summed))
        if prescribed:
            em.prescribed_state(t="ts")
        block("load_stage")
    if fixed_step:  # the bodies' sin/cos computed before the stage (_stage_angles)
        em.angle_rows = lambda body: (at("scc", 2 * body), at("scc", 2 * body + 1))
    em.acceleration(t="ts")
    em.angle_rows = None
    block("accel_stage")
    if topo.contact_joints and not fixed_step:
        # The adaptive stage again for lane groups whose contact exponents are all 1.5:
        # contact_power's Hertz branch alone, no libm pow call in the vectorised loop (the
        # same values: the general stage takes that branch for those lanes).
        em.hertz_exponent = True
        em.acceleration(t="ts")
        em.hertz_exponent = False
        block("accel_stage_hertz")
        slots = topo.slots()
        other = " or ".join(f"{at('P', slots[f'mx{k}'])} != 1.5" for k in topo.contact_joints)
        b["hertz_dispatch"] = "\n".join(
            [
                "nother = 0",
                "for l in range(nl):",
                f"    nother += 1 if {other} else 0",
                "if nother == 0:",
                "    group_stage_hertz_SUFFIX("
                "W, nl, s_first, s_stop, A, cc, balpha2, bbeta2, tau, run, nev)",
                "    return",
            ]
        )
    em.angles_ready.clear()  # the closed-form angles' sin/cos: the stage's alone
    b.update(_stage_angles(topo, lay) if fixed_step else {})
    b.update(fixed_step_blocks(topo, nstage, lay) if fixed_step else {})

    # the stage's k into this stage's rows at the run-time offset kw (fixed_step_blocks,
    # adaptive_step.stage_state_block; the adaptive first stage's: rows kqc)
    k_row = lambda i: lay.stage_at(i, "kw")  # noqa: E731
    stage_k = [f"{k_row(i)} = v{i}" for i in range(ndof)]
    stage_k += [f"{k_row(ndof + i)} = qdd{i}" for i in range(ndof)]
    stage_contact = []
    for k, j in cj.items():
        stage_contact += [
            f"{at(x, j)} = {y}{k}" for x, y in (("pdc", "pen"), ("prc", "pdot"), ("wjc", "wj"))
        ]
    stage_contact += [f"{at('wcc')} = wc2"] if cj else []
    # λ and max |Φ| of the stage (the fixed step's checks read them after its first stage
    # only: store_stage_later, templates.ERK_KERNEL), its rank loss (the adaptive step's)
    em.emit(
        *stage_k,
        *(f"{at('lamc', r)} = lam{r}" for r in range(ncon)),
        *probe,
        f"{at('chkc')} = phimax + prb * 0.0",
        *([] if fixed_step else [f"{at('sgc')} = sing"]),
        *stage_contact,
        # the closed forms at the stage's time (the last stage's: the step's new state)
        *(f"{at('ys', c)} = q{c}" for c in prescribed),
        *(f"{at('ys', ndof + c)} = v{c}" for c in prescribed),
    )
    block("store_stage")
    em.emit(*stage_k, *stage_contact)
    block("store_stage_later")
    if cj:
        em.emit(f"{at('wca')} = max({at('wca')}, {at('wcc')})")
    block("contact_stage_max")
    if not fixed_step:  # the adaptive first stage's (FSAL) rows
        em.emit(
            *(f"{at('kq0', i)} = {at('kqc', i)}" for i in range(2 * ndof)),
            *(f"{at('lam', r)} = {at('lamc', r)}" for r in range(ncon)),
            f"{at('chk')} = {at('chkc')}",
            f"{at('sg')} = {at('sgc')}",
        )
    block("accept_zero")
    elem = lay.at_index
    b["kill_lane"] = "\n".join(
        [
            f"for r in range({2 * ndof}):",
            f"    {elem('q', 'r')} = np.nan",
            f"    {elem('kq0', 'r')} = np.nan",
            f"for r in range({ncon}):",
            f"    {elem('lam', 'r')} = np.nan",
            f"    {elem('lamc', 'r')} = np.nan",
        ]
    )
    # Fixed step: the status as rows (alv: no failure bit; ncl: no contact_lost bit), and
    # which lanes' status the step's checks may change (row att): a failure (max |Φ|
    # past ctol, NaN included; a dropped pivot unless robust), or a link's λ ≤ 0 at a
    # clearance joint; with contact-law joints every lane (their bookkeeping runs each step).
    b["status_rows"] = b["check_flag"] = ""
    if "att" in lay.rows:
        law_rows = {topo.joint_row[k] for k in topo.contact_joints}
        lost = [f"{at('lamc', r)} <= 0.0" for r in topo.clearance_rows if r not in law_rows]
        # Bitwise | and & of the comparisons, not `or` and `and`: short-circuits branch, and
        # the vectorised loop stored through masked scatters (2 % of the rk4 lanes' step).
        lost = [f"({x})" for x in lost]
        em.emit(
            f"bad = (not ({at('chkc')} <= ctol)) | ((not robust) & ({at('sga')} > 0.0))",
            f"lost = {' | '.join(lost) if lost else 'False'}",
            f"watch = bad | (({at('ncl')} > 0.0) & lost)",
            f"{at('att')} = 1.0 if {bool(law_rows)} | (({at('alv')} > 0.0) & watch) else 0.0",
            f"{at('sga')} = {at('sga')} if {at('att')} > 0.0 else 0.0",
        )
        block("check_flag")
        em.emit(
            f"{at('alv')} = 1.0 if (st[l] & FAILBITS) == 0 else 0.0",
            f"{at('ncl')} = 1.0 if (st[l] & CONTACT_BIT) == 0 else 0.0",
        )
        block("status_rows")
    for row, name in (("lam", "contact_check"), ("lamc", "contact_check_c")):
        lines = []
        law_rows = {topo.joint_row[k] for k in topo.contact_joints}
        for r in topo.clearance_rows:
            if r in law_rows:  # the contact_lost flag is the link's only
                continue
            lines += [
                f"if {at(row, r)} <= 0.0 and (st[l] & CONTACT_BIT) == 0:",
                "    st[l] |= CONTACT_BIT",
                "    tcl[l] = ts",
            ]
        em.emit(*(lines or ["pass"]))
        block(name)
    em.outputs(t="t_now")
    block("outputs")
    pairs = history_stores(topo)
    em.emit(*(f"{target} = {value}" for target, value in pairs))
    block("store_outputs")
    if "ost" in lay.rows:  # the adaptive kernel's: staged for all lanes, stored for some
        em.emit(*(f"{at('ost', i)} = {value}" for i, (_, value) in enumerate(pairs)))
        block("stage_outputs")
        em.emit(*(f"{target} = {at('ost', i)}" for i, (target, _) in enumerate(pairs)))
        block("store_staged_outputs")
        # Its lanes land one by one, each on its own stream of rows: the next lines asked
        # for (the fixed step's group lands at once every few steps: no gain measured).
        em.emit(*history_prefetches(topo))
        block("prefetch_outputs")
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
    # Kinetic energy of the lane and the velocities scaled by ``scale`` (re-seat).
    em.emit("ke = 0.0")
    for body in range(topo.own_bodies):  # not an ideal copy's (Topology.reference)
        rates = [f"v{3 * body + i}" for i in range(3)]
        arguments = [f"p_m{body}", f"p_J{body}", *rates]
        (kinetic,) = em.kernel(FORCE_KERNELS, "body_kinetic_energy", arguments)
        em.emit(f"ke += {kinetic}")
    block("kinetic")
    em.emit(*(f"{at('v', i)} = scale * v{i}" for i in range(3 * topo.own_bodies)))
    block("scale_velocity")

    # Adaptive: the step's new state and error norm (adaptive_step.py)
    for name in ("error_coefs", "new_state", "error_norm"):
        b[name] = ""
    if "en" in lay.rows:  # the adaptive kernel's layout
        b.update(step_blocks(topo, tableau, lay, prescribed))
    # An accepted step: its checks at once; its new state, last stage (FSAL) and λ copied
    # afterwards, every lane at once (row acc: accepted).
    b["accept"] = "\n".join([f"{at('chk')} = {at('chkc')}", f"{at('sg')} = {at('sga')}"])
    b["accept_copy"] = ""
    if "acc" in lay.rows:
        copies = [(at("q", r), at("qn", r)) for r in range(2 * ndof)]
        last = 2 * ndof * (nstage - 1)  # the last stage's rows (FSAL)
        copies += [(at("kq0", r), at("kq0", r + last)) for r in range(2 * ndof)]
        copies += [(at("lam", r), at("lamc", r)) for r in range(ncon)]
        em.emit(f"done = {at('acc')} > 0.0", *(f"{a} = {b_} if done else {a}" for a, b_ in copies))
        em.emit(f"{at('acc')} = 0.0")
        block("accept_copy")
    b.update(contact_blocks(topo, lay, b["kill_lane"]))
    b.update(tracking_blocks(topo, lay))
    b.update(output_blocks(topo, lay, outputs))
    return b


def _ground_determinants(em: Emitter, lay: Layout) -> str:
    """Rows ``gdet`` of each ideal revolute joint to the ground (its index in
    ``topo.ground_revolutes``: i): the determinant of its block of S, 1/m (1/m + |s|²/J),
    and its inverse, per sample (the group's setup, templates.ERK_KERNEL); and the emitter's
    :attr:`~mcchain.codegen.sparse_ldl.SchurComplement.invariant_pivots` reading them, so
    that a stage divides for neither (what it gives: benchmarks/results/roofline/
    reading.md, sixth stop)."""
    topo, at = em.topo, lay.at
    slots = topo.slots()
    lines: list[str] = []
    pivots: dict[frozenset[int], tuple[str, str]] = {}
    for pair, (k, body, sx, sy) in em.ground_revolutes().items():
        i = topo.ground_revolutes.index(k)
        det, inverse = at("gdet", 2 * i), at("gdet", 2 * i + 1)
        im, ij = at("P", slots[f"im{body}"]), at("P", slots[f"iJ{body}"])
        x, y = at("P", slots[sx]), at("P", slots[sy])
        lines += [f"{det} = {im} * ({im} + {ij} * ({x} * {x} + {y} * {y}))"]
        lines += [f"{inverse} = 1.0 / {det}"]
        pivots[pair] = (det, inverse)
    em.invariant_pivots = pivots
    return "\n".join(lines)


def _stage_angles(topo: Topology, lay: Layout) -> dict[str, str]:
    """The fixed-step kernel's blocks of the bodies' sin/cos at a stage, into rows ``scc``
    (templates.ERK_KERNEL): ``sincos_start`` at the step's start (also into rows ``sc0``); at
    a later stage the start's turned by the stage's increment δ = ah θ̇, each lane and body
    by its own |δ|: ``sincos_rotated`` by the short polynomials (every lane) with
    ``rotation_check`` (counts in ``nlong`` the lanes' bodies past
    :data:`SHORT_ROTATION_BOUND`), ``sincos_rotated_long`` by fdlibm's where |δ| is past it
    (counts in ``nbig`` those past :data:`ROTATION_BOUND`), ``sincos_mixed`` in full where
    |δ| is past that. A sample's bits so never depend on the lanes beside it (nor on the
    chunk or thread count); the group's branches only skip a longer tier no lane needs.

    The stage's angle is θ₀ + ah k, k its previous stage's θ̇; written in full as the stage
    itself writes it (the first stage's bits are the full evaluation's). A NaN δ counts as
    within the bounds: its lane's sin/cos are NaN either way.
    """
    at = lay.at
    full: list[str] = []
    rotated: list[str] = []
    long: list[str] = []
    mixed: list[str] = []
    check: list[str] = []
    start: list[str] = []
    for body in range(topo.nbody):
        i = 3 * body + 2
        delta = f"ah * {lay.stage_at(i, 'kr')}"  # the previous stage's θ̇
        sn, cs = f"sn{body}", f"cs{body}"
        rows = (at("scc", 2 * body), at("scc", 2 * body + 1))
        first = (at("sc0", 2 * body), at("sc0", 2 * body + 1))
        past, big = (f"abs({delta}) > {b!r}" for b in (SHORT_ROTATION_BOUND, ROTATION_BOUND))
        evaluated = [
            f"th{body} = {at('q', i)} + {delta}",
            *sincos_code(f"th{body}", sn, cs, str(body)),
        ]
        full += [*evaluated, f"{rows[0]} = {sn}", f"{rows[1]} = {cs}"]
        start += [f"{first[0]} = {sn}", f"{first[1]} = {cs}"]
        short = rotated_sincos_code(*first, delta, sn, cs, str(body), short=True)
        rotated += [*short, f"{rows[0]} = {sn}", f"{rows[1]} = {cs}"]
        check.append(f"nlong += 1 if {past} else 0")
        long += rotated_sincos_code(*first, delta, sn, cs, str(body))
        long += [f"{rows[0]} = {sn} if {past} else {rows[0]}"]
        long += [f"{rows[1]} = {cs} if {past} else {rows[1]}", f"nbig += 1 if {big} else 0"]
        mixed += [*evaluated, f"{rows[0]} = {sn} if {big} else {rows[0]}"]
        mixed += [f"{rows[1]} = {cs} if {big} else {rows[1]}"]
    return {
        "sincos_start": "\n".join(full + start or ["pass"]),
        "rotation_check": "\n".join(check or ["pass"]),
        "sincos_rotated": "\n".join(rotated or ["pass"]),
        "sincos_rotated_long": "\n".join(long or ["pass"]),
        "sincos_mixed": "\n".join(mixed or ["pass"]),
    }


def _tokens(topo: Topology, nstage: int, lay: Layout) -> dict[str, str]:
    return {
        "NDOF": str(topo.ndof),
        "NSLOT": str(len(topo.slots())),
        "NSTAGE": str(nstage),
        "NROW": str(lay.size),
        "LMAXV": str(lay.lmax),
        "PROW": str(lay.rows["P"]),
        "QROW": str(lay.rows["q"]),
        "VROW": str(lay.rows["v"]),
        "LAMROW": str(lay.rows["lam"]),
        "LAMCROW": str(lay.rows["lamc"]),
        "K0ROW": str(lay.rows["kq0"]),
        "FAILBITS": str(FAILURE_BITS),
        "DIVERGED_BIT": str(DIVERGED),
        "SINGULAR_BIT": str(SINGULAR),
        "CONTACT_BIT": str(CONTACT_LOST),
        "CONTACT_STEP_BIT": str(CONTACT_STEP_TOO_LARGE),
        "CONTACT_LIMIT2": repr(CONTACT_STEP_LIMIT**2),
        "RESEAT_TOL": repr(RESEAT_TOLERANCE),
        "RESEAT_NEWTON": str(RESEAT_NEWTON),
        "DRIVEN": str(bool(topo.ndriver)),
        "SAFETY": repr(SAFETY),
        "MIN_FACTOR": repr(MIN_FACTOR),
        "MAX_FACTOR": repr(MAX_FACTOR),
        "CAP_MARGIN": repr(CAP_MARGIN),
        "KEEP_MARGIN": repr(KEEP_MARGIN),
    }


_ERK_PLAIN = templates.ERK_KERNEL.replace(templates.PROJECT_CALL, "")
_ERK_PROJECT = templates.ERK_KERNEL.replace("erk_", "erk_project_")

VARIANTS: dict[str, tuple[str, Tableau | None, str, tuple[str, ...]]] = {
    # variant: (what it holds, its tableau (None: no work rows), suffix, templates)
    "accel": (
        "accel, outputs (the radau right-hand side and its outputs)",
        None,
        "",
        (templates.ACCEL_KERNEL, templates.OUTPUT_KERNEL),
    ),
    "rk4": ("erk_run", RK4, "erk", (_ERK_PLAIN, templates.OUTPUT_HELPER)),
    "rk4-projection": (
        "erk_project_run",
        RK4,
        "erkp",
        (_ERK_PROJECT, templates.OUTPUT_HELPER, templates.PROJECT_HELPER),
    ),
    "rk45": (
        "adaptive_run",
        DOPRI5,
        "dp",
        (
            templates.ADAPTIVE_KERNEL,
            templates.OUTPUT_LANDED_HELPER,
            templates.FIRST_STAGE_HELPER,
            templates.STAGE_HELPER,
        ),
    ),
}
"""The variants of a topology's lane-kernel module: each holds only the functions that its
entry points call, so a scene run with ``rk4`` compiles no projection or adaptive code."""


def generate_source(
    topo: Topology, variant: str, lmax: int | None = None, outputs: Signature = ()
) -> str:
    """Source of the lane-kernel module of ``topo`` for ``variant`` (a key of
    :data:`VARIANTS`), for work rows ``lmax`` doubles long (default :func:`lane_rows`),
    tracking the ``[[output]]``s ``outputs`` (their structure:
    :mod:`mcchain.codegen.output_blocks`; none: the text of a scene without)."""
    users, tableau, suffix, parts_of = VARIANTS[variant]
    if tableau is None:
        outputs = ()  # the radau right-hand side tracks nothing
    parts = [templates.HEADER, f"# topology: {topo!r}\n# variant: {variant}\n"]
    if outputs:
        parts.append(f"# outputs: {outputs!r}\n")
    nstage = RK4.nstage if tableau is None else tableau.nstage
    lmax = lane_rows(topo, variant, outputs) if lmax is None else lmax
    lay = _layout(topo, variant, nstage, lmax, outputs)
    fixed = lay.fixed_step
    if lmax > LMAX and variant != "rk45":
        # The rk45 lanes one register of lanes at a time: their stage keeps more values live
        # (contact, outputs), and two registers side by side spilled more than they overlapped
        # (verdict kernel 0.94, Flores slider-crank 0.95; the rk4 lanes' 1.04 the other way:
        # benchmarks/results/verdict/combine.md).
        parts.append(f"{INTERLEAVE_CONSTANT} = {lmax // LMAX}  # SIMD registers of lanes per row\n")
    if tableau is not None:
        parts += [row_meanings(fixed), lay.row_map(f"{users} ({nstage} stages)")]
        parts.append(ADAPTIVE_ROW_MEANINGS if variant == "rk45" else FIXED_STEP_ROW_MEANINGS)
    if topo.contact_joints or fixed:
        # the contact law's fused multiply-add (contact_power, inlined), the fixed step's
        # combine's rounded products (fixed_step.py): for numba's compile
        parts.append("from mcchain.kernels.config import fma  # noqa: E402\n")
    if "ost" in lay.rows:  # the landed outputs' hint (mcchain.kernels.config.prefetch)
        parts.append("from mcchain.kernels.config import prefetch  # noqa: E402\n")
    if tableau is not None:  # the queue of samples or groups (mcchain.kernels.config.take_next)
        parts.append("from mcchain.kernels.config import take_next  # noqa: E402\n")
    if topo.contact_joints:
        if tableau is not None:
            parts.append(CONTACT_ROW_MEANINGS)
        parts.append(_contact_functions(adaptive=variant == "rk45"))
    if tableau is not None:
        parts.append(tracking_functions())
    if variant == "rk45":  # a finished sample's history from its last output on
        from mcchain.kernels.explicit import nan_history

        parts.append(copied_functions(nan_history))
    if outputs:
        parts += [OUTPUT_ROW_MEANINGS, output_functions(with_hermite=not topo.contact_joints)]
    if any(topo.driver_tables) or any(topo.load_tables):
        parts.append(_table_constants(topo))
    if tableau is RK4:
        sub = RK4.A[np.tril_indices(RK4.nstage, -2)]
        assert not sub.any(), "the fixed-step kernel needs a strictly sub-diagonal tableau"
    # The fixed-step lanes' pivots divide side by side (SchurComplement.parallel_pivots),
    # their B M⁻¹F drops the terms uniform gravity cancels (Emitter.cancel_gravity) and
    # their clearance rows enter the solve scaled by |d| (ConstraintKinematics.scaled_rows);
    # the adaptive lanes and the radau right-hand side keep the sequential pivots, the terms
    # and the unit normals, and their bits: the shipped contact-law configs run rk45, whose
    # impacts amplify an ulp of a pivot into a different sequence of impacts.
    blocks = _blocks(topo, RK4 if tableau is None else tableau, lay, outputs)
    tokens = {**_tokens(topo, nstage, lay), "SUFFIX": suffix}
    if variant == "rk45" and topo.contact_joints:  # the stage, and its Hertz copy
        # the markers the copy and the dispatch replace (else the copy would silently be the
        # general stage, or never be called)
        stages = "    for s in range(s_first, s_stop):\n"
        for marker in ("group_stage_SUFFIX(", "@@accel_stage\n", stages):
            assert marker in templates.STAGE_HELPER, marker
        hertz = templates.STAGE_HELPER.replace("group_stage_SUFFIX(", "group_stage_hertz_SUFFIX(")
        hertz = hertz.replace("@@accel_stage\n", "@@accel_stage_hertz\n")
        general = templates.STAGE_HELPER.replace(stages, "    @@hertz_dispatch\n" + stages)
        parts_of = tuple(
            general + hertz if part is templates.STAGE_HELPER else part for part in parts_of
        )
    if tableau is not None and topo.contact_joints:
        refresh = templates.RESEAT_REFRESH if variant == "rk45" else ""
        parts_of = (*parts_of, templates.RESEAT_HELPER.replace("@@refresh_call\n", refresh))
    text = "\n".join(parts_of).replace("@CT", ", out_ct, sum_ct" if topo.contact_joints else "")
    text = text.replace("@OT", ", ot_in, out_ot" if outputs else "")
    parts.append(schedule_lane_loops(_fill(text, blocks, tokens, lay)))
    return "\n".join(parts)


def lane_rows(topo: Topology, variant: str, outputs: Signature = ()) -> int:
    """The row length (the largest lane group) of ``topo``'s lane kernels for ``variant``
    (tracking ``outputs``): :func:`mcchain.codegen.layout.row_length` of its work array."""
    tableau = VARIANTS[variant][1]
    nstage = RK4.nstage if tableau is None else tableau.nstage
    if tableau is None:
        outputs = ()
    return row_length(_layout(topo, variant, nstage, LMAX, outputs).size)


def _layout(topo: Topology, variant: str, nstage: int, lmax: int, outputs: Signature) -> Layout:
    """The work array of ``variant``'s module (rows ``lmax`` long, ``outputs`` tracked)."""
    fixed = variant in FIXED_STEP_VARIANTS
    return Layout(topo, nstage, lmax, variant == "rk45", len(outputs), fixed_step=fixed)


def _contact_functions(adaptive: bool) -> str:
    """The source of the contact kernels the lane kernels call, copied into the generated
    module from :mod:`mcchain.kernels.contact` (:func:`mcchain.codegen.cache.
    copied_functions`). ``adaptive``: with ``dwell_start`` (the located start of a re-seat
    dwell) and the ``quasi_static_slack`` and ``_dwell_slack`` it calls.
    """
    from mcchain.contact import SEATED, SEATED_AT_SWITCH
    from mcchain.kernels import contact

    parts = [f"SEATED = {SEATED!r}\nSEATED_AT_SWITCH = {SEATED_AT_SWITCH!r}"]
    kernels = (
        contact._hermite,
        contact.contact_crossing,
        contact.hermite_peak,
        contact.contact_bookkeeping,
    )
    located = (contact.quasi_static_slack, contact._dwell_slack, contact.dwell_start)
    parts.append(copied_functions(*kernels, *(located if adaptive else ())))
    return "\n\n".join(parts)


def _table_constants(topo: Topology) -> str:
    """The table laws' splines as module constants (``TK{d}``/``TC{d}`` of drivers,
    ``FK{f}``/``FC{f}`` of loads: knots and ascending coefficients), and a copy of
    :func:`mcchain.kernels.tables.spline_at` (:func:`mcchain.codegen.cache.
    copied_functions`)."""
    from mcchain.kernels import tables

    lines = ["# table laws: knots and ascending cubic coefficients per segment"]
    for prefix, items in (("T", topo.driver_tables), ("F", topo.load_tables)):
        for i, table in enumerate(items):
            if table:
                lines.append(f"{prefix}K{i} = {table[0]!r}")
                lines.append(f"{prefix}C{i} = {table[1]!r}")
    lines.append("\n" + copied_functions(tables.spline_at))
    return "\n".join(lines)


LaneKernels = ModuleType | NativeModule
"""A topology's lane kernels: entry points called with numpy arrays and scalars."""

_MODULES: dict[tuple[Topology, str, Signature], LaneKernels] = {}


@functools.cache
def _native_usable() -> bool:
    """Whether :mod:`mcchain.codegen.native` can call its entries with this NumPy; if not,
    one warning (once per process) and the lanes compile with numba."""
    if array_layout_ok():
        return True
    print(
        "mcchain: warning: this NumPy's array layout is not the one mcchain.codegen.native "
        "reads: the lane kernels compile with numba instead (slower to compile, the same "
        "values)",
        file=sys.stderr,
        flush=True,
    )
    return False


def lane_kernels(topo: Topology, variant: str, outputs: Signature = ()) -> LaneKernels:
    """The compiled lane kernels of a topology for one :data:`VARIANTS` key (``accel`` and
    ``outputs``; ``erk_run``; ``erk_project_run``; ``adaptive_run``).

    Each entry point compiles on its first call (:mod:`mcchain.codegen.native`: the text
    straight to LLVM, a few seconds where numba took 20-30 s for a four-bar with a contact
    joint) and its machine code is cached under ``MCCHAIN_CACHE_DIR/native``, in files
    named after the variant. ``MCCHAIN_LANE_COMPILER=numba`` compiles the same text with
    ``@njit`` instead (the reference of the tests and ``benchmarks/bench_native.py``; the
    same numbers; also where this NumPy's array layout is not the one the native entries
    read, with a warning). ``outputs``: the ``[[output]]``s they track (their structure,
    :mod:`mcchain.codegen.output_blocks`)."""
    module = _MODULES.get((topo, variant, outputs))
    if module is None:
        prefix = "mcchain_gen_" + variant.replace("-", "_")
        # A warm run reads the text made before (generating it costs more than loading
        # its machine code): keyed by all that shapes it besides mcchain's sources.
        key = repr((dataclasses.astuple(topo), variant, outputs, LMAX, target_cpu()))
        source = generated_text(
            prefix, key, lambda: generate_source(topo, variant, outputs=outputs)
        )
        if os.environ.get("MCCHAIN_LANE_COMPILER") == "numba" or not _native_usable():
            from mcchain.kernels.config import numba_cache

            numba_cache()  # a writable numba cache before the module's kernels are decorated
            module = load_module(source, prefix=prefix)
        else:
            digest = hashlib.sha256(source.encode()).hexdigest()[:20]
            module = NativeModule(source, f"{prefix}_{digest}")
        _MODULES[(topo, variant, outputs)] = module
    return module
