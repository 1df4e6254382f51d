"""Per-step tracking in the lanes: quantities fed at every accepted state of a lane and
written out when its run ends (today the continuous peaks of |joint force| and |driver
torque|, :mod:`mcchain.kernels.peaks`).

A tracker is a function ``(topo, lay) -> {hook: text}`` giving the scalar per-lane code of
the templates' three tracking hooks (:data:`TRACKING_HOOKS`), and the source of the kernel
functions that code calls (copied into the generated module). A new tracker keeps its
state in rows of its own in the work array (``layout.py``), adds its function to
:data:`TRACKERS`, and touches neither the templates nor the other trackers.
"""

from __future__ import annotations

from collections.abc import Callable

from mcchain.codegen.layout import Layout
from mcchain.codegen.topology import Topology
from mcchain.kernels.tableaux import PEAK_WIDTH
from mcchain.model import JOINT_IDEAL

TRACKING_HOOKS = {
    "track_step": "fixed step: each step's start (time ts, λ of its first stage in row lamc), "
    "every lane l of the group once per step (a failed lane's values are NaN)",
    "track_accepted": "adaptive: each accepted state of running lane l (time tl, λ in row "
    "lam); a rejected step's repeated state comes back with the same time",
    "track_finish": "the end of a lane group: a loop over its lanes writes the results "
    "(s0 + l the sample; st[l] & FAILBITS its failure)",
}
"""The templates' tracking hooks (``@@<hook>``) and where each stands."""


def peak_blocks(topo: Topology, lay: Layout) -> dict[str, str]:
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
        "track_step": feed("lamc", "ts"),
        "track_accepted": feed("lam", at("tl")),
        "track_finish": "\n".join(finish),
    }


def peak_functions() -> str:
    """The source of :mod:`mcchain.kernels.peaks`' ``cubic_peak``, ``peak_feed`` and
    ``peak_last``, copied into the generated module (for the reason of
    :func:`mcchain.codegen.generate._contact_functions`)."""
    import inspect

    from mcchain.kernels import peaks

    parts = []
    for kernel in (peaks.cubic_peak, peaks.peak_feed, peaks.peak_last):
        source = inspect.getsource(kernel.py_func)
        parts.append("@njit(**JIT)\n" + source[source.index("def ") :])
    return "\n\n".join(parts)


TRACKERS: tuple[Callable[[Topology, Layout], dict[str, str]], ...] = (peak_blocks,)
"""The trackers of the lanes, in the order their code runs at each hook."""


def tracking_blocks(topo: Topology, lay: Layout) -> dict[str, str]:
    """The code of every tracker at each of :data:`TRACKING_HOOKS`."""
    parts = [tracker(topo, lay) for tracker in TRACKERS]
    return {hook: "\n".join(p[hook] for p in parts if p.get(hook)) for hook in TRACKING_HOOKS}


def tracking_functions() -> str:
    """The source of the kernel functions the trackers' code calls."""
    return peak_functions()
