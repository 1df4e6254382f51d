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

from mcchain.codegen.cache import copied_functions
from mcchain.codegen.inline import inline
from mcchain.codegen.layout import Layout
from mcchain.codegen.topology import Topology
from mcchain.kernels.tableaux import PEAK_WIDTH
from mcchain.model import JOINT_IDEAL

PEAK_KERNELS = "mcchain.kernels.peaks"
"""The module whose straight-line functions the peak tracking inlines."""

TRACKING_HOOKS = {
    "track_step": "fixed step: each step's start (time ts, after the last one: "
    "mcchain.solvers.grid, λ of its first stage in row lamc), every lane l of the group once "
    "per step (a failed lane's values are NaN), all lanes in one vectorised loop: "
    "straight-line code on lane l's rows of W only",
    "track_accepted": "adaptive: each lane's accepted state (time in row tl, λ in row lam), "
    "all lanes in one vectorised loop as track_step; a lane's state comes back unchanged "
    "(a rejected step, a lane not running), with the same time",
    "track_pending": "fixed step: after track_step, in its loop: ``npend += 1`` for a lane "
    "that has work for track_fixup (whose loop runs only in a group with some); a tracker "
    "with track_fixup code has this hook",
    "track_fixup": "after track_step or track_accepted, lane by lane (scalar: branches and "
    "calls allowed): the rare work the vectorised feed flagged",
    "track_finish": "the end of lane l's sample sl (``dead``: it failed): its results out",
}
"""The templates' tracking hooks (``@@<hook>``) and where each stands."""


