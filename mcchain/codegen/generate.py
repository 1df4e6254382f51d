"""The lane-kernel modules of a topology: their source text and the loaded modules.

One module per variant (:data:`VARIANTS`: ``accel``, ``rk4``, ``rk4-projection``, ``rk45``),
holding only the functions that variant's entry points call.
:func:`generate_source` fills the templates (``templates.py``) with the emitter's blocks
(``emitter.py``) for the work-array rows of ``layout.py``, then schedules the lane loops
(``schedule.py``); :func:`lane_kernels` compiles the text (``native.py``; with
``MCCHAIN_LANE_COMPILER=numba``, writes it to the cache and imports it: ``cache.py``).
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import re
import sys
from types import ModuleType

import numpy as np

from mcchain.codegen import templates
from mcchain.codegen.cache import load_module
from mcchain.codegen.emitter import Emitter
from mcchain.codegen.layout import CONTACT_ROW_MEANINGS, LMAX, ROW_MEANINGS, Layout
from mcchain.codegen.native import NativeModule, array_layout_ok
from mcchain.codegen.schedule import schedule_lane_loops
from mcchain.codegen.topology import Topology
from mcchain.contact import (
    AUTO,
    CONTACT_STEP_LIMIT,
    CONTACT_SUMMARY,
    RESEAT_NEWTON,
    RESEAT_PERIODS,
    RESEAT_RATE,
    RESEAT_TOLERANCE,
    SEAT_TOLERANCE,
    START_LINK,
    START_SEATED,
    SWITCH_OVERSHOOT,
)
from mcchain.kernels.tableaux import (
    DOPRI5,
    MAX_FACTOR,
    MIN_FACTOR,
    PEAK_WIDTH,
    RK4,
    SAFETY,
    Tableau,
)
from mcchain.model import JOINT_IDEAL
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


def _blocks(topo: Topology, nstage: int, lay: Layout) -> dict[str, str]:
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
    em.emit(*(f"aa{j} = A[s, {j}]" for j in range(nstage)))
    block("stage_coefs_row")
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
    for k, j in cj.items():
        em.emit(f"{at('pdc', j)} = pen{k}", f"{at('prc', j)} = pdot{k}", f"{at('wjc', j)} = wj{k}")
    if cj:
        em.emit(f"{at('wcc')} = wc2")
    block("store_stage")
    if cj:
        em.emit(f"{at('wca')} = max({at('wca')}, {at('wcc')})")
    block("contact_stage_max")
    em.emit(
        *(f"{at('kq0', i)} = {at('kqc', i)}" for i in range(ndof)),
        *(f"{at('kv0', i)} = {at('kvc', i)}" for i in range(ndof)),
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
    # energy · 0: NaN for a killed lane's NaN state (max() in phimax drops a NaN), 0 otherwise.
    store += ["out_cerr[s0 + l, it] = phimax + energy * 0.0", "out_en[s0 + l, it] = energy"]
    for k, j in cj.items():
        store += [
            f"out_ct[s0 + l, it, {2 * j}] = pen{k}",
            f"out_ct[s0 + l, it, {2 * j + 1}] = mode{k}",
        ]
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
    # Kinetic energy of the lane and the velocities scaled by ``scale`` (re-seat).
    em.emit("ke = 0.0")
    for body in range(topo.nbody):
        vx, vy, w = f"v{3 * body}", f"v{3 * body + 1}", f"v{3 * body + 2}"
        em.emit(f"ke += 0.5 * (p_m{body} * ({vx} * {vx} + {vy} * {vy}) + p_J{body} * {w} * {w})")
    block("kinetic")
    em.emit(*(f"{at('v', i)} = scale * v{i}" for i in range(ndof)))
    block("scale_velocity")

    # Adaptive: new state and error norm (scaled as scipy's RK45: atol + rtol·max(|y|, |y_new|)),
    # summed over q0, v0, q1, v1, ... Loops over the rows, not unrolled: numba's compile time
    # grows faster than a function's length (the values are the same expressions).
    stride = 2 * ndof
    new = " + ".join(f"bw[{j}] * {elem('kq0', 'r', stride * j)}" for j in range(nstage))
    err = " + ".join(f"be[{j}] * {elem('kq0', 'r', stride * j)}" for j in range(nstage))
    b["error_norm"] = "\n".join(
        [
            "en = 0.0",
            f"for i in range({2 * ndof}):",
            f"    r = (i % 2) * {ndof} + i // 2",
            f"    y = {elem('q', 'r')}",
            f"    yn = y + hh * ({new})",
            f"    {elem('qn', 'r')} = yn",
            f"    e_ = hh * ({err}) / (atol + rtol * max(abs(y), abs(yn)))",
            "    en += e_ * e_",
            f"en = math.sqrt(en / {2 * ndof})",
            "en = en if en == en else np.inf",
        ]
    )
    b["accept"] = "\n".join(
        [
            f"for r in range({2 * ndof}):",
            f"    {elem('q', 'r')} = {elem('qn', 'r')}",
            f"    {elem('kq0', 'r')} = {elem('kq0', 'r', stride * (nstage - 1))}",
            f"for r in range({ncon}):",
            f"    {elem('lam', 'r')} = {elem('lamc', 'r')}",
            f"{at('chk')} = {at('chkc')}",
            f"{at('sg')} = {at('sga')}",
        ]
    )
    b.update(_contact_blocks(topo, lay, b["kill_lane"]))
    b.update(_peak_blocks(topo, lay))
    return b


def _peak_blocks(topo: Topology, lay: Layout) -> dict[str, str]:
    """The continuous peaks of |joint force| and |driver torque| (mcchain.kernels.peaks):
    each value fed at every accepted state (fixed step: each step's start, λ of the first
    stage; adaptive: each accepted state, λ of the last stage, a rejected step's repeated
    state skipped), and the peaks written at the end (NaN for a failed lane)."""
    at = lay.at
    cj = {k: j for j, k in enumerate(topo.contact_joints)}
    npk = topo.njoint + topo.ndriver

    def base(i: int) -> str:
        return f"{(lay.rows['pk'] + PEAK_WIDTH * i) * lay.lmax} + l"

    def feed(lamrow: str, t: str) -> str:
        lines = [
            f"cnt = {at('pkt', 4)}",
            f"if cnt == 0.0 or {t} > {at('pkt', 3)}:",
            *(f"    t{x} = {at('pkt', i + 1)}" for i, x in enumerate("bcd")),
        ]
        for k in range(topo.njoint):
            r = topo.joint_row[k]
            lam = at(lamrow, r)
            if topo.joint_kind[k] == JOINT_IDEAL:
                lam2 = at(lamrow, r + 1)
                value = f"math.sqrt({lam} * {lam} + {lam2} * {lam2})"
            elif k in cj:  # the link's |λ|, or F_n ≥ 0 under the law
                value = f"abs({lam}) if {at('fm', cj[k])} == 0.0 else max({lam}, 0.0)"
            else:  # prismatic (the normal force) or a clearance joint on the link
                value = f"abs({lam})"
            lines.append(f"    peak_feed(W, {base(k)}, {lay.lmax}, cnt, tb, tc, td, {t}, {value})")
        for d in range(topo.ndriver):
            value = f"abs({at(lamrow, topo.driver_row[d])})"
            lines.append(
                f"    peak_feed(W, {base(topo.njoint + d)}, {lay.lmax}, cnt, tb, tc, td, "
                f"{t}, {value})"
            )
        lines += [
            f"    {at('pkt', 0)} = tb",
            f"    {at('pkt', 1)} = tc",
            f"    {at('pkt', 2)} = td",
            f"    {at('pkt', 3)} = {t}",
            f"    {at('pkt', 4)} = min(cnt + 1.0, 4.0)",
        ]
        return "\n".join(lines)

    finish = [
        "for l in range(nl):",
        "    dead = (st[l] & FAILBITS) != 0",
        f"    cnt = {at('pkt', 4)}",
        *(f"    t{x} = {at('pkt', i)}" for i, x in enumerate("abcd")),
    ]
    for i in range(npk):
        peak = f"W[{base(i)} + {(PEAK_WIDTH - 1) * lay.lmax}]"
        finish += [
            f"    {peak} = peak_last(W, {base(i)}, {lay.lmax}, cnt, ta, tb, tc, td)",
            f"    out_pk[s0 + l, {i}] = np.nan if dead or cnt == 0.0 else {peak}",
        ]
    return {
        "peaks_c": feed("lamc", "ts"),
        "peaks": feed("lam", at("tl")),
        "peaks_finish": "\n".join(finish),
    }


_CONTACT_BLOCKS = (
    "contact_setup",
    "contact_finish",
    "contact_step_c",
    "contact_start",
    "contact_switch",
    "contact_accept",
    "contact_event",
    "contact_dead",
    "contact_reseat_erk",
    "contact_reseat",
)


def _contact_blocks(topo: Topology, lay: Layout, kill: str) -> dict[str, str]:
    """The scalar per-lane code of contact-law joints: start values, the switch from the
    link (model auto), located onsets and separations, summaries; empty without them."""
    joints = topo.contact_joints
    if not joints:
        return dict.fromkeys(_CONTACT_BLOCKS, "")
    at = lay.at
    slots = topo.slots()
    adaptive = "pw" in lay.rows  # the adaptive kernel's layout: the blocks it alone fills

    def indent(lines: list[str], n: int = 4) -> list[str]:
        return [" " * n + line for line in lines]

    def model(k: int) -> str:
        """The joint's model code (contact or auto) from the lane's parameters."""
        return at("P", slots[f"md{k}"])

    def switch(j: int, k: int, lamrow: str, t: str, d1: str) -> list[str]:
        """Model auto: the law from the first λ ≤ 0 on, starting from the link's state."""
        r = topo.joint_row[k]
        return [
            f"if {at('fm', j)} == 0.0 and {at(lamrow, r)} <= 0.0 and {model(k)} == {AUTO!r}.0:",
            f"    {at('fm', j)} = 1.0",
            f"    {at('vi', j)} = -1.0",  # seated: the link's δ is 0 up to rounding
            f"    {at('ins', j)} = 1.0",
            f"    if {at('tse', j)} != {at('tse', j)}:",
            f"        {at('tse', j)} = {t}",
        ]

    def kinetic(vrow: str) -> str:
        """The lane's kinetic energy from the velocities in W rows ``vrow``."""
        terms = []
        for b in range(topo.nbody):
            vx, vy, w = (at(vrow, 3 * b + i) for i in range(3))
            m, inertia = at("P", slots[f"m{b}"]), at("P", slots[f"J{b}"])
            terms.append(f"0.5 * ({m} * ({vx} * {vx} + {vy} * {vy}) + {inertia} * {w} * {w})")
        return " + ".join(terms)

    def criterion(j: int, k: int, lamrow: str, d1: str, r1: str, vrow: str) -> str:
        """Model auto: whether the joint may count the instant with δ1, δ̇1, its λ in W rows
        ``lamrow`` and the velocities in ``vrow`` towards its re-seat dwell: pressed
        quasi-statically (mcchain.contact.RESEAT_RATE) and, without drivers, with the kinetic
        energy to pay for the position step (mcchain.kernels.clearance.reseat_ready); ``wn``
        (ω_c) set before."""
        r = topo.joint_row[k]
        slow = f"abs({r1}) <= {RESEAT_RATE!r} * wn * {d1}"
        pressed = f"{d1} > 0.0 and {at(lamrow, r)} > 0.0 and {model(k)} == {AUTO!r}.0"
        mx = at("P", slots[f"mx{k}"])
        # without drivers, the kinetic energy must pay for the position step
        paid = f" and ({kinetic(vrow)}) > {mx} / ({mx} + 1.0) * {at(lamrow, r)} * {d1}"
        return f"{pressed} and {slow}{'' if topo.ndriver else paid}"

    def dwell(j: int, k: int, lamrow: str, h: str, d1: str, r1: str, vrow: str) -> list[str]:
        """Adaptive, model auto: ``dwn``, how long (s) the joint has met the re-seat
        criterion at the end of the step of length h (:func:`criterion`), −1 if it does not
        there; ``w0``, ``wn``: ω_c at the step's start (``pw``) and end. A dwell that begins
        in the step begins where RESEAT_RATE ω_c δ − |δ̇| rises through 0 on the step's
        Hermite interpolant (``dwell_start``, ω_c linear between the ends), or at the step's
        start if that term was ≥ 0 there (another condition decided)."""
        wj, dwl, d0, r0, pw = at("wjc", j), at("dwl", j), at("pd", j), at("pr", j), at("pw", j)
        return [
            f"wn = math.sqrt({wj}) if {wj} > 0.0 else 0.0",
            f"w0 = math.sqrt({pw}) if {pw} > 0.0 else wn",
            "dwn = -1.0",
            f"if {criterion(j, k, lamrow, d1, r1, vrow)}:",
            f"    g0 = {RESEAT_RATE!r} * w0 * {d0} - abs({r0})",
            "    th = 0.0",
            f"    if {dwl} == 0.0 and g0 < 0.0:",
            f"        th = dwell_start({d0}, {r0}, {d1}, {r1}, {h}, {RESEAT_RATE!r} * w0,"
            f" {RESEAT_RATE!r} * wn)",
            f"    dwn = {dwl} + (1.0 - th) * {h}",
        ]

    def reseat(
        j: int, k: int, lamrow: str, h: str, d1: str, r1: str, vrow: str, located: bool
    ) -> list[str]:
        """Model auto: back to the link once the re-seat criterion (:func:`criterion`) has
        held for RESEAT_PERIODS periods of the contact (mcchain.contact); the lane is then
        projected. ``located`` (adaptive): the dwell's start located in its step
        (:func:`dwell`) and the step that completes it retried to end there
        (``contact_event``); else (fixed step) counted in whole steps: re-seated at the end
        of the step that completes it."""
        dwl, wj = at("dwl", j), at("wjc", j)
        if located:
            count = [*dwell(j, k, lamrow, h, d1, r1, vrow), "if dwn >= 0.0:", f"    {dwl} = dwn"]
        else:
            count = [
                f"wn = math.sqrt({wj}) if {wj} > 0.0 else 0.0",
                f"if {criterion(j, k, lamrow, d1, r1, vrow)}:",
                f"    {dwl} += {h}",
            ]
        return [
            *count,
            f"    if {dwl} * wn >= {2.0 * math.pi * RESEAT_PERIODS!r}:",
            f"        {dwl} = -1.0",  # marked: group_reseat puts it on the link
            f"        {at('rsw')} = 1.0",
            "else:",
            f"    {dwl} = 0.0",
        ]

    def step(
        j: int, k: int, lamrow: str, t: str, h: str, d1: str, r1: str, vrow: str, located: bool
    ) -> list[str]:
        """Bookkeeping of the step of length h that ended at time t with δ1, δ̇1: onset
        (δ crosses 0 upwards: located, its rate is δ̇⁻), separation, free flight, peak
        penetration (the peak force is tracked with the joint forces: _peak_blocks)."""
        d0, r0 = at("pd", j), at("pr", j)
        seat = f"{SEAT_TOLERANCE!r} * {at('P', slots[f'cl{k}'])}"
        return [
            f"if {at('fm', j)} == 1.0:",
            # seated (vi < 0: from a start on the wall or the link): in contact, undamped,
            # no onset, until the journal is off the wall by more than the seat tolerance
            f"    if {at('vi', j)} < 0.0:",
            f"        if {d1} < -{seat}:",
            "            th = 0.0",
            f"            if {d0} > 0.0:",
            f"                th, rate = contact_crossing({d0}, {r0}, {d1}, {r1}, {h})",
            f"            {at('tff', j)} += (1.0 - th) * {h}",
            f"            if {at('tse', j)} != {at('tse', j)}:",
            f"                {at('tse', j)} = {t} - {h} + th * {h}",
            f"            {at('vi', j)} = 0.0",
            f"            {at('ins', j)} = 0.0",
            "        else:",
            f"            {at('ins', j)} = 1.0",
            "    else:",
            f"        if {d0} <= 0.0 and {d1} > 0.0:",
            f"            th, rate = contact_crossing({d0}, {r0}, {d1}, {r1}, {h})",
            f"            {at('vi', j)} = rate",
            f"            {at('nim', j)} += 1.0",
            f"            {at('tff', j)} += th * {h}",
            f"        elif {d0} > 0.0 and {d1} <= 0.0:",
            f"            th, rate = contact_crossing({d0}, {r0}, {d1}, {r1}, {h})",
            f"            {at('tff', j)} += (1.0 - th) * {h}",
            f"            if {at('tse', j)} != {at('tse', j)}:",
            f"                {at('tse', j)} = {t} - {h} + th * {h}",
            f"        elif {d0} <= 0.0:",
            f"            {at('tff', j)} += {h}",
            f"        {at('ins', j)} = 1.0 if {d1} > 0.0 else 0.0",
            f"    {at('pkd', j)} = max({at('pkd', j)}, {d1})",
            *indent(reseat(j, k, lamrow, h, d1, r1, vrow, located)),
            f"{d0} = {d1}",
            f"{r0} = {r1}",
            *([f"{at('pw', j)} = {at('wjc', j)}"] if located else []),
        ]

    b: dict[str, str] = {}
    setup = ["for l in range(nl):"]
    for j, k in enumerate(joints):
        # the mode it starts in (Model.joint_start: link, law, or law seated on the wall); a
        # contact present at t = 0 has no onset: undamped (vi 0, or < 0 while seated)
        first_mode = at("P", slots[f"fs{k}"])
        setup += indent(
            [
                f"{at('fm', j)} = 1.0 if {first_mode} != {START_LINK!r}.0 else 0.0",
                f"{at('ins', j)} = {at('fm', j)}",
                f"{at('vi', j)} = -1.0 if {first_mode} == {START_SEATED!r}.0 else 0.0",
            ]
        )
        setup += indent([f"{at(x, j)} = np.nan" for x in ("pd", "pr", "tse")])
    b["contact_setup"] = "\n".join(setup)
    finish = ["for l in range(nl):", "    dead = (st[l] & FAILBITS) != 0"]
    for j, k in enumerate(joints):
        for m, name in enumerate(CONTACT_SUMMARY):
            col = len(CONTACT_SUMMARY) * j + m
            # the peak contact force: the joint's continuous peak (pk rows, _peak_blocks)
            value = at("pk", PEAK_WIDTH * k + PEAK_WIDTH - 1) if name == "pkf" else at(name, j)
            finish.append(f"    sum_ct[s0 + l, {col}] = np.nan if dead else {value}")
    b["contact_finish"] = "\n".join(finish)

    # Fixed step: at each step's start (stage 0 evaluated there), after the failure checks;
    # hb is the step that ended there (the last one of a run may be shorter than h).
    body = []
    for j, k in enumerate(joints):
        d1, r1 = at("pdc", j), at("prc", j)
        body += switch(j, k, "lamc", "ts", d1)
        body += step(j, k, "lamc", "ts", "hb", d1, r1, "v", located=False)
    b["contact_step_c"] = "\n".join(
        [
            "if (st[l] & FAILBITS) == 0:",
            f"    if hb * hb * {at('wca')} > CONTACT_LIMIT2:",
            "        st[l] |= CONTACT_STEP_BIT",
            *indent(kill.splitlines(), 8),
            "    else:",
            *indent(body, 8),
            f"{at('wca')} = 0.0",
        ]
    )

    # Adaptive: the state after the first stage; the switch at each accepted state (top of
    # the loop); onsets and separations at each accepted step.
    start = ["for l in range(nl):"]
    for j in range(len(joints)):
        start += indent(
            [
                f"{at('pd', j)} = {at('pdc', j)}",
                f"{at('pr', j)} = {at('prc', j)}",
                *([f"{at('pw', j)} = {at('wjc', j)}"] if adaptive else []),
                f"{at('ins', j)} = {at('fm', j)} if {at('pdc', j)} > 0.0 or {at('vi', j)} < 0.0"
                " else 0.0",
            ]
        )
    b["contact_start"] = "\n".join(start)
    top = []
    for j, k in enumerate(joints):
        top += switch(j, k, "lam", at("tl"), at("pd", j))
    b["contact_switch"] = "\n".join(["if alive:", *indent(top or ["pass"])])
    accept = []
    for j, k in enumerate(joints):
        end = f"({at('tl')} + hh)"
        accept += step(j, k, "lamc", end, "hh", at("pdc", j), at("prc", j), "vn", located=adaptive)
    b["contact_accept"] = "\n".join(accept)
    # Adaptive, model auto: a step whose end has the link's λ ≤ 0 (its start λ > 0) is
    # retried to land just past the crossing (λ interpolated linearly; an undershoot is
    # accepted and the next step crosses again, shorter), so the law takes over where λ
    # reaches 0, not up to a whole step later. A crossing in the step's first thousandth is
    # taken at the step's end (retrying would shrink the step towards hmin).
    event = ["evt = 2.0"]
    for j, k in enumerate(joints):
        r = topo.joint_row[k]
        lam0, lam1 = at("lam", r), at("lamc", r)
        event += [
            f"if {at('fm', j)} == 0.0 and {model(k)} == {AUTO!r}.0 and {lam0} > 0.0"
            f" and {lam1} <= 0.0:",
            f"    frac = {lam0} / ({lam0} - {lam1})",
            "    if frac >= 1e-3:",
            f"        evt = min(evt, frac * {SWITCH_OVERSHOOT!r})",
        ]
    # Model auto under the law: a step in which the re-seat dwell completes is retried the
    # same way to end just past where (dwell) ω_c reaches 2π RESEAT_PERIODS,
    # so the re-seat time does not follow the steps.
    for j, k in enumerate(joints if adaptive else ()):
        d1, r1 = at("pdc", j), at("prc", j)
        event += [
            f"if {at('fm', j)} == 1.0 and {model(k)} == {AUTO!r}.0:",
            *indent(dwell(j, k, "lamc", "hh", d1, r1, "vn")),
            f"    if dwn >= 0.0 and dwn * wn >= {2.0 * math.pi * RESEAT_PERIODS!r}:",
            # (dwell at the step's start + θ hh) ω_c(θ) = 2π RESEAT_PERIODS, ω_c linear
            # between the ends, by bisection (a fixed point does not converge where the dwell
            # is many steps long: θ then moves by (dwell / hh)(Δω_c / ω_c) per iteration)
            "        flo = 0.0",
            "        fhi = 1.0",
            "        for itr in range(50):",
            "            frac = 0.5 * (flo + fhi)",
            "            if (dwn - hh + frac * hh) * (w0 + frac * (wn - w0))"
            f" >= {2.0 * math.pi * RESEAT_PERIODS!r}:",
            "                fhi = frac",
            "            else:",
            "                flo = frac",
            "        frac = fhi",
            # however early in the step (a retried step that ended just short of it, ω_c
            # not quite linear, completes it at once in the next), down to 10 hmin
            "        if frac * hh >= 10.0 * hmin:",
            f"            evt = min(evt, frac * {SWITCH_OVERSHOOT!r})",
        ]
    event += ["if ok and evt < 0.999:", "    ok = False", "    fac = evt"]
    b["contact_event"] = "\n".join(event)
    b["contact_dead"] = "out_ct[s0 + l, it, :] = np.nan"
    marks = []
    for j in range(len(joints)):
        marks += [
            f"if {at('dwl', j)} < 0.0:",
            f"    {at('fm', j)} = 0.0",
            f"    {at('dwl', j)} = 0.0",
        ]
    b["reseat_marks"] = "\n".join(marks)
    # Re-seats of model auto (whether a joint is auto is data: its md slot).
    b["contact_reseat_erk"] = "group_reseat_SUFFIX(W, nl, t, A, balpha2, bbeta2, tau, False)"
    b["contact_reseat"] = "group_reseat_SUFFIX(W, nl, 0.0, A, balpha2, bbeta2, tau, True)"
    return b


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
        "KCROW": str(lay.rows["kqc"]),
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
            templates.OUTPUT_HELPER,
            templates.FIRST_STAGE_HELPER,
            templates.STAGE_HELPER,
        ),
    ),
}
"""The variants of a topology's lane-kernel module: each holds only the functions that its
entry points call, so a scene run with ``rk4`` compiles no projection or adaptive code."""


