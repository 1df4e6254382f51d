"""The lanes' bookkeeping of contact-law joints: the scalar per-lane code that
:func:`mcchain.codegen.generate.generate_source` puts into the templates' ``@@contact_*``
blocks (start values, the switch from the link of model auto, located onsets and
separations, re-seats, the summaries); the law itself is inlined from
:mod:`mcchain.kernels.contact` by the emitter.
"""

from __future__ import annotations

import math

from mcchain.codegen.inline import inline
from mcchain.codegen.lane_text import CONTACT_KERNELS, FORCE_KERNELS
from mcchain.codegen.layout import Layout
from mcchain.codegen.topology import Topology
from mcchain.contact import (
    AUTO,
    CONTACT_SUMMARY,
    RESEAT_PERIODS,
    RESEAT_RATE,
    SEAT_TOLERANCE,
    SEATED,
    SEATED_AT_SWITCH,
    START_LINK,
    START_SEATED,
    SWITCH_OVERSHOOT,
)
from mcchain.kernels.tableaux import PEAK_WIDTH

CONTACT_BLOCKS = (
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


def contact_blocks(topo: Topology, lay: Layout, kill: str) -> dict[str, str]:
    """The scalar per-lane code of contact-law joints: start values, the switch from the
    link (model auto), located onsets and separations, summaries; empty without them."""
    joints = topo.contact_joints
    if not joints:
        return dict.fromkeys(CONTACT_BLOCKS, "")
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
            f"    {at('vi', j)} = {SEATED_AT_SWITCH!r}",  # seated: the link's δ is 0 up to rounding
            f"    {at('ins', j)} = 1.0",
            f"    if {at('tse', j)} != {at('tse', j)}:",
            f"        {at('tse', j)} = {t}",
        ]

    def kinetic(vrow: str) -> str:
        """The lane's kinetic energy from the velocities in W rows ``vrow``
        (:func:`mcchain.kernels.forces.body_kinetic_energy` of each body, summed)."""
        terms = []
        for b in range(topo.own_bodies):  # not an ideal copy's (Topology.reference)
            m, inertia = at("P", slots[f"m{b}"]), at("P", slots[f"J{b}"])
            rates = [at(vrow, 3 * b + i) for i in range(3)]
            terms += inline(FORCE_KERNELS, "body_kinetic_energy", [m, inertia, *rates], "")[1]
        return " + ".join(terms)

    def criterion(k: int, lamrow: str, d1: str, r1: str, vrow: str) -> list[str]:
        """Lines that set ``rsk`` > 0 exactly where joint k may count the instant with δ1,
        δ̇1, its λ in W rows ``lamrow`` and the velocities in ``vrow`` towards its re-seat
        dwell (:func:`mcchain.kernels.contact.reseat_slack`); ``wn`` (ω_c) set before."""
        paid = topo.ndriver == 0  # without drivers, the kinetic energy pays the re-seat
        lam, mx = at(lamrow, topo.joint_row[k]), at("P", slots[f"mx{k}"])
        arguments = [model(k), d1, r1, lam, "wn", "ken" if paid else "0.0", mx, f"{paid:d}.0"]
        lines, (slack,) = inline(CONTACT_KERNELS, "reseat_slack", arguments, f"_rs{k}")
        return [*([f"ken = {kinetic(vrow)}"] if paid else []), *lines, f"rsk = {slack}"]

    def dwell(j: int, k: int, lamrow: str, h: str, d1: str, r1: str, vrow: str) -> list[str]:
        """Adaptive, model auto: ``dwn``, how long (s) the joint has met the re-seat
        criterion at the end of the step of length h (:func:`criterion`), −1 if it does not
        there; ``w0``, ``wn``: ω_c at the step's start (``pw``) and end. A dwell that begins
        in the step begins where RESEAT_RATE ω_c δ − |δ̇| rises through 0 on the step's
        Hermite interpolant (``dwell_start``, ω_c linear between the ends), or at the step's
        start if that term was ≥ 0 there (another condition decided)."""
        wj, dwl, d0, r0, pw = at("wjc", j), at("dwl", j), at("pd", j), at("pr", j), at("pw", j)
        rate0 = f"{RESEAT_RATE!r} * w0"
        _, (slow,) = inline(CONTACT_KERNELS, "quasi_static_slack", [rate0, d0, r0], "")
        return [
            f"wn = math.sqrt({wj}) if {wj} > 0.0 else 0.0",
            f"w0 = math.sqrt({pw}) if {pw} > 0.0 else wn",
            "dwn = -1.0",
            *criterion(k, lamrow, d1, r1, vrow),
            "if rsk > 0.0:",
            f"    g0 = {slow}",
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
        (:func:`dwell`, run once by ``contact_event``, which also retries the step that
        completes it to end there); else (fixed step) counted in whole steps: re-seated at the end
        of the step that completes it."""
        dwl, wj = at("dwl", j), at("wjc", j)
        if located:
            # the dwell and ω_c at the step's end as the event check found them (the same
            # inputs: an accepted step is the one it checked), not a second dwell_start
            count = [f"dwn = dwn{j}", f"wn = wn{j}", "if dwn >= 0.0:", f"    {dwl} = dwn"]
        else:
            count = [
                f"wn = math.sqrt({wj}) if {wj} > 0.0 else 0.0",
                *criterion(k, lamrow, d1, r1, vrow),
                "if rsk > 0.0:",
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
        """Bookkeeping of the step of length h that ended at time t with δ1, δ̇1: onset,
        separation, free flight, peak penetration (:func:`mcchain.kernels.contact.
        contact_bookkeeping`, which the generated module copies; the peak force is tracked
        with the joint forces: _peak_blocks), then the re-seat dwell (:func:`reseat`)."""
        d0, r0 = at("pd", j), at("pr", j)
        seat = f"{SEAT_TOLERANCE!r} * {at('P', slots[f'cl{k}'])}"
        names = ("vi", "ins", "nim", "tff", "tse", "pkd")
        books = [at(name, j) for name in names]
        arguments = ", ".join([*books, d0, r0, d1, r1, h, t, seat])
        return [
            f"if {at('fm', j)} == 1.0:",
            f"    {', '.join('c' + n for n in names)} = contact_bookkeeping({arguments})",
            *(f"    {row} = c{name}" for row, name in zip(books, names, strict=True)),
            *indent(reseat(j, k, lamrow, h, d1, r1, vrow, located)),
            f"{d0} = {d1}",
            f"{r0} = {r1}",
            *([f"{at('pw', j)} = {at('wjc', j)}"] if located else []),
        ]

    b: dict[str, str] = {}
    # Per lane l (sample sl): its start values, and its summaries at its end (dead: failed).
    setup = []
    for j, k in enumerate(joints):
        # the mode it starts in (Model.joint_start: link, law, or law seated on the wall); a
        # contact present at t = 0 has no onset: undamped (vi 0, or < 0 while seated)
        first_mode = at("P", slots[f"fs{k}"])
        setup += [
            f"{at('fm', j)} = 1.0 if {first_mode} != {START_LINK!r}.0 else 0.0",
            f"{at('ins', j)} = {at('fm', j)}",
            f"{at('vi', j)} = {SEATED!r} if {first_mode} == {START_SEATED!r}.0 else 0.0",
        ]
        setup += [f"{at(x, j)} = np.nan" for x in ("pd", "pr", "tse")]
    b["contact_setup"] = "\n".join(setup)
    finish = []
    for j, k in enumerate(joints):
        for m, name in enumerate(CONTACT_SUMMARY):
            col = len(CONTACT_SUMMARY) * j + m
            # the peak contact force: the joint's continuous peak (pk rows, tracking.py)
            value = at("pk", PEAK_WIDTH * k + PEAK_WIDTH - 1) if name == "pkf" else at(name, j)
            finish.append(f"sum_ct[sl, {col}] = np.nan if dead else {value}")
    b["contact_finish"] = "\n".join(finish)

    # Fixed step: at each step's start (stage 0 evaluated there), after the failure checks;
    # hb is the step that ended there (the last one of a run may be shorter than h).
    body = []
    for j, k in enumerate(joints):
        d1, r1 = at("pdc", j), at("prc", j)
        body += step(j, k, "lamc", "ts", "hb", d1, r1, "v", located=False)
        body += switch(j, k, "lamc", "ts", d1)  # after: the step hb was on the link
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

    # Adaptive: the state after a sample's first stage (per lane); the switch at each
    # accepted state (top of the loop); onsets and separations at each accepted step.
    start = []
    for j in range(len(joints)):
        start += [
            f"{at('pd', j)} = {at('pdc', j)}",
            f"{at('pr', j)} = {at('prc', j)}",
            *([f"{at('pw', j)} = {at('wjc', j)}"] if adaptive else []),
            f"{at('ins', j)} = {at('fm', j)} if {at('pdc', j)} > 0.0 or {at('vi', j)} < 0.0"
            " else 0.0",
        ]
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
    # The dwell is kept per joint (dwn{j}, wn{j}) for the accepted step's bookkeeping
    # (reseat); −1 where the joint is not under the law of model auto (no dwell there).
    for j, k in enumerate(joints if adaptive else ()):
        d1, r1 = at("pdc", j), at("prc", j)
        event += [
            f"dwn{j} = -1.0",
            f"wn{j} = 0.0",
            f"if {at('fm', j)} == 1.0 and {model(k)} == {AUTO!r}.0:",
            *indent(dwell(j, k, "lamc", "hh", d1, r1, "vn")),
            f"    dwn{j} = dwn",
            f"    wn{j} = wn",
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
    b["contact_dead"] = "for it in range(iout[l], out_ct.shape[1]):\n    out_ct[sl, it, :] = np.nan"
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
