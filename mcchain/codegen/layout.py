"""The flat work array ``W`` of one lane group: its rows and their length.

Vectorising (PERFORMANCE.md, and measured here): every hot lane loop reads and writes ONE
flat work array ``W`` whose rows are LMAX apart, a literal. LLVM then sees constant distances
between rows and vectorises without run-time alias checks; with several arrays (or rows a
run-time stride apart) it needs more checks than it allows and gives up. The parameters are
copied into W once per lane group for the same reason. The trip count (the lane count) stays a
run-time value, so the loop is vectorised rather than unrolled.
"""

from __future__ import annotations

from mcchain.codegen.history import history_stores
from mcchain.codegen.topology import Topology
from mcchain.codes import OUTPUT_WIDTH
from mcchain.kernels.tableaux import PEAK_CLOCK, PEAK_WIDTH

OUTPUT_SAMPLE_COLUMNS = 5
"""The per-sample columns of an output's data (``ot_in[row, k, :5]``: the point sx, sy, the
window w0, w1, the threshold: mcchain.solvers.output_plan.DATA_COLUMNS), which the adaptive
kernel copies into rows ``otd`` when a lane takes a sample."""


def target_cpu() -> tuple[str, str]:
    """The CPU name and features numba compiles for, as its codegen chooses them:
    ``NUMBA_CPU_NAME`` and ``NUMBA_CPU_FEATURES`` where set (no features for the name
    ``generic``), else the host's. The generated text follows them (:data:`LMAX`), not the
    host's own flags, so a cache built for a portable target is portable."""
    import os

    from llvmlite import binding

    name = os.environ.get("NUMBA_CPU_NAME") or binding.get_host_cpu_name()
    features = os.environ.get("NUMBA_CPU_FEATURES")
    if features is None:
        features = "" if name.lower() == "generic" else binding.get_host_cpu_features().flatten()
    return name, features


def simd_doubles(features: str) -> int:
    """Doubles in one SIMD register of a CPU with these features (LLVM's ``+f,-g`` list):
    8 with AVX-512, else 4 (AVX2)."""
    return 8 if "+avx512f" in features.split(",") else 4


LMAX = simd_doubles(target_cpu()[1])
"""Lanes of one SIMD register of doubles (this CPU's, or the target's): the shortest row of the
work array, and the row length of large mechanisms. Measured here (AVX2, rk4, ns per
instance-step, side by side): rows of 64 doubles, 512 bytes apart, all fell into an eighth of
the L1 sets and long chains thrashed the cache (16-bar chain, 1 thread: 1,518 ns; rows of 72
doubles: 1,231; rows of 8: 1,139; of 4: 1,166), and the 32-bar chain's work rows (~830 of them)
fit in L1 only with rows of 4 (1 thread: 3,218 ns with rows of 8, 2,704 with 4)."""

GROUP_BYTES = 44 << 10
"""Largest work array of a lane group whose rows take several SIMD registers of lanes
(:func:`row_length`): it stays in the L1 data cache (48 KiB here)."""

MAX_REGISTERS = 2
"""Most SIMD registers of lanes in one row (:func:`row_length`). Measured (AVX-512, 1 thread,
best CPU time of 12 runs alternating, ns per instance-step, rows of 8 / 16 / 32 doubles):
clearance double pendulum rk4 94.8 / 78.7 / 81.4, Flores slider-crank rk4 232.6 / 217.1 /
252.4, rk45 704.1 / 708.0 / 911.5: four registers gained nothing over two."""


def row_length(nrow: int) -> int:
    """Doubles per row of a work array of ``nrow`` rows: :data:`LMAX` × k lanes, k (a power
    of two, at most :data:`MAX_REGISTERS`) the most registers whose rows keep the array
    within :data:`GROUP_BYTES`.

    Why more than one register: a lane group's stage is one long chain of dependent
    operations (sin/cos, the joints, the Schur solve) that one register of lanes runs at the
    latency of each instruction, not at the machine's throughput; the generated lane loops
    then run k registers interleaved (:data:`mcchain.codegen.schedule.INTERLEAVE_CONSTANT`),
    whose independent chains fill the gaps."""
    k = MAX_REGISTERS
    while k > 1 and nrow * LMAX * k * 8 > GROUP_BYTES:
        k //= 2
    return LMAX * k