def generate_source(topo: Topology, variant: str, lmax: int = LMAX) -> str:
    """Source of the lane-kernel module of ``topo`` for ``variant`` (a key of
    :data:`VARIANTS`), for work rows ``lmax`` doubles long (default: this CPU's SIMD
    register)."""
    users, tableau, suffix, parts_of = VARIANTS[variant]
    parts = [templates.HEADER, f"# topology: {topo!r}\n# variant: {variant}\n"]
    nstage = RK4.nstage if tableau is None else tableau.nstage
    lay = Layout(topo, nstage, lmax, adaptive=variant == "rk45")
    if tableau is not None:
        parts += [ROW_MEANINGS, lay.row_map(f"{users} ({nstage} stages)")]
    if topo.contact_joints:
        if tableau is not None:
            parts.append(CONTACT_ROW_MEANINGS)
        parts.append(_contact_functions(adaptive=variant == "rk45"))
    if tableau is not None:
        parts.append(_peak_functions())
    if any(topo.driver_tables) or any(topo.load_tables):
        parts.append(_table_constants(topo))
    if tableau is RK4:
        sub = RK4.A[np.tril_indices(RK4.nstage, -2)]
        assert not sub.any(), "the fixed-step kernel needs a strictly sub-diagonal tableau"
    blocks = _blocks(topo, nstage, lay)
    tokens = {**_tokens(topo, nstage, lay), "SUFFIX": suffix}
    if tableau is not None and topo.contact_joints:
        refresh = templates.RESEAT_REFRESH if variant == "rk45" else ""
        parts_of = (*parts_of, templates.RESEAT_HELPER.replace("@@refresh_call\n", refresh))
    if not topo.contact_joints:
        parts_of = tuple(p.replace(templates.FIRST_STAGE_RESEATED, "") for p in parts_of)
    text = "\n".join(parts_of).replace("@CT", ", out_ct, sum_ct" if topo.contact_joints else "")
    parts.append(schedule_lane_loops(_fill(text, blocks, tokens, lay)))
    return "\n".join(parts)