def peak_blocks(topo: Topology, lay: Layout) -> dict[str, str]:
    """The continuous peaks of |joint force| and |driver torque| (mcchain.kernels.peaks):
    each value fed at every accepted state (fixed step: each step's start, λ of the first
    stage; adaptive: each accepted state, λ of the last stage, a rejected step's repeated
    state skipped), and the peaks written at the end (NaN for a failed lane).

    A feed is :func:`mcchain.kernels.peaks.peak_feed` split in two: every lane at once, the
    new point shifted in, the running maximum taken and :func:`~mcchain.kernels.peaks.
    peak_checks`' flags kept (row ``pkf``); then, lane by lane, the cubic of a flagged step
    (rare: a local maximum of the data) on the four points now kept. The maxima are taken
    in peak_feed's order."""
    at = lay.at
    cj = {k: j for j, k in enumerate(topo.contact_joints)}
    npk = topo.njoint + topo.ndriver

    def row(i: int, m: int) -> str:
        """Number m (f_a, f_b, f_c, f_d, peak) of quantity i."""
        return at("pk", PEAK_WIDTH * i + m)

    def values(lamrow: str) -> list[str]:
        out = []
        for k in range(topo.njoint):
            r = topo.joint_row[k]
            lam = at(lamrow, r)
            if topo.joint_kind[k] == JOINT_IDEAL:
                lam2 = at(lamrow, r + 1)
                out.append(f"math.sqrt({lam} * {lam} + {lam2} * {lam2})")
            elif k in cj:  # the link's |λ|, or F_n ≥ 0 under the law
                out.append(f"abs({lam}) if {at('fm', cj[k])} == 0.0 else max({lam}, 0.0)")
            else:  # prismatic (the normal force) or a clearance joint on the link
                out.append(f"abs({lam})")
        out += [f"abs({at(lamrow, topo.driver_row[d])})" for d in range(topo.ndriver)]
        return out

    def feed(lamrow: str, t: str, tested: bool) -> str:
        """The feed of every quantity at time ``t``; ``tested``: a lane whose time is not
        after the last one it fed (a rejected step's repeated state) keeps its rows; untested
        (the fixed step's feed, whose times increase), every lane feeds, without the per-lane
        test and its selects (reading.md, tenth stop)."""
        lines = [f"cnt = {at('pkt', 4)}", f"tfeed = {t}"]
        if tested:
            lines.append(f"fresh = cnt == 0.0 or tfeed > {at('pkt', 3)}")

        def kept(target: str, value: str, otherwise: str) -> str:
            return f"{target} = {value}" + (f" if fresh else {otherwise}" if tested else "")

        for i, value in enumerate(values(lamrow)):
            lines.append(f"f{i} = {value}")
            lines += [f"f{x}{i} = {row(i, m)}" for m, x in ((1, "b"), (2, "c"), (3, "d"))]
            arguments = ["cnt", f"fb{i}", f"fc{i}", f"fd{i}", f"f{i}"]
            checks, (interior, first) = inline(PEAK_KERNELS, "peak_checks", arguments, f"_pk{i}")
            lines += checks
            shifted = [f"fb{i}", f"fc{i}", f"fd{i}", f"f{i}", f"max({row(i, 4)}, f{i})"]
            lines += [kept(row(i, m), v, row(i, m)) for m, v in enumerate(shifted)]
            lines.append(kept(at("pkf", i), f"({interior} + 2.0 * {first})", "0.0"))
        times = [at("pkt", 1), at("pkt", 2), at("pkt", 3), "tfeed", "min(cnt + 1.0, 4.0)"]
        lines += [kept(at("pkt", m), v, at("pkt", m)) for m, v in enumerate(times)]
        return "\n".join(lines)

    flagged = " or ".join(f"{at('pkf', i)} > 0.0" for i in range(npk))
    pending = f"npend += 1 if {flagged} else 0" if npk else ""
    fixup = []
    for i in range(npk):
        points = ", ".join(f"{at('pkt', m)}, {row(i, m)}" for m in range(4))
        fixup += [
            f"if {at('pkf', i)} > 0.0:",
            f"    flag = {at('pkf', i)}",
            f"    peak = {row(i, 4)}",
            "    if flag != 2.0:",
            f"        peak = max(peak, cubic_peak({points}, 1))",
            "    if flag >= 2.0:",
            f"        peak = max(peak, cubic_peak({points}, 0))",
            f"    {row(i, 4)} = peak",
        ]
    finish = [f"cnt = {at('pkt', 4)}", *(f"t{x} = {at('pkt', i)}" for i, x in enumerate("abcd"))]
    for i in range(npk):
        base = f"{(lay.rows['pk'] + PEAK_WIDTH * i) * lay.lmax} + l"
        finish += [
            f"{row(i, 4)} = peak_last(W, {base}, {lay.lmax}, cnt, ta, tb, tc, td)",
            f"out_pk[sl, {i}] = np.nan if dead or cnt == 0.0 else {row(i, 4)}",
        ]
    return {
        "track_step": feed("lamc", "ts", tested=False),
        "track_accepted": feed("lam", at("tl"), tested=True),
        "track_pending": pending,
        "track_fixup": "\n".join(fixup),
        "track_finish": "\n".join(finish),
    }


def peak_functions() -> str:
    """The source of :mod:`mcchain.kernels.peaks`' ``cubic_peak`` and ``peak_last``, copied
    into the generated module (:func:`mcchain.codegen.cache.copied_functions`)."""
    from mcchain.kernels import peaks

    return copied_functions(peaks.cubic_peak, peaks.peak_last)


TRACKERS: tuple[Callable[[Topology, Layout], dict[str, str]], ...] = (peak_blocks,)
"""The trackers of the lanes, in the order their code runs at each hook."""


def tracking_blocks(topo: Topology, lay: Layout) -> dict[str, str]:
    """The code of every tracker at each of :data:`TRACKING_HOOKS`."""
    parts = [tracker(topo, lay) for tracker in TRACKERS]
    for part in parts:  # the fixed-step kernel runs track_fixup only where a lane is pending
        assert not part.get("track_fixup") or part.get("track_pending"), "track_pending"
    return {hook: "\n".join(p[hook] for p in parts if p.get(hook)) for hook in TRACKING_HOOKS}


def tracking_functions() -> str:
    """The source of the kernel functions the trackers' code calls."""
    return peak_functions()
