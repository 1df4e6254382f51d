"""Straight-line code of one lane of a :class:`~mcchain.codegen.topology.Topology`.

:class:`Emitter` writes the index-1 acceleration, the constraint projection and the outputs
(joint forces, energy, max |Φ|); the generator (``generate.py``) puts these blocks into the
time loops of ``templates.py``. :func:`sincos_code` is the branch-free sine/cosine it inlines.

The physics is not written here: each joint's Φ, Φ̇ and γ, B's turning entries, the driver
and load laws, the spring-dampers and the energies are the straight-line functions of
``mcchain/kernels/joints.py`` and ``forces.py`` (the contact law: ``contact.py``), which the
loop kernels call and :meth:`Emitter.kernel` inlines (:mod:`mcchain.codegen.inline`), a ground
body's terms as literal 0.0 / 1.0 folded away. What stays here is structure: which bodies and
rows, the ground skipped, the sparse pattern of B; the Schur complement S = B M⁻¹ Bᵀ and its
sparse LDLᵀ are :mod:`mcchain.codegen.sparse_ldl`'s."""

from __future__ import annotations

import ast
import math
from collections.abc import Callable

import numpy as np

from mcchain.codegen.inline import inline
from mcchain.codegen.sparse_ldl import Coef, SchurComplement, _mul, _sum
from mcchain.codegen.topology import Topology
from mcchain.model import GROUND, JOINT_CLEARANCE, JOINT_IDEAL, JOINT_PRISMATIC
from mcchain.scene.compile import spline_value

CONTACT_KERNELS = "mcchain.kernels.contact"
"""The module whose functions define the contact law for the loop kernels and the lanes."""
JOINT_KERNELS = "mcchain.kernels.joints"
"""… the joints' and drivers' arithmetic (points, Φ, Φ̇, γ, B's turning entries)."""
FORCE_KERNELS = "mcchain.kernels.forces"
"""… the applied forces' arithmetic (loads, spring-dampers, moments, energies)."""


def _tidy(text: str) -> str:
    """``text`` with the parentheses it does not need dropped (a composed expression)."""
    return ast.unparse(ast.parse(text, mode="eval"))


def _coef(text: str) -> Coef:
    """A coefficient of B from an inlined expression: a literal as its float, a name as it
    is, anything else in parentheses (it becomes a factor of products)."""
    try:
        return float(text)
    except ValueError:
        pass
    return text if isinstance(ast.parse(text, mode="eval").body, ast.Name) else f"({text})"


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