def _contact_functions(adaptive: bool) -> str:
    """The source of the contact kernels the lane kernels call, copied into the generated
    module from :mod:`mcchain.kernels.contact`.

    Copied, not imported: numba's cache of a generated module is keyed by the module's own
    file, so a change of a function it imported would not reach the cached machine code;
    with the source in the text, such a change makes a new module (its name is the text's
    hash). ``adaptive``: with ``dwell_start`` (the located start of a re-seat dwell).
    """
    import inspect

    from mcchain.kernels import contact

    parts = []
    kernels = (contact._hermite, contact.contact_crossing)
    for kernel in (*kernels, contact.dwell_start) if adaptive else kernels:
        source = inspect.getsource(kernel.py_func)
        parts.append("@njit(**JIT)\n" + source[source.index("def ") :])
    return "\n\n".join(parts)


def _peak_functions() -> str:
    """The source of :mod:`mcchain.kernels.peaks`' ``cubic_peak``, ``peak_feed`` and
    ``peak_last``, copied into the generated module (for the reason of
    :func:`_contact_functions`)."""
    import inspect

    from mcchain.kernels import peaks

    parts = []
    for kernel in (peaks.cubic_peak, peaks.peak_feed, peaks.peak_last):
        source = inspect.getsource(kernel.py_func)
        parts.append("@njit(**JIT)\n" + source[source.index("def ") :])
    return "\n\n".join(parts)