def row_meanings(fixed_step: bool) -> str:
    """Legend of the row map written into the header of a generated module; the fixed-step
    kernel's has no rows kqc, kvc (its stages write their rows kq{j}, kv{j} themselves:
    :class:`Layout`)."""
    stage = (
        "(each written by its stage, read by the next stage and by the step's combine);"
        if fixed_step
        else "kqc, kvc the first stage's; ys the stage's state (q, v);"
    )
    return f"""\
# W rows: P parameters (slots of Topology.slots); q, v state; kq{{j}}, kv{{j}} stage j (q', v');
# {stage} qn, vn the
# proposed state of an adaptive step; lam, lamc multipliers (accepted, current stage); chk,
# chkc max |Phi| (accepted, current); sg, sgc, sga rank-loss counts (accepted, current, since
# the last check); act, pmax projection (still iterating, last max |Phi|); hs the lane's step;
# tl the lane's time; pk five rows per |joint force| then per |driver torque|: its last four
# values and its continuous peak (mcchain.kernels.peaks); pkt their four times and the count;
# pkf the cubic checks the last point fed asks for (1 interior, 2 first step, 3 both).
"""


OUTPUT_ROW_MEANINGS = """\
# [[output]]s: ot OUTPUT_WIDTH rows each, their running reductions; otk their four times and
# the count fed (mcchain.kernels.outputs). Adaptive kernel only: otd each output's data for
# the lane's sample (point, window, threshold); ofr its tabulated reference's x, y and rates
# at the lane's state; ofv its signal and rate there; ofl 1 where its step is left to the
# full feed; ofs 1 where the lane's state is new (fed).
"""
"""Legend of the output rows, written only into modules that have them."""

CONTACT_ROWS = (
    "fm", "ins", "vi", "pd", "pr", "pdc", "prc", "wjc", "dwl",
    "nim", "pkd", "tff", "tse",
)  # fmt: skip
"""Rows of W per contact-law joint (one row per such joint each), after the others."""

CONTACT_ROW_MEANINGS = """\
# Contact-law joints, one row each: fm law active (0 link, 1 law); ins in contact at the
# step's start; vi approach speed of the contact in progress; pd, pr penetration and its rate
# at the accepted state; pdc, prc the same at the current stage; wjc the contact's pulsation^2
# at the current stage; dwl time pressed quasi-statically (model auto: re-seat); nim impacts;
# pkd peak penetration (the peak contact force is its joint's pk peak); tff free-flight
# time; tse first separation time; wca largest (contact pulsation)^2 since the last check;
# wcc the largest at the current stage; rsw lane to re-seat; e0 its energy before the
# re-seat.
"""
"""Legend of the contact rows, written only into modules that have them."""

FIXED_STEP_ROW_MEANINGS = """\
# Fixed-step kernels only: alv 1 while the lane's sample has no failure bit, ncl 1 while it
# has no contact_lost bit; att 1 where the step's checks may change its status; sc0 sin and
# cos of each body's angle at the step's start, scc at the current stage; gdet per ideal
# revolute joint to the ground the determinant of its block of S and its inverse.
"""
"""Legend of the rows only the fixed-step kernels have."""

ADAPTIVE_ROW_MEANINGS = """\
# Adaptive kernel only: en the error norm of the lane's attempted step; lnd 1 where the lane
# is on an output time (its outputs are written after the lanes' checks), itw that output's
# index; smp the sample in the lane; fsm 1 where its first stage is to compute (a fresh
# sample, a re-seat); dne 1 where its sample is finished (the lane takes the next one); acc 1
# where its step was accepted (its new state is copied in after the lanes' acceptance); ost
# the lane's history point (every lane's computed at once, the landed lanes' then stored).
"""
"""Legend of the rows only the adaptive kernel has."""