class Emitter(SchurComplement):
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

    def _point(
        self, body: int, sx: str, sy: str, name: str, q: str = "q", tag: str = "", world=False
    ) -> None:
        """Rotated point ``{name}x/y`` = A s (and with ``world`` the world point ``{name}X/Y``
        = r + A s)."""
        if body == GROUND:
            self.emit(f"{name}x = {sx}", f"{name}y = {sy}")
        else:
            c, sn = f"cs{body}{tag}", f"sn{body}{tag}"
            px, py = self.kernel(JOINT_KERNELS, "rotate", [c, sn, sx, sy])
            self.emit(f"{name}x = {px}", f"{name}y = {py}")
        if world:
            x, y = (f"{c} + " if body != GROUND else "" for c in self._coordinates(body, q, 2))
            self.emit(f"{name}X = {x}{name}x", f"{name}Y = {y}{name}y")

    def _separation(
        self, out: tuple[str, str], a: int, b: int, pa: str, pb: str, state: str, rate=False
    ) -> None:
        """Names ``out`` = d = (r_b + p_b) − (r_a + p_a) between the rotated points ``pa``
        and ``pb`` (:meth:`_point`) of bodies a and b at the positions ``state``; with
        ``rate``, ḋ at the velocities ``state``."""
        count, function = (3, "separation_rate") if rate else (2, "separation")
        ends = [[*self._coordinates(body, state, count), f"{p}x", f"{p}y"] for body, p in
                ((a, pa), (b, pb))]  # fmt: skip
        x, y = self.kernel(JOINT_KERNELS, function, ends[0] + ends[1], f"_{out[0]}")
        self.emit(f"{out[0]} = {x}", f"{out[1]} = {y}")

    @staticmethod
    def _coordinates(body: int, state: str, count: int) -> list[str]:
        """The first ``count`` of (x, y, θ) of ``body`` in ``state`` (or of their rates):
        literal 0.0 for the ground."""
        return [f"{state}{3 * body + i}" if body != GROUND else "0.0" for i in range(count)]

    def joints(self, q: str = "q", tag: str = "") -> None:
        """Points ``pa{k}``, ``pb{k}`` and separation ``dx{k}``, ``dy{k}`` of every joint."""
        topo = self.topo
        for k in range(topo.njoint):
            a, b = topo.joint_a[k], topo.joint_b[k]
            self._point(a, f"p_sax{k}", f"p_say{k}", f"pa{k}", q, tag)
            self._point(b, f"p_sbx{k}", f"p_sby{k}", f"pb{k}", q, tag)
            self._separation((f"dx{k}", f"dy{k}"), a, b, f"pa{k}", f"pb{k}", q)
            if topo.joint_kind[k] == JOINT_CLEARANCE:
                # One division per joint: ex, ey and γ multiply by 1/ρ. Under a contact law
                # the journal may sit at the bearing centre (ρ = 0, written there): no normal,
                # and none needed (F_n = 0 there), so n = 0 rather than NaN.
                guarded = "1.0" if k in self.contact_row else "0.0"
                (inverse,) = self.kernel(JOINT_KERNELS, "inverse_distance", [f"rho{k}", guarded])
                (rho,) = self.kernel(JOINT_KERNELS, "distance", [f"dx{k}", f"dy{k}"])
                self.emit(
                    f"rho{k} = {rho}",
                    f"irho{k} = {inverse}",
                    f"ex{k} = dx{k} * irho{k}",
                    f"ey{k} = dy{k} * irho{k}",
                )
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                # n = A_a Ω u, the axis' normal, and B's θ_a entry n·(−Ω p_a) + (Ω n)·d
                c, sn = ("1.0", "0.0") if a == GROUND else (f"cs{a}{tag}", f"sn{a}{tag}")
                nx, ny = self.kernel(JOINT_KERNELS, "axis_normal", [c, sn, f"p_ux{k}", f"p_uy{k}"])
                self.emit(f"nx{k} = {nx}", f"ny{k} = {ny}")
                if a != GROUND:
                    self._turn(f"pta{k}", f"nx{k}", f"ny{k}", k)
                if k in topo.slider_drivers.values():
                    # u = A_a u_0 the axis itself (Ω u = n), and B's θ_a entry of u·d
                    if a == GROUND:
                        self.emit(f"ax{k} = p_ux{k}", f"ay{k} = p_uy{k}")
                    else:
                        self.emit(f"ax{k} = ny{k}", f"ay{k} = -nx{k}")
                        self._turn(f"ptu{k}", f"ax{k}", f"ay{k}", k)

    def _turn(self, name: str, wx: str, wy: str, k: int) -> None:
        """B's θ_a entry of w·d for a vector w fixed in joint k's body a."""
        arguments = [wx, wy, f"pa{k}x", f"pa{k}y", f"dx{k}", f"dy{k}"]
        (turn,) = self.kernel(JOINT_KERNELS, "axis_turn", arguments)
        self.emit(f"{name} = {turn}")

    def rows(self) -> list[dict[int, Coef]]:
        """Non-zeros of each row of B as {column: coefficient} (after :meth:`joints`)."""
        if self._rows_cache is not None:
            return self._rows_cache
        topo = self.topo
        rows: list[dict[int, Coef]] = []

        def point_row(body: int, sign: float, wx: Coef, wy: Coef, px: str, py: str) -> dict:
            if body == GROUND:
                return {}
            arguments = [repr(sign), str(wx), str(wy), px, py]
            entries = self.kernel(JOINT_KERNELS, "point_row", arguments)
            return {3 * body + i: _coef(entry) for i, entry in enumerate(entries)}

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
                a, b = topo.joint_a[k], topo.joint_b[k]
                self._separation((f"ddx{k}", f"ddy{k}"), a, b, f"pa{k}", f"pb{k}", v, rate=True)
            if topo.joint_kind[k] == JOINT_IDEAL:
                self.emit(f"phi{r} = dx{k}", f"phi{r + 1} = dy{k}")
                if v is not None:
                    self.emit(f"phid{r} = ddx{k}", f"phid{r + 1} = ddy{k}")
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                a, b = topo.joint_a[k], topo.joint_b[k]
                qa, qb = self._angle(a, q), self._angle(b, q)
                vectors = [f"nx{k}", f"ny{k}", f"dx{k}", f"dy{k}"]
                offset, angle = self.kernel(
                    JOINT_KERNELS, "prismatic_residual", [*vectors, qa, qb, f"p_rel{k}"]
                )
                self.emit(f"phi{r} = {offset}", f"phi{r + 1} = {angle}")
                if v is not None:
                    rates = [f"ddx{k}", f"ddy{k}", self._angle(a, v), self._angle(b, v)]
                    phid = self.kernel(JOINT_KERNELS, "prismatic_rate", [*vectors, *rates])
                    self.emit(f"phid{r} = {phid[0]}", f"phid{r + 1} = {phid[1]}")
            else:
                self.emit(f"phi{r} = rho{k} - p_cl{k}")
                if v is not None:
                    arguments = [f"ex{k}", f"ey{k}", f"ddx{k}", f"ddy{k}"]
                    (rate,) = self.kernel(JOINT_KERNELS, "clearance_rate", arguments)
                    self.emit(f"phid{r} = {rate}")
        self._swing_acc: dict[int, str] = {}  # f̈ of each driver with a law, for γ
        for d in range(topo.ndriver):
            # f = f0 + rate · t (+ A (sin(Ω t + φ) − sin φ), Ω = 2π f; hs, hc, hw serve γ too)
            r = topo.driver_row[d]
            swing, swing_rate = "0.0", "0.0"
            if topo.driver_tables and topo.driver_tables[d]:  # g(t) − g(0), ġ, g̈ (g̈ serves γ)
                knots, coef = topo.driver_tables[d]
                self.emit(
                    f"tvs{d} = spline_at(TK{d}, TC{d}, {len(knots)}, {t})",
                    f"tv{d} = tvs{d}[0]",
                    f"tv1{d} = tvs{d}[1]",
                    f"tv2{d} = tvs{d}[2]",
                )
                g0 = spline_value(np.asarray(knots), np.asarray(coef), 0.0)
                swing, swing_rate = f"tv{d} - {g0!r}", f"tv1{d}"
                self._swing_acc[d] = f"tv2{d}"
            if d in topo.harmonic_drivers:
                self.emit(f"hw{d} = {TWO_PI!r} * p_frq{d}")
                self.emit(*sincos_code(f"(hw{d} * {t} + p_pha{d})", f"hs{d}", f"hc{d}", f"h{d}"))
                self.emit(*sincos_code(f"p_pha{d}", f"hp{d}", f"_hpc{d}", f"hp{d}"))
                arguments = [f"p_amp{d}", f"hw{d}", f"hs{d}", f"hc{d}", f"hp{d}"]
                swing, swing_rate, acc = self.kernel(JOINT_KERNELS, "harmonic_swing", arguments)
                self._swing_acc[d] = acc
            g = topo.slider_drivers.get(d)
            if g is None:  # θ − θ0 − ω t
                i = 3 * topo.driver_body[d] + 2
                coordinate, start, speed, rate_now = f"{q}{i}", f"p_th0_{d}", f"p_om{d}", f"{v}{i}"
            else:  # a slider driver: u·d − s0 − v t
                a = topo.joint_a[g]
                coordinate = f"ax{g} * dx{g} + ay{g} * dy{g}"
                start, speed = f"p_s0_{d}", f"p_spd{d}"
                if v is not None:
                    vectors = [f"ax{g}", f"ay{g}", f"dx{g}", f"dy{g}", f"ddx{g}", f"ddy{g}"]
                    rate_now = self.kernel(
                        JOINT_KERNELS, "prismatic_rate", [*vectors, self._angle(a, v), "0.0"]
                    )[0]
            (phi,) = self.kernel(
                JOINT_KERNELS, "driver_residual", [coordinate, start, speed, t, swing]
            )
            self.emit(f"phi{r} = {phi}")
            if v is not None:
                (rate,) = self.kernel(JOINT_KERNELS, "driver_speed", [speed, swing_rate])
                self.emit(f"phid{r} = {_tidy(f'{rate_now} - ({rate})')}")
        # A running max (numba's max of many arguments is the same left fold): with demand
        # ordering each Φ_r is then consumed where it is made instead of kept to the end.
        terms = []
        for r in (r for r in range(topo.ncon) if topo.own_row(r)):  # not an ideal copy's
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
            wa, wb = self._angle(a, v), self._angle(b, v)
            points = [f"pa{k}x", f"pa{k}y", f"pb{k}x", f"pb{k}y"]
            cqx, cqy = self.kernel(JOINT_KERNELS, "centripetal", [*points, wa, wb])
            self.emit(f"cqx{k} = {cqx}", f"cqy{k} = {cqy}")
            if topo.joint_kind[k] == JOINT_IDEAL:
                self.emit(f"gam{r} = cqx{k}", f"gam{r + 1} = cqy{k}")
            elif topo.joint_kind[k] == JOINT_PRISMATIC:
                gam = self._axis_gamma(f"nx{k}", f"ny{k}", k, wa)
                self.emit(f"gam{r} = {gam}", f"gam{r + 1} = 0.0")
            else:
                arguments = [f"ex{k}", f"ey{k}", f"cqx{k}", f"cqy{k}", f"ddx{k}", f"ddy{k}"]
                (gam,) = self.kernel(
                    JOINT_KERNELS, "clearance_gamma", [*arguments, f"phid{r}", f"irho{k}"]
                )
                self.emit(f"gam{r} = {gam}")
        for d in range(topo.ndriver):
            r = topo.driver_row[d]
            terms = []
            g = topo.slider_drivers.get(d)
            if g is not None:  # −(Ḃ q̇) of u·d, as a prismatic offset row with u for n
                terms.append(
                    self._axis_gamma(f"ax{g}", f"ay{g}", g, self._angle(topo.joint_a[g], v))
                )
            if d in self._swing_acc:  # −Φ_tt = f̈ of the law
                terms.append(self._swing_acc[d])
            self.emit(f"gam{r} = " + _tidy(" + ".join(terms) if terms else "0.0"))
        if baumgarte:
            for r in range(topo.ncon):
                self.emit(f"gam{r} = gam{r} - balpha2 * phid{r} - bbeta2 * phi{r}")

    def _axis_gamma(self, wx: str, wy: str, k: int, wa: str) -> str:
        """γ of the row w·d of joint k (a prismatic offset row, w = n, or its slider
        driver's, w = u)."""
        arguments = [wx, wy, f"cqx{k}", f"cqy{k}", f"dx{k}", f"dy{k}", f"ddx{k}", f"ddy{k}", wa]
        return self.kernel(JOINT_KERNELS, "prismatic_gamma", arguments)[0]

    @staticmethod
    def _angle(body: int, q: str) -> str:
        """The angle (or angular speed, q = "v") of ``body``: the literal 0.0 for the ground."""
        return f"{q}{3 * body + 2}" if body != GROUND else "0.0"

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
            factor = "1.0"
            if f in topo.varying_loads:
                if f in topo.harmonic_loads:
                    arg = f"({TWO_PI!r} * p_ffr{f} * {t} + p_fph{f})"
                    self.emit(*sincos_code(arg, f"lf{f}", f"_lfc{f}", f"lf{f}{tag}"))
                else:  # a table's spline
                    n = len(topo.load_tables[f][0])
                    self.emit(f"lfs{f} = spline_at(FK{f}, FC{f}, {n}, {t})", f"lf{f} = lfs{f}[0]")
                factor = f"lf{f}"
            arguments = [factor, f"p_fx{f}", f"p_fy{f}", f"fp{f}x", f"fp{f}y", f"p_tq{f}"]
            wrench = self.kernel(FORCE_KERNELS, "load_wrench", arguments)
            self.emit(*(f"F{3 * b + i} += {w}" for i, w in enumerate(wrench)))
        for s in range(len(topo.spring_a)):
            a, b = topo.spring_a[s], topo.spring_b[s]
            self._point(a, f"p_spax{s}", f"p_spay{s}", f"sa{s}", q, tag)
            self._point(b, f"p_spbx{s}", f"p_spby{s}", f"sb{s}", q, tag)
            self._separation((f"ux{s}", f"uy{s}"), a, b, f"sa{s}", f"sb{s}", q)
            self._separation((f"dux{s}", f"duy{s}"), a, b, f"sa{s}", f"sb{s}", v, rate=True)
            arguments = [f"ux{s}", f"uy{s}", f"dux{s}", f"duy{s}", f"p_k{s}", f"p_l0{s}"]
            fx, fy = self.kernel(FORCE_KERNELS, "spring_force", [*arguments, f"p_cd{s}"], f"_s{s}")
            self.emit(f"sfx{s} = {fx}", f"sfy{s} = {fy}")
            for body, sign, pt in ((b, "+", f"sb{s}"), (a, "-", f"sa{s}")):
                if body == GROUND:
                    continue
                arguments = [f"{pt}x", f"{pt}y", f"sfx{s}", f"sfy{s}"]
                (torque,) = self.kernel(FORCE_KERNELS, "moment", arguments)
                self.emit(
                    f"F{3 * body} {sign}= sfx{s}",
                    f"F{3 * body + 1} {sign}= sfy{s}",
                    f"F{3 * body + 2} {sign}= {torque}",
                )

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
        """:meth:`kernel` of ``mcchain.kernels.contact.<function>`` for joint ``k``."""
        return self.kernel(CONTACT_KERNELS, function, arguments, str(k))

    def kernel(
        self, module: str, function: str, arguments: list[str], suffix: str = ""
    ) -> list[str]:
        """Emit the text of ``module.function(*arguments)`` (:func:`mcchain.codegen.inline.
        inline`: the kernels' own definition, its locals suffixed with ``suffix``, needed
        only by a function with locals) and return the expressions of its results."""
        statements, results = inline(module, function, arguments, suffix)
        if statements and not suffix:
            raise TypeError(f"{module}.{function} has locals: give a suffix")
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
        for b in range(topo.own_bodies):  # an ideal copy's (Topology.reference) left out
            x, y, th = 3 * b, 3 * b + 1, 3 * b + 2
            rates = [f"v{x}", f"v{y}", f"v{th}"]
            (kinetic,) = self.kernel(
                FORCE_KERNELS, "body_kinetic_energy", [f"p_m{b}", f"p_J{b}", *rates]
            )
            arguments = [f"p_m{b}", "p_gx", "p_gy", f"q{x}", f"q{y}"]
            (potential,) = self.kernel(FORCE_KERNELS, "gravity_potential", arguments)
            self.emit(f"energy += {kinetic}", f"energy -= {potential}")
        for f, b in enumerate(topo.force_body[: topo.own_forces]):
            if b == GROUND or f in topo.varying_loads:  # a load varying in time: no potential
                continue
            self._point(b, f"p_fpx{f}", f"p_fpy{f}", f"fp{f}", world=True)
            arguments = [f"p_fx{f}", f"p_fy{f}", f"fp{f}X", f"fp{f}Y", f"p_tq{f}", f"q{3 * b + 2}"]
            (potential,) = self.kernel(FORCE_KERNELS, "load_potential", arguments)
            self.emit(f"energy -= {potential}")
        for s in range(topo.own_springs):
            a, b = topo.spring_a[s], topo.spring_b[s]
            self._point(a, f"p_spax{s}", f"p_spay{s}", f"sa{s}")
            self._point(b, f"p_spbx{s}", f"p_spby{s}", f"sb{s}")
            self._separation((f"ux{s}", f"uy{s}"), a, b, f"sa{s}", f"sb{s}", "q")
            arguments = [f"ux{s}", f"uy{s}", f"p_k{s}", f"p_l0{s}"]
            (elastic,) = self.kernel(FORCE_KERNELS, "spring_energy", arguments, f"_s{s}")
            self.emit(f"energy += {elastic}")
        # Contact joints: δ, the mode (0 link, 1 contact, 2 free) and the elastic energy
        # K δ^(m+1) / (m+1).
        for k in self.contact_row:
            self.emit(f"pen{k} = rho{k} - p_cl{k}")
            (eel,) = self.inline("elastic_energy", [f"pen{k}", f"p_K{k}", f"p_mx{k}"], k)
            (mode,) = self.inline("contact_mode", [f"fm{k}", f"pen{k}", f"vi{k}"], k)
            self.emit(
                f"mode{k} = {mode}",
                f"eel{k} = {eel}",
                f"energy = energy if fm{k} == 0.0 else energy + eel{k}",
            )