def _table_constants(topo: Topology) -> str:
    """The table laws' splines as module constants (``TK{d}``/``TC{d}`` of drivers,
    ``FK{f}``/``FC{f}`` of loads: knots and ascending coefficients), and a copy of
    :func:`mcchain.kernels.tables.spline_at` (copied for the reason of
    :func:`_contact_functions`)."""
    import inspect

    from mcchain.kernels import tables

    lines = ["# table laws: knots and ascending cubic coefficients per segment"]
    for prefix, items in (("T", topo.driver_tables), ("F", topo.load_tables)):
        for i, table in enumerate(items):
            if table:
                lines.append(f"{prefix}K{i} = {table[0]!r}")
                lines.append(f"{prefix}C{i} = {table[1]!r}")
    source = inspect.getsource(tables.spline_at.py_func)
    lines.append("\n@njit(**JIT)\n" + source[source.index("def ") :])
    return "\n".join(lines)


LaneKernels = ModuleType | NativeModule
"""A topology's lane kernels: entry points called with numpy arrays and scalars."""

_MODULES: dict[tuple[Topology, str], LaneKernels] = {}


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


def lane_kernels(topo: Topology, variant: str) -> LaneKernels:
    """The compiled lane kernels of a topology for one :data:`VARIANTS` key (``accel`` and
    ``outputs``; ``erk_run``; ``erk_project_run``; ``adaptive_run``).

    Each entry point compiles on its first call (:mod:`mcchain.codegen.native`: the text
    straight to LLVM, a few seconds where numba took 20-30 s for a four-bar with a contact
    joint) and its machine code is cached under ``MCCHAIN_CACHE_DIR/native``, in files
    named after the variant. ``MCCHAIN_LANE_COMPILER=numba`` compiles the same text with
    ``@njit`` instead (the reference of the tests and ``benchmarks/bench_native.py``; the
    same numbers; also where this NumPy's array layout is not the one the native entries
    read, with a warning)."""
    module = _MODULES.get((topo, variant))
    if module is None:
        prefix = "mcchain_gen_" + variant.replace("-", "_")
        source = generate_source(topo, variant)
        if os.environ.get("MCCHAIN_LANE_COMPILER") == "numba" or not _native_usable():
            from mcchain.kernels.config import numba_cache

            numba_cache()  # a writable numba cache before the module's kernels are decorated
            module = load_module(source, prefix=prefix)
        else:
            digest = hashlib.sha256(source.encode()).hexdigest()[:20]
            module = NativeModule(source, f"{prefix}_{digest}")
        _MODULES[(topo, variant)] = module
    return module