class Layout:
    """Rows of the flat work array W (each ``lmax`` long, default :data:`LMAX`) of one
    lane group."""

    def __init__(
        self,
        topo: Topology,
        nstage: int,
        lmax: int | None = None,
        adaptive: bool = False,
        outputs: int = 0,
        fixed_step: bool = False,
    ):
        """``adaptive``: with the rows only the adaptive kernel uses (``pw``: ω_c² at the
        accepted state, per contact-law joint, for the located re-seat dwell); ``outputs``:
        the number of ``[[output]]``s (rows ``ot``, OUTPUT_WIDTH each, and their clock
        ``otk``: mcchain.kernels.outputs), last; ``fixed_step``: the fixed-step kernel's,
        without rows kqc, kvc (its stages write their own rows: :meth:`stage_at`)."""
        self.lmax = LMAX if lmax is None else lmax
        self.fixed_step = fixed_step
        self.rows: dict[str, int] = {}
        self.size = 0
        ncon1 = max(topo.ncon, 1)
        self.add("P", len(topo.slots()))
        self.add("q", topo.ndof)
        self.add("v", topo.ndof)
        for j in range(nstage):  # stage j: kq_j then kv_j, 2 ndof consecutive rows
            self.add(f"kq{j}", topo.ndof)
            self.add(f"kv{j}", topo.ndof)
        if not fixed_step:
            self.add("kqc", topo.ndof)  # the first stage's, copied to kq0 where it starts
            self.add("kvc", topo.ndof)
            self.add("ys", 2 * topo.ndof)  # the stage's state (q, v)
        self.add("qn", topo.ndof)
        self.add("vn", topo.ndof)
        self.add("lam", ncon1)
        self.add("lamc", ncon1)
        for name in ("chk", "sg", "chkc", "sgc", "sga", "act", "pmax", "hs", "tl"):
            self.add(name, 1)
        self.add("pk", PEAK_WIDTH * (topo.njoint + topo.ndriver))
        self.add("pkt", PEAK_CLOCK)
        self.add("pkf", topo.njoint + topo.ndriver)
        ncj = len(topo.contact_joints)
        if ncj:
            for name in CONTACT_ROWS:
                self.add(name, ncj)
            self.add("wca", 1)
            self.add("wcc", 1)
            self.add("rsw", 1)
            self.add("e0", 1)
            if adaptive:
                self.add("pw", ncj)
        if adaptive:
            for name in ("en", "lnd", "itw", "smp", "fsm", "dne", "acc"):
                self.add(name, 1)
            self.add("ost", len(history_stores(topo)))
        else:
            for name in ("alv", "ncl", "att"):
                self.add(name, 1)
            self.add("sc0", 2 * topo.nbody)  # sin θ, cos θ of each body at the step's start
            self.add("scc", 2 * topo.nbody)  # ... at the current stage
            self.add("gdet", 2 * len(topo.ground_revolutes))  # per such joint: det, 1/det
        if outputs:
            self.add("ot", OUTPUT_WIDTH * outputs)
            self.add("otk", PEAK_CLOCK)
            if adaptive:  # the feed of all lanes at once (mcchain.codegen.output_blocks)
                self.add("otd", OUTPUT_SAMPLE_COLUMNS * outputs)
                self.add("ofr", 4 * outputs)
                self.add("ofv", 2 * outputs)
                self.add("ofl", outputs)
                self.add("ofs", 1)

    def row_map(self, title: str) -> str:
        """A comment block naming the rows of W (first-last) under ``title``."""
        names = list(self.rows)
        items = []
        for i, name in enumerate(names):
            start = self.rows[name]
            end = self.rows[names[i + 1]] if i + 1 < len(names) else self.size
            items.append(f"{name} {start}" if end - start == 1 else f"{name} {start}-{end - 1}")
        lines = [f"# W rows of {title}; element W[row * {self.lmax} + lane]:"]
        for item in items:
            if lines[-1].endswith(":"):
                lines.append("#   " + item)
            elif len(lines[-1]) + len(item) + 2 > 96:
                lines[-1] += ","
                lines.append("#   " + item)
            else:
                lines[-1] += ", " + item
        return "\n".join(lines) + "\n"

    def add(self, name: str, count: int) -> None:
        self.rows[name] = self.size
        self.size += count

    def at(self, name: str, i: int = 0) -> str:
        return f"W[{(self.rows[name] + i) * self.lmax} + l]"

    def stage_at(self, i: int, base: str) -> str:
        """Element ``i`` of a stage's rows kq{j}, kv{j} (q' rows 0..ndof-1, then v') of lane
        ``l``, the stage's first element at the run-time offset ``base`` (the fixed-step
        kernel's ``kw``: this stage's rows, ``kr``: the previous stage's; templates.ERK_KERNEL).
        The offset is the same for every lane, so the lane loops stay vectorised."""
        return f"W[{base} + {i * self.lmax} + l]"

    def at_index(self, name: str, index: str, shift: int = 0) -> str:
        """Element of row ``name`` + ``shift`` + the loop variable ``index`` (generated loops
        over rows)."""
        return f"W[({self.rows[name] + shift} + {index}) * {self.lmax} + l]"
