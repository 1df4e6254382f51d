"""Straight-line code of one lane of a :class:`~mcchain.codegen.topology.Topology`.

:class:`Emitter` writes the index-1 acceleration (Schur complement S = B M⁻¹ Bᵀ, sparse
LDLᵀ in a bandwidth-reducing row order), the constraint projection and the outputs (joint
forces, energy, max |Φ|); the generator (``generate.py``) puts these blocks into the time
loops of ``templates.py``. :func:`sincos_code` is the branch-free sine/cosine it inlines.

Formulation: the constraints and forces of ``mcchain/kernels/joints.py`` and
``mcchain/kernels/forces.py``, whose conventions are mirrored (rotated point p = A(θ) s,
d = r_b + p_b − r_a − p_a, springs with rest length 0 isotropic).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from mcchain.codegen.inline import inline
from mcchain.codegen.topology import Topology
from mcchain.model import GROUND, JOINT_CLEARANCE, JOINT_IDEAL, JOINT_PRISMATIC
from mcchain.scene.compile import spline_value

CONTACT_KERNELS = "mcchain.kernels.contact"
"""The module whose functions define the contact law for the loop kernels and the lanes."""

# ---------------------------------------------------------------------------------------------
# sin / cos: fdlibm kernels on [-π/4, π/4] after a three-part Cody–Waite reduction. Branch-free
# (quadrant chosen by exact 0/1 and ±1 factors), so the lane loop vectorises, and free of
# function calls: rounding to an integer is (y + 1.5·2⁵²) − 1.5·2⁵², exact for |y| < 2⁵¹ (so
# for |x| < 3.5e15 rad; the reduction itself stays ≤ 1 ulp-ish for |x| < 1e6 rad). Calls such
# as np.floor cost numba's type inference more than anything else in generated code.

TWO_PI = 2.0 * math.pi
_ROUND = "6755399441055744.0"  # 1.5 · 2⁵²: adding and subtracting it rounds to an integer

_SINCOS_TEMPLATE = "\n".join(
    [
        f"{{k}} = ({{x}} * 0.6366197723675814 + {_ROUND}) - {_ROUND}",
        "{r} = (({x} - {k} * 1.5707963267341256) - {k} * 6.077100506303966e-11)"
        " - {k} * 2.0222662487111665e-21",
        "{z} = {r} * {r}",
        "{ps} = {r} + ({z} * {r}) * (-0.16666666666666632 + {z} * (0.008333333333322489"
        " + {z} * (-0.00019841269829857949 + {z} * (2.755731370707007e-06"
        " + {z} * (-2.5050760253406863e-08 + {z} * 1.5896909952115501e-10)))))",
        "{hz} = 0.5 * {z}",
        "{w} = 1.0 - {hz}",
        "{pc} = {w} + (((1.0 - {w}) - {hz}) + {z} * ({z} * (0.0416666666666666"
        " + {z} * (-0.0013888888888874109 + {z} * (2.480158728947673e-05"
        " + {z} * (-2.7557314351390663e-07 + {z} * (2.087572321298175e-09"
        " + {z} * -1.1359647557788195e-11)))))))",
        # Quadrant j = k mod 4 ∈ {0, 1, 2, 3}; floor(k / 4) and h = floor(j / 2) are roundings
        # of k/4 − 3/8 and j/2 − 1/4 (never a tie). h: j ≥ 2; sw: odd j (sine and cosine swap);
        # the sine's sign is 1 − 2h, the cosine's (1 − 2h)(1 − 2 sw).
        f"{{j}} = {{k}} - 4.0 * ((({{k}} * 0.25 - 0.375) + {_ROUND}) - {_ROUND})",
        f"{{h}} = (({{j}} * 0.5 - 0.25) + {_ROUND}) - {_ROUND}",
        "{sw} = {j} - 2.0 * {h}",
        "{ss} = 1.0 - 2.0 * {h}",
        "{sa} = {sw} * {pc} + (1.0 - {sw}) * {ps}",
        "{ca} = {sw} * {ps} + (1.0 - {sw}) * {pc}",
        "{sin} = {ss} * {sa}",
        "{cos} = ({ss} * (1.0 - 2.0 * {sw})) * {ca}",
    ]
)


def sincos_code(x: str, sin: str, cos: str, tag: str) -> list[str]:
    """Lines computing ``sin``/``cos`` of the expression ``x`` (temporaries suffixed ``tag``)."""
    temps = ("k", "r", "z", "ps", "hz", "w", "pc", "j", "h", "sw", "ss", "sa", "ca")
    names = {n: f"_{n}{tag}" for n in temps}
    return _SINCOS_TEMPLATE.format(x=x, sin=sin, cos=cos, **names).splitlines()


# ---------------------------------------------------------------------------------------------
# Symbolic helpers: a coefficient is a float constant or the name of a scalar variable.

Coef = float | str


def _mul(*factors: Coef) -> Coef:
    const = 1.0
    names = []
    for f in factors:
        if isinstance(f, str):
            names.append(f)
        else:
            const *= f
    if const == 0.0:
        return 0.0
    if not names:
        return const
    expr = " * ".join(names)
    if const == 1.0:
        return expr
    if const == -1.0:
        return f"(-{expr})" if len(names) == 1 else f"(-({expr}))"
    return f"({const!r} * {expr})"


def _sum(terms: list[Coef]) -> Coef:
    const = sum(t for t in terms if not isinstance(t, str))
    names = [t for t in terms if isinstance(t, str)]
    if not names:
        return float(const)
    expr = " + ".join(names)
    if const != 0.0:
        expr = f"{expr} + {const!r}"
    return f"({expr})" if len(names) > 1 or const != 0.0 else expr


def _row_order(pattern: list[set[int]]) -> list[int]:
    """A bandwidth-reducing order of the rows of S (reverse Cuthill–McKee on its graph)."""
    n = len(pattern)
    if n == 0:
        return []
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    rows, cols = [], []
    for i, nbrs in enumerate(pattern):
        for j in nbrs:
            rows.append(i)
            cols.append(j)
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    order = [int(i) for i in reverse_cuthill_mckee(graph, symmetric_mode=True)]

    # Keep the natural order when it is at least as narrow (chains are already banded).
    def bandwidth(perm: list[int]) -> int:
        pos = {r: i for i, r in enumerate(perm)}
        return max((abs(pos[i] - pos[j]) for i in range(n) for j in pattern[i]), default=0)

    natural = list(range(n))
    return natural if bandwidth(natural) <= bandwidth(order) else order


class Emitter:
    """Generates the straight-line code of one lane for a :class:`Topology`.

    Names in the generated code: ``q{i}``, ``v{i}`` the lane's coordinates and velocities,
    ``t`` the time, ``p_<slot>`` the parameters (loaded by :meth:`load_params`), ``lam{r}``
    the multipliers, ``qdd{i}`` the accelerations. Methods append lines to a list and return
    nothing; :meth:`code` returns them indented.
    """

    def __init__(self, topo: Topology):
        self.topo = topo
        self.slots = topo.slots()
        self.lines: list[str] = []
        self._rows_cache: list[dict[int, Coef]] | None = None
        names = {i: f"p_{name}" for name, i in self.slots.items()}
        self._where: Callable[[int], str] = names.__getitem__  # before load_params: the names
        # Contact-law joints: joint -> its constraint row; the per-lane state they read
        # (fm: law active, ins: in contact at the step's start, vi: approach speed δ̇⁻).
        self.contact_row = {k: topo.joint_row[k] for k in topo.contact_joints}
        self._contact_state: Callable[[str, int], str] = lambda name, k: "0.0"

    def contact_source(self, where: Callable[[str, int], str]) -> None:
        """Where the contact state ``fm``/``ins``/``vi`` of joint k is read (default 0: the
        link, as in the Python-facing kernels)."""
        self._contact_state = where

    def _load_contact_state(self, *names: str) -> None:
        for k in self.contact_row:
            self.emit(*(f"{n}{k} = {self._contact_state(n, k)}" for n in names))

    def _row_law(self, r: int) -> str | None:
        """``fm{k}`` (1 while the law replaces the link, else 0) for the row of a contact
        joint, None for the other rows.

        Every blend between the link and the law is a select on it (``x if fm == 0.0 else
        y``), never a product by 0/1: under fastmath "contract" LLVM may fuse a product by
        1.0 with the next addition and round once where the link alone rounds twice, and
        the model auto must give the link's values bit for bit while the link holds.
        """
        for k, row in self.contact_row.items():
            if row == r:
                return f"fm{k}"
        return None

    # -- plumbing --------------------------------------------------------------------------
    def emit(self, *lines: str) -> None:
        self.lines.extend(lines)

    def take(self, indent: int) -> str:
        pad = " " * indent
        text = "\n".join(pad + line if line else "" for line in self.lines)
        self.lines = []
        return text

    def load_params(self, where: Callable[[int], str]) -> None:
        """``p_<slot> = where(slot index)`` for every parameter slot; later blocks may load a
        parameter again from ``where`` (:meth:`_reload`)."""
        self._where = where
        for name, i in self.slots.items():
            self.emit(f"p_{name} = {where(i)}")

    def _reload(self, name: str) -> str:
        """A fresh load of parameter ``p_<name>`` (from the last :meth:`load_params`): at the
        end of a long body a load is cheaper than keeping the value from the start."""
        return self._where(self.slots[name])

    # -- kinematics ------------------------------------------------------------------------
    def bodies(self, q: str = "q", tag: str = "") -> None:
        """sin/cos of every body angle: ``s{b}``, ``c{b}``."""
        for b in range(self.topo.nbody):
            self.emit(*sincos_code(f"{q}{3 * b + 2}", f"sn{b}{tag}", f"cs{b}{tag}", f"{b}{tag}"))

    def _point(self, body: int, sx: str, sy: str, name: str, q: str = "q", tag: str = "") -> None:
        """Rotated point ``{name}x/y`` = A s and absolute point ``{name}X/Y`` = r + A s."""
        if body == GROUND:
            self.emit(f"{name}x = {sx}", f"{name}y = {sy}", f"{name}X = {sx}", f"{name}Y = {sy}")
            return
        c, s = f"cs{body}{tag}", f"sn{body}{tag}"
        self.emit(
            f"{name}x = {c} * {sx} - {s} * {sy}",
            f"{name}y = {s} * {sx} + {c} * {sy}",
            f"{name}X = {q}{3 * body} + {name}x",
            f"{name}Y = {q}{3 * body + 1} + {name}y",
        )

    def _point_velocity(self, body: int, name: str, v: str = "v") -> None:
        """Velocity ``{name}vx/vy`` of point ``name`` (zero on the ground)."""
        if body == GROUND:
            self.emit(f"{name}vx = 0.0", f"{name}vy = 0.0")
            return
        w = f"{v}{3 * body + 2}"
        self.emit(
            f"{name}vx = {v}{3 * body} - {w} * {name}y",
            f"{name}vy = {v}{3 * body + 1} + {w} * {name}x",
        )

    def joints(self, q: str = "q", tag: str = "") -> None:
        """Points ``pa{k}``, ``pb{k}`` and separation ``dx{k}``, ``dy{k}`` of every joint."""
        topo = self.topo
        for k in range(topo.njoint):
            a, b = topo.joint_a[k], topo.joint_b[k]
            self._point(a, f"p_sax{k}", f"p_say{k}", f"pa{k}", q, tag)
            self._point(b, f"p_sbx{k}", f"p_sby{k}", f"pb{k}", q, tag)
            self.emit(f"dx{k} = pb{k}X - pa{k}X", f"dy{k} = pb{k}Y - pa{k}Y")
            if topo.joint_kind[k] == JOINT_CLEARANCE:
                # One division per joint: ex, ey and γ multiply by 1/ρ. Under a contact law
                # the journal may sit at the bearing centre (ρ = 0, written there): no normal,
                # and none needed (F_n = 0 there), so n = 0 rather than NaN.
                inverse = (
                    f"1.0 / rho{k} if rho{k} > 0.0 else 0.0"
                    if k in self.contact_row
                    else f"1.0 / rho{k}"
                )
                self.emit(
                    f"rho{k} = math.sqrt(dx{k} * dx{k} + dy{k} * dy{k})",
                    f"irho{k} = {inverse}",
                    f"ex{k} = dx{k} * irho{k}",
                    f"ey{k} = dy{k} * irho{k}",
                )
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                # n = A_a Ω u, the axis' normal, and B's θ_a entry n·(−Ω p_a) + (Ω n)·d
                if a == GROUND:
                    self.emit(f"nx{k} = -p_uy{k}", f"ny{k} = p_ux{k}")
                else:
                    c, sn = f"cs{a}{tag}", f"sn{a}{tag}"
                    self.emit(
                        f"nx{k} = -{c} * p_uy{k} - {sn} * p_ux{k}",
                        f"ny{k} = -{sn} * p_uy{k} + {c} * p_ux{k}",
                        f"pta{k} = nx{k} * (pa{k}y + dy{k}) - ny{k} * (pa{k}x + dx{k})",
                    )
                if k in topo.slider_drivers.values():
                    # u = A_a u_0 the axis itself (Ω u = n), and B's θ_a entry of u·d
                    if a == GROUND:
                        self.emit(f"ax{k} = p_ux{k}", f"ay{k} = p_uy{k}")
                    else:
                        self.emit(
                            f"ax{k} = ny{k}",
                            f"ay{k} = -nx{k}",
                            f"ptu{k} = ax{k} * (pa{k}y + dy{k}) - ay{k} * (pa{k}x + dx{k})",
                        )

    def rows(self) -> list[dict[int, Coef]]:
        """Non-zeros of each row of B as {column: coefficient} (after :meth:`joints`)."""
        if self._rows_cache is not None:
            return self._rows_cache
        topo = self.topo
        rows: list[dict[int, Coef]] = []

        def point_row(body: int, sign: float, wx: Coef, wy: Coef, px: str, py: str) -> dict:
            if body == GROUND:
                return {}
            # sign · w·∂(r + p)/∂q = sign · (wx, wy, −wx py + wy px)
            return {
                3 * body: _mul(sign, wx),
                3 * body + 1: _mul(sign, wy),
                3 * body + 2: _sum([_mul(-sign, wx, py), _mul(sign, wy, px)]),
            }

        for k in range(topo.njoint):
            a, b = topo.joint_a[k], topo.joint_b[k]
            pa, pb = (f"pa{k}x", f"pa{k}y"), (f"pb{k}x", f"pb{k}y")
            if topo.joint_kind[k] == JOINT_IDEAL:
                for wx, wy in ((1.0, 0.0), (0.0, 1.0)):
                    row = point_row(b, 1.0, wx, wy, *pb)
                    for col, val in point_row(a, -1.0, wx, wy, *pa).items():
                        row[col] = val
                    rows.append({c: v for c, v in row.items() if v != 0.0})
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                row = point_row(b, 1.0, f"nx{k}", f"ny{k}", *pb)
                row.update(point_row(a, -1.0, f"nx{k}", f"ny{k}", *pa))
                angle: dict[int, Coef] = {}
                if a != GROUND:
                    row[3 * a + 2] = f"pta{k}"
                    angle[3 * a + 2] = -1.0
                if b != GROUND:
                    angle[3 * b + 2] = 1.0
                rows += [row, angle]
            else:
                ex, ey = f"ex{k}", f"ey{k}"
                row = point_row(b, 1.0, ex, ey, *pb)
                row.update(point_row(a, -1.0, ex, ey, *pa))
                rows.append(row)
        for d in range(topo.ndriver):
            g = topo.slider_drivers.get(d)
            if g is None:
                rows.append({3 * topo.driver_body[d] + 2: 1.0})
                continue
            a, b = topo.joint_a[g], topo.joint_b[g]
            row = point_row(b, 1.0, f"ax{g}", f"ay{g}", f"pb{g}x", f"pb{g}y")
            row.update(point_row(a, -1.0, f"ax{g}", f"ay{g}", f"pa{g}x", f"pa{g}y"))
            if a != GROUND:
                row[3 * a + 2] = f"ptu{g}"
            rows.append(row)
        self._rows_cache = rows
        return rows

    def constraint_values(self, t: str = "t", q: str = "q", v: str | None = "v") -> None:
        """``phi{r}`` (and ``phid{r}`` = Φ̇ if ``v``) and ``phimax`` = max |Φ|."""
        topo = self.topo
        for k in range(topo.njoint):
            r = topo.joint_row[k]
            if v is not None:
                self._point_velocity(topo.joint_a[k], f"pa{k}", v)
                self._point_velocity(topo.joint_b[k], f"pb{k}", v)
                self.emit(f"ddx{k} = pb{k}vx - pa{k}vx", f"ddy{k} = pb{k}vy - pa{k}vy")
            if topo.joint_kind[k] == JOINT_IDEAL:
                self.emit(f"phi{r} = dx{k}", f"phi{r + 1} = dy{k}")
                if v is not None:
                    self.emit(f"phid{r} = ddx{k}", f"phid{r + 1} = ddy{k}")
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                a, b = topo.joint_a[k], topo.joint_b[k]
                qa = f"{q}{3 * a + 2}" if a != GROUND else "0.0"
                qb = f"{q}{3 * b + 2}" if b != GROUND else "0.0"
                self.emit(
                    f"phi{r} = nx{k} * dx{k} + ny{k} * dy{k}",
                    f"phi{r + 1} = {qb} - {qa} - p_rel{k}",
                )
                if v is not None:
                    va = f"{v}{3 * a + 2}" if a != GROUND else "0.0"
                    vb = f"{v}{3 * b + 2}" if b != GROUND else "0.0"
                    self.emit(
                        f"phid{r} = nx{k} * ddx{k} + ny{k} * ddy{k} + {va} * "
                        f"(-ny{k} * dx{k} + nx{k} * dy{k})",
                        f"phid{r + 1} = {vb} - {va}",
                    )
            else:
                self.emit(f"phi{r} = rho{k} - p_cl{k}")
                if v is not None:
                    self.emit(f"phid{r} = ex{k} * ddx{k} + ey{k} * ddy{k}")
        for d in range(topo.ndriver):
            # f = f0 + rate · t (+ A (sin(Ω t + φ) − sin φ), Ω = 2π f; hs, hc, hw serve γ too)
            r = topo.driver_row[d]
            swing, swing_rate = "", ""
            if topo.driver_tables and topo.driver_tables[d]:  # g(t) − g(0), ġ, g̈ (g̈ serves γ)
                knots, coef = topo.driver_tables[d]
                self.emit(
                    f"tvs{d} = spline_at(TK{d}, TC{d}, {len(knots)}, {t})",
                    f"tv{d} = tvs{d}[0]",
                    f"tv1{d} = tvs{d}[1]",
                    f"tv2{d} = tvs{d}[2]",
                )
                start = spline_value(np.asarray(knots), np.asarray(coef), 0.0)
                swing, swing_rate = f" - (tv{d} - {start!r})", f" + tv1{d}"
            if d in topo.harmonic_drivers:
                self.emit(f"hw{d} = {TWO_PI!r} * p_frq{d}")
                self.emit(*sincos_code(f"(hw{d} * {t} + p_pha{d})", f"hs{d}", f"hc{d}", f"h{d}"))
                self.emit(*sincos_code(f"p_pha{d}", f"hp{d}", f"_hpc{d}", f"hp{d}"))
                swing = f" - p_amp{d} * (hs{d} - hp{d})"
                swing_rate = f" + p_amp{d} * hw{d} * hc{d}"
            g = topo.slider_drivers.get(d)
            if g is None:  # θ − θ0 − ω t
                i = 3 * topo.driver_body[d] + 2
                rate = f"(p_om{d}{swing_rate})" if swing_rate else f"p_om{d}"
                self.emit(f"phi{r} = {q}{i} - p_th0_{d} - p_om{d} * {t}{swing}")
                if v is not None:
                    self.emit(f"phid{r} = {v}{i} - {rate}")
                continue
            # a slider driver: u·d − s0 − v t
            a = topo.joint_a[g]
            rate = f"(p_spd{d}{swing_rate})" if swing_rate else f"p_spd{d}"
            along = f"ax{g} * dx{g} + ay{g} * dy{g}"
            self.emit(f"phi{r} = {along} - p_s0_{d} - p_spd{d} * {t}{swing}")
            if v is not None:
                turn = (
                    f" + {v}{3 * a + 2} * (-ay{g} * dx{g} + ax{g} * dy{g})" if a != GROUND else ""
                )
                self.emit(f"phid{r} = ax{g} * ddx{g} + ay{g} * ddy{g}{turn} - {rate}")
        # A running max (numba's max of many arguments is the same left fold): with demand
        # ordering each Φ_r is then consumed where it is made instead of kept to the end.
        terms = []
        for r in range(topo.ncon):
            law = self._row_law(r)
            terms.append(
                f"abs(phi{r})" if law is None else f"(abs(phi{r}) if {law} == 0.0 else 0.0)"
            )
        self.emit("phimax = 0.0", *(f"phimax = max(phimax, {t})" for t in terms))

    def gamma(self, v: str = "v", baumgarte: bool = True) -> None:
        """``gam{r}``: B q̈ = γ − 2α Φ̇ − β² Φ (after :meth:`constraint_values` with v)."""
        topo = self.topo
        for k in range(topo.njoint):
            r = topo.joint_row[k]
            a, b = topo.joint_a[k], topo.joint_b[k]
            wa2 = f"{v}{3 * a + 2} * {v}{3 * a + 2}" if a != GROUND else None
            wb2 = f"{v}{3 * b + 2} * {v}{3 * b + 2}" if b != GROUND else None
            for ax in ("x", "y"):
                parts = []
                if wb2:
                    parts.append(f"pb{k}{ax} * {wb2}")
                if wa2:
                    parts.append(f"- pa{k}{ax} * {wa2}")
                expr = " ".join(parts) if parts else "0.0"
                if expr.startswith("- "):
                    expr = "-" + expr[2:]
                self.emit(f"cq{ax}{k} = {expr}")
            if topo.joint_kind[k] == JOINT_IDEAL:
                self.emit(f"gam{r} = cqx{k}", f"gam{r + 1} = cqy{k}")
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                # n·(p_b θ̇_b² − p_a θ̇_a²) + θ̇_a² n·d − 2 θ̇_a (Ω n)·ḋ
                expr = f"nx{k} * cqx{k} + ny{k} * cqy{k}"
                if wa2:
                    wa = f"{v}{3 * a + 2}"
                    expr += (
                        f" + {wa2} * (nx{k} * dx{k} + ny{k} * dy{k})"
                        f" - 2.0 * {wa} * (-ny{k} * ddx{k} + nx{k} * ddy{k})"
                    )
                self.emit(f"gam{r} = {expr}", f"gam{r + 1} = 0.0")
            else:
                self.emit(
                    f"gam{r} = ex{k} * cqx{k} + ey{k} * cqy{k} - (ddx{k} * ddx{k} + ddy{k} * ddy{k}"
                    f" - phid{r} * phid{r}) * irho{k}"
                )
        for d in range(topo.ndriver):
            r = topo.driver_row[d]
            terms = []
            g = topo.slider_drivers.get(d)
            if g is not None:  # −(Ḃ q̇) of u·d, as a prismatic offset row with u for n
                a = topo.joint_a[g]
                terms.append(f"ax{g} * cqx{g} + ay{g} * cqy{g}")
                if a != GROUND:
                    wa, wa2 = f"{v}{3 * a + 2}", f"{v}{3 * a + 2} * {v}{3 * a + 2}"
                    terms.append(
                        f"{wa2} * (ax{g} * dx{g} + ay{g} * dy{g})"
                        f" - 2.0 * {wa} * (-ay{g} * ddx{g} + ax{g} * ddy{g})"
                    )
            if d in topo.harmonic_drivers:  # −Φ_tt = f̈ = −A Ω² sin(Ω t + φ)
                terms.append(f"-(p_amp{d} * hw{d} * hw{d} * hs{d})")
            if topo.driver_tables and topo.driver_tables[d]:  # f̈ of the table's spline
                terms.append(f"tv2{d}")
            self.emit(f"gam{r} = " + (" + ".join(terms) if terms else "0.0"))
        if baumgarte:
            for r in range(topo.ncon):
                self.emit(f"gam{r} = gam{r} - balpha2 * phid{r} - bbeta2 * phi{r}")

    def loaded_bodies(self) -> set[int]:
        """Bodies carrying a load or a spring (the others feel gravity only)."""
        topo = self.topo
        bodies = set(topo.force_body) | set(topo.spring_a) | set(topo.spring_b)
        return bodies - {GROUND}

    def forces(self, q: str = "q", v: str = "v", tag: str = "", t: str = "t") -> None:
        """Generalised applied forces ``F{i}`` (gravity, loads, springs) of the bodies in
        :meth:`loaded_bodies` (the free acceleration of the others is g); a harmonic load is
        multiplied by ``lf{f}`` = sin(2π f t + φ)."""
        topo = self.topo
        for b in sorted(self.loaded_bodies()):
            self.emit(
                f"F{3 * b} = p_m{b} * p_gx", f"F{3 * b + 1} = p_m{b} * p_gy", f"F{3 * b + 2} = 0.0"
            )
        for f, b in enumerate(topo.force_body):
            if b == GROUND:
                continue
            self._point(b, f"p_fpx{f}", f"p_fpy{f}", f"fp{f}", q, tag)
            if f in topo.varying_loads:
                if f in topo.harmonic_loads:
                    arg = f"({TWO_PI!r} * p_ffr{f} * {t} + p_fph{f})"
                    self.emit(*sincos_code(arg, f"lf{f}", f"_lfc{f}", f"lf{f}{tag}"))
                else:  # a table's spline
                    n = len(topo.load_tables[f][0])
                    self.emit(f"lfs{f} = spline_at(FK{f}, FC{f}, {n}, {t})", f"lf{f} = lfs{f}[0]")
                self.emit(
                    f"F{3 * b} += lf{f} * p_fx{f}",
                    f"F{3 * b + 1} += lf{f} * p_fy{f}",
                    f"F{3 * b + 2} += lf{f} * (fp{f}x * p_fy{f} - fp{f}y * p_fx{f} + p_tq{f})",
                )
                continue
            self.emit(
                f"F{3 * b} += p_fx{f}",
                f"F{3 * b + 1} += p_fy{f}",
                f"F{3 * b + 2} += fp{f}x * p_fy{f} - fp{f}y * p_fx{f} + p_tq{f}",
            )
        for s in range(len(topo.spring_a)):
            a, b = topo.spring_a[s], topo.spring_b[s]
            self._point(a, f"p_spax{s}", f"p_spay{s}", f"sa{s}", q, tag)
            self._point(b, f"p_spbx{s}", f"p_spby{s}", f"sb{s}", q, tag)
            self._point_velocity(a, f"sa{s}", v)
            self._point_velocity(b, f"sb{s}", v)
            self.emit(
                f"ux{s} = sb{s}X - sa{s}X",
                f"uy{s} = sb{s}Y - sa{s}Y",
                f"dux{s} = sb{s}vx - sa{s}vx",
                f"duy{s} = sb{s}vy - sa{s}vy",
                f"len{s} = math.sqrt(ux{s} * ux{s} + uy{s} * uy{s})",
                # iso: rest length 0, an isotropic spring −k u − c u̇ (as forces.py).
                f"iso{s} = (p_l0{s} == 0.0) * 1.0",
                f"ilen{s} = (1.0 - iso{s}) / (len{s} + iso{s})",
                f"snx{s} = ux{s} * ilen{s}",
                f"sny{s} = uy{s} * ilen{s}",
                f"ten{s} = p_k{s} * (len{s} - p_l0{s})"
                f" + p_cd{s} * (snx{s} * dux{s} + sny{s} * duy{s})",
                f"sfx{s} = iso{s} * (-p_k{s} * ux{s} - p_cd{s} * dux{s}) - ten{s} * snx{s}",
                f"sfy{s} = iso{s} * (-p_k{s} * uy{s} - p_cd{s} * duy{s}) - ten{s} * sny{s}",
            )
            for body, sign, pt in ((b, "+", f"sb{s}"), (a, "-", f"sa{s}")):
                if body == GROUND:
                    continue
                self.emit(
                    f"F{3 * body} {sign}= sfx{s}",
                    f"F{3 * body + 1} {sign}= sfy{s}",
                    f"F{3 * body + 2} {sign}= {pt}x * sfy{s} - {pt}y * sfx{s}",
                )

    # -- Schur complement and its sparse LDLᵀ ---------------------------------------------
    def _minv(self, col: int) -> str:
        return f"p_{self._minv_slot(col)}"

    def _minv_slot(self, col: int) -> str:
        """Parameter slot of M⁻¹ at coordinate ``col`` (1/m or 1/J of its body)."""
        b, k = divmod(col, 3)
        return f"iJ{b}" if k == 2 else f"im{b}"

    def schur_factor(self) -> None:
        """``Wt{r}_{c}`` = (M⁻¹Bᵀ)ᵀ, S = B M⁻¹ Bᵀ and its LDLᵀ; ``sing`` counts dropped pivots.

        A pivot ``d_j ≤ tau · S_jj`` is dropped (its inverse set to 0: the row is treated as
        dependent on the previous ones, λ_j = 0) and counted in ``sing``; integrators either
        flag the sample SINGULAR or, on the robust path, carry on with the basic solution.
        """
        rows = self.rows()
        n = len(rows)
        for r, row in enumerate(rows):
            for col, val in row.items():
                self.emit(f"Wt{r}_{col} = {_mul(val, self._minv(col))}")
        pattern = [{j for j in range(n) if set(rows[i]) & set(rows[j])} for i in range(n)]
        order = _row_order(pattern)
        self.order = order
        # Entries of S in the permuted numbering (i, j: positions), lower part.
        pos = {r: i for i, r in enumerate(order)}
        S: dict[tuple[int, int], str] = {}
        # A row whose joint is under the contact law (fm = 1) is replaced by λ_r = F_n:
        # its S row and column become the unit vector (so the factors keep their pattern)
        # and the coupling S_jr F_n moves to the right-hand side (:meth:`acceleration`). In
        # link mode (fm = 0) the selects give the values of the link alone.
        self.coupling: dict[tuple[int, int], str] = {}
        for ri in range(n):
            for rj in pattern[ri]:
                i, j = pos[ri], pos[rj]
                if j > i:
                    continue
                terms = [_mul(rows[ri][c], f"Wt{rj}_{c}") for c in set(rows[ri]) & set(rows[rj])]
                laws = sorted({x for x in (self._row_law(ri), self._row_law(rj)) if x})
                if not laws:
                    self.emit(f"S{i}_{j} = {_sum(terms)}")
                else:
                    self.emit(f"Sx{i}_{j} = {_sum(terms)}")
                    self.coupling[ri, rj] = self.coupling[rj, ri] = f"Sx{i}_{j}"
                    held = " + ".join(laws) + " == 0.0"
                    unit = "1.0" if i == j else "0.0"
                    self.emit(f"S{i}_{j} = Sx{i}_{j} if {held} else {unit}")
                S[i, j] = f"S{i}_{j}"
        # Symbolic fill: L_ij nonzero if S_ij nonzero or L_ik, L_jk nonzero for some k < j.
        L: set[tuple[int, int]] = set()
        lower: list[set[int]] = [set() for _ in range(n)]  # lower[i] = {k < i : L_ik != 0}
        for j in range(n):
            for i in range(j + 1, n):
                if (i, j) in S or (lower[i] & lower[j]):
                    L.add((i, j))
                    lower[i].add(j)

        for j in range(n):
            prods = [f"L{j}_{k} * E{j}_{k}" for k in sorted(lower[j])]
            dj = S[j, j] + ("" if not prods else " - (" + " + ".join(prods) + ")")
            self.emit(
                f"D{j} = {dj}",
                f"okp{j} = (D{j} > tau * {S[j, j]}) * 1.0",
                f"Di{j} = okp{j} / (okp{j} * D{j} + (1.0 - okp{j}))",
            )
            for i in range(j + 1, n):
                if (i, j) not in L:
                    continue
                common = sorted(lower[i] & lower[j])
                sij = S.get((i, j), "0.0")
                prods = [f"L{i}_{k} * E{j}_{k}" for k in common]
                num = sij + ("" if not prods else " - (" + " + ".join(prods) + ")")
                self.emit(f"E{i}_{j} = {num}", f"L{i}_{j} = E{i}_{j} * Di{j}")
            # E{i}_{j} = L_ij d_j is needed by later columns (for rows i > j).
        self.emit("sing = 0.0", *(f"sing = sing + (1.0 - okp{j})" for j in range(n)))
        self._L = L
        self._lower = lower

    def schur_solve(self, rhs: str, out: str) -> None:
        """Solve S x = ``{rhs}{r}`` with the factors of :meth:`schur_factor`: ``{out}{r}``."""
        n = len(self.order)
        order = self.order
        for i in range(n):
            terms = [f"L{i}_{k} * y{out}{k}" for k in sorted(self._lower[i])]
            expr = f"{rhs}{order[i]}" + ("" if not terms else " - (" + " + ".join(terms) + ")")
            self.emit(f"y{out}{i} = {expr}")
        upper: list[list[int]] = [[] for _ in range(n)]  # upper[k] = rows i > k with L_ik
        for i, k in self._L:
            upper[k].append(i)
        for k in reversed(range(n)):
            terms = [f"L{i}_{k} * x{out}{i}" for i in sorted(upper[k])]
            expr = f"y{out}{k} * Di{k}" + ("" if not terms else " - (" + " + ".join(terms) + ")")
            self.emit(f"x{out}{k} = {expr}")
        for i in range(n):
            self.emit(f"{out}{order[i]} = x{out}{i}")

    def apply_wt(self, x: str, out: str, base: dict[int, Coef] | None) -> None:
        """``{out}{c}`` = base_c − M⁻¹_c Σ_r B_rc x_r  (base None: 0).

        Bᵀx first, then one product by M⁻¹ (loaded again): the entries of B (point
        coordinates, ±1) are fewer values to keep across the Schur solve than those of M⁻¹Bᵀ,
        and ±1 costs no product.
        """
        rows = self.rows()
        for c in range(self.topo.ndof):
            terms = [_mul(row[c], f"{x}{r}") for r, row in enumerate(rows) if c in row]
            head = base[c] if base else 0.0
            if not terms:
                self.emit(f"{out}{c} = {float(head) if isinstance(head, float) else head}")
                continue
            total = f"{self._reload(self._minv_slot(c))} * ({_sum(terms)})"
            self.emit(f"{out}{c} = -{total}" if head == 0.0 else f"{out}{c} = {head} - {total}")

    # -- whole blocks ----------------------------------------------------------------------
    def acceleration(self, t: str = "t", baumgarte: bool = True) -> None:
        """Index-1 accelerations ``qdd{i}``, multipliers ``lam{r}``, ``phimax``, ``sing``.

        Needs ``q{i}``, ``v{i}``, ``t`` and the parameters in scope; names ``balpha2`` (2α),
        ``bbeta2`` (β²) and ``tau`` (pivot tolerance) too.
        """
        topo = self.topo
        self._load_contact_state("fm", "ins", "vi")
        self.bodies()
        self.joints()
        self.constraint_values(t=t)
        self.gamma(baumgarte=baumgarte)
        self.forces(t=t)
        # Free accelerations M⁻¹F; a body under gravity alone has exactly (gx, gy, 0), and the
        # structural zeros drop out of the products below.
        loaded = self.loaded_bodies()
        a0: dict[int, Coef] = {}
        for c in range(topo.ndof):
            b, k = divmod(c, 3)
            if b in loaded:
                self.emit(f"a0_{c} = F{c} * {self._minv(c)}")
                a0[c] = f"a0_{c}"
            else:
                a0[c] = ("p_gx", "p_gy", 0.0)[k]
        rows = self.rows()
        for k in self.contact_row:
            self.contact_law(k)
            self.contact_friction(k, a0)
        for r, row in enumerate(rows):
            terms = [_mul(val, a0[c]) for c, val in row.items()]
            law = self._row_law(r)
            if law is None:
                self.emit(f"rhs{r} = {_sum(terms)} - gam{r}")
            else:
                k = next(j for j, rr in self.contact_row.items() if rr == r)
                self.emit(f"rhs{r} = ({_sum(terms)} - gam{r}) if {law} == 0.0 else fn{k}")
        self.schur_factor()
        for k, rk in self.contact_row.items():
            for r in range(len(rows)):
                if r != rk and (r, rk) in self.coupling:
                    moved = f"rhs{r} - fn{k} * {self.coupling[r, rk]}"
                    # a row under the law itself keeps its λ_r = F_n
                    held = f"fm{k} == 0.0" + (
                        f" or {self._row_law(r)} == 1.0" if self._row_law(r) else ""
                    )
                    self.emit(f"rhs{r} = rhs{r} if {held} else {moved}")
        self.contact_stiffness_check()
        self.schur_solve("rhs", "lam")
        self.apply_wt("lam", "qdd", a0)

    def inline(self, function: str, arguments: list[str], k: int) -> list[str]:
        """Emit the text of ``mcchain.kernels.contact.<function>(*arguments)`` for joint ``k``
        (:func:`mcchain.codegen.inline.inline`: the kernels' own definition, its locals
        suffixed with ``k``) and return the expressions of its results."""
        statements, results = inline(CONTACT_KERNELS, function, arguments, str(k))
        self.emit(*statements)
        return results

    def contact_law(self, k: int) -> None:
        """The normal force of contact joint ``k`` (after :meth:`constraint_values` with v):
        ``pen{k}`` δ, ``pdot{k}`` δ̇, ``fn{k}`` F_n, and ``kc{k}`` = fm ∂F_n/∂δ (for the
        step-size check only), from :func:`mcchain.kernels.contact.contact_law` inlined
        (the loop kernels call the same function).
        """
        r = self.contact_row[k]
        self.emit(f"pen{k} = rho{k} - p_cl{k}", f"pdot{k} = phid{r}")
        fn, delta_slope, _rate_slope = self.inline(
            "contact_law",
            [f"{x}{k}" for x in ("pen", "pdot", "ins", "vi", "p_K", "p_mx", "p_lw", "p_er")],
            k,
        )
        if fn != f"fn{k}":
            self.emit(f"fn{k} = {fn}")
        self.emit(f"kc{k} = fm{k} * {delta_slope}")

    def contact_friction(self, k: int, a0: dict[int, Coef]) -> None:
        """Regularised Coulomb friction of contact joint ``k`` under the law, added to the free
        accelerations ``a0`` of its two bodies (mcchain.kernels.contact.contact_slip and
        friction_force, inlined).

        The journal receives F_t t at its contact point (centre + R n), t = (−n_y, n_x), the
        bearing −F_t t at its own (centre + (R + c) n). On the link, and at μ = 0, the terms
        are exact zeros: a0 keeps its value bit for bit.
        """
        topo = self.topo
        a, b = topo.joint_a[k], topo.joint_b[k]
        wa = f"v{3 * a + 2}" if a != GROUND else "0.0"
        wb = f"v{3 * b + 2}" if b != GROUND else "0.0"
        (slip,) = self.inline(
            "contact_slip",
            [f"ex{k}", f"ey{k}", f"ddx{k}", f"ddy{k}", f"p_R{k}", f"p_cl{k}", wa, wb],
            k,
        )
        self.emit(f"slip{k} = {slip}")
        (ftn,) = self.inline("friction_force", [f"fn{k}", f"slip{k}", f"p_mu{k}"], k)
        self.emit(
            f"tx{k} = -ey{k}",
            f"ty{k} = ex{k}",
            f"ftn{k} = {ftn}",
            f"ft{k} = ftn{k} if fm{k} == 1.0 else 0.0",
            f"ftx{k} = ft{k} * tx{k}",
            f"fty{k} = ft{k} * ty{k}",
        )
        for body, sign, px, py, arm in (
            (b, "", f"pb{k}x", f"pb{k}y", f"p_R{k}"),
            (a, "-", f"pa{k}x", f"pa{k}y", f"(p_R{k} + p_cl{k})"),
        ):
            if body == GROUND:
                continue
            x, y, th = 3 * body, 3 * body + 1, 3 * body + 2
            torque = f"{sign}({px} * fty{k} - {py} * ftx{k} + {arm} * ft{k})"
            for c, force in ((x, f"{sign}ftx{k}"), (y, f"{sign}fty{k}"), (th, torque)):
                name = f"a0f{k}_{c}"
                self.emit(f"{name} = {a0[c]!s} + ({force}) * {self._minv(c)}")
                a0[c] = name

    def contact_stiffness_check(self) -> None:
        """``wc2`` = max over contact joints of ∂F_n/∂δ · S_rr (S_rr = 1/m*, the inverse
        effective mass along n): the square of the contact's linearised pulsation."""
        if not self.contact_row:
            return
        self.emit("wc2 = 0.0")
        for k, r in self.contact_row.items():
            self.emit(f"wj{k} = kc{k} * {self.coupling[r, r]}", f"wc2 = max(wc2, wj{k})")

    def projection_terms(self, t: str = "t") -> None:
        """Position and velocity corrections of a projection step at (q, v, t).

        ``dq{i}`` = −M⁻¹Bᵀ S⁻¹ Φ (Gauss–Newton in the M metric), ``dv{i}`` = −M⁻¹Bᵀ S⁻¹ Φ̇,
        plus ``phimax`` and ``sing`` (see :meth:`schur_factor`).
        """
        self._load_contact_state("fm")
        self.bodies()
        self.joints()
        self.constraint_values(t=t)
        for k, r in self.contact_row.items():  # no correction along a row under the law
            self.emit(
                f"phi{r} = phi{r} if fm{k} == 0.0 else 0.0",
                f"phid{r} = phid{r} if fm{k} == 0.0 else 0.0",
            )
        self.schur_factor()
        self.schur_solve("phi", "mu")
        self.schur_solve("phid", "nu")
        self.apply_wt("mu", "dq", None)
        self.apply_wt("nu", "dv", None)

    def outputs(self, t: str = "t") -> None:
        """Output quantities at (q, v, λ): ``jfx{k}``, ``jfy{k}``, ``cf{k}``, ``dtq{d}``,
        ``energy``, ``phimax``. Needs ``lam{r}`` in scope."""
        topo = self.topo
        self._load_contact_state("fm", "vi")
        self.bodies()
        self.joints()
        self.constraint_values(t=t, v=None)
        for k in range(topo.njoint):
            r = topo.joint_row[k]
            if topo.joint_kind[k] == JOINT_IDEAL:
                self.emit(f"jfx{k} = -lam{r}", f"jfy{k} = -lam{r + 1}", f"cf{k} = math.nan")
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                # the normal force at b's point; the couple goes out where clearance joints
                # put their contact force (the solver files it as joint_moment)
                self.emit(
                    f"jfx{k} = -lam{r} * nx{k}", f"jfy{k} = -lam{r} * ny{k}", f"cf{k} = -lam{r + 1}"
                )
            elif k in self.contact_row:
                # Under the law λ_r is F_n ≥ 0; at the switch from the link, the link's last λ
                # (≤ 0) is not a contact force.
                cf = f"lam{r} if fm{k} == 0.0 else max(lam{r}, 0.0)"
                self.emit(f"cf{k} = {cf}", f"jfx{k} = -cf{k} * ex{k}", f"jfy{k} = -cf{k} * ey{k}")
            else:
                self.emit(
                    f"jfx{k} = -lam{r} * ex{k}", f"jfy{k} = -lam{r} * ey{k}", f"cf{k} = lam{r}"
                )
        for d in range(topo.ndriver):
            self.emit(f"dtq{d} = -lam{topo.driver_row[d]}")
        self.emit("energy = 0.0")
        for b in range(topo.nbody):
            x, y, th = 3 * b, 3 * b + 1, 3 * b + 2
            self.emit(
                f"energy += 0.5 * (p_m{b} * (v{x} * v{x} + v{y} * v{y}) + p_J{b} * v{th} * v{th})",
                f"energy -= p_m{b} * (p_gx * q{x} + p_gy * q{y})",
            )
        for f, b in enumerate(topo.force_body):
            if b == GROUND or f in topo.varying_loads:  # a load varying in time: no potential
                continue
            self._point(b, f"p_fpx{f}", f"p_fpy{f}", f"fp{f}")
            self.emit(f"energy -= p_fx{f} * fp{f}X + p_fy{f} * fp{f}Y + p_tq{f} * q{3 * b + 2}")
        for s in range(len(topo.spring_a)):
            a, b = topo.spring_a[s], topo.spring_b[s]
            self._point(a, f"p_spax{s}", f"p_spay{s}", f"sa{s}")
            self._point(b, f"p_spbx{s}", f"p_spby{s}", f"sb{s}")
            self.emit(
                f"ux{s} = sb{s}X - sa{s}X",
                f"uy{s} = sb{s}Y - sa{s}Y",
                f"st{s} = math.sqrt(ux{s} * ux{s} + uy{s} * uy{s}) - p_l0{s}",
                f"energy += 0.5 * p_k{s} * st{s} * st{s}",
            )
        # Contact joints: δ, the mode (0 link, 1 contact, 2 free; seated, vi < 0, is in
        # contact whichever the sign of δ) and the elastic energy K δ^(m+1) / (m+1).
        for k in self.contact_row:
            (eel,) = self.inline("elastic_energy", [f"pen{k}", f"p_K{k}", f"p_mx{k}"], k)
            self.emit(
                f"pen{k} = rho{k} - p_cl{k}",
                f"mode{k} = fm{k} * (1.0 + (pen{k} <= 0.0 and vi{k} >= 0.0) * 1.0)",
                f"eel{k} = {eel}",
                f"energy = energy if fm{k} == 0.0 else energy + eel{k}",
            )
