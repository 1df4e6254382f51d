"""The constraint equations of one lane, as straight-line text: body rotations, joint
points and separations, the non-zeros of B, Φ, Φ̇ and γ (B q̈ = γ).

Structure only: which bodies and rows, the ground skipped (its terms literal 0.0 / 1.0,
folded away), the sparse pattern of B. The arithmetic of each joint and driver is
:mod:`mcchain.kernels.joints`' own, inlined (:meth:`LaneText.kernel`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mcchain.codegen.lane_text import JOINT_KERNELS, LaneText, _coef, _tidy
from mcchain.codegen.sincos import TWO_PI, sincos_code
from mcchain.codegen.sparse_ldl import Coef
from mcchain.codegen.topology import Topology
from mcchain.model import GROUND, JOINT_CLEARANCE, JOINT_IDEAL, JOINT_PRISMATIC
from mcchain.scene.compile import spline_value


class ConstraintKinematics(LaneText):
    """Emits the kinematics of the constraints: :meth:`bodies` (sin/cos), :meth:`joints`
    (points, separations, normals), :meth:`rows` (B's non-zeros), :meth:`constraint_values`
    (Φ, Φ̇, max |Φ|) and :meth:`gamma` (γ)."""

    scaled_rows = False
    """Whether each clearance row not under a contact law enters the solve multiplied by
    |d| (:meth:`scaled_clearance_rows`): its entries are d's instead of the unit normal
    e = d/|d|'s, its γ and its Baumgarte terms are |d| times the row's (:meth:`gamma`), and
    the solve gives λ/|d|, which the emitter multiplies back. The same S⁻¹ in exact
    arithmetic, and neither √ nor 1/|d| on the way to the row's pivot (a shorter chain); other
    bits of λ and q̈, a few ulp (benchmarks/results/roofline/reading.md). Φ and Φ̇ keep
    their meaning (max |Φ|, the outputs). The generator sets it for the fixed-step
    variants."""

    def __init__(self, topo: Topology):
        super().__init__(topo)
        self._rows_cache: list[dict[int, Coef]] | None = None
        self.angle_rows: Callable[[int], tuple[str, str]] | None = None
        """Where :meth:`bodies` reads body b's sin/cos (computed before, in a lane loop of
        their own), or None: computed in place."""
        self.angles_ready: set[int] = set()
        """Bodies whose sin/cos are already in scope (an angle written in closed form:
        :meth:`mcchain.codegen.emitter.Emitter.prescribed_state`): :meth:`bodies` skips them."""

    def bodies(self, q: str = "q", tag: str = "") -> None:
        """sin/cos of every body angle: ``sn{b}``, ``cs{b}`` (read from :attr:`angle_rows`
        where set)."""
        for b in range(self.topo.nbody):
            if b in self.angles_ready:
                continue
            sn, cs = f"sn{b}{tag}", f"cs{b}{tag}"
            if self.angle_rows is not None:
                rows = self.angle_rows(b)
                self.emit(f"{sn} = {rows[0]}", f"{cs} = {rows[1]}")
            else:
                self.emit(*sincos_code(f"{q}{3 * b + 2}", sn, cs, f"{b}{tag}"))

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

    def joints(self, q: str = "q", tag: str = "") -> None:
        """Points ``pa{k}``, ``pb{k}`` and separation ``dx{k}``, ``dy{k}`` of every joint."""
        topo = self.topo
        scaled = self.scaled_clearance_rows()
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
                separation = [f"dx{k}", f"dy{k}"]
                if topo.joint_row[k] in scaled:
                    # ρ² for the scaled row's S_rr and γ; ρ the same √ of it as `distance`
                    (squared,) = self.kernel(JOINT_KERNELS, "distance_squared", separation)
                    self.emit(f"rr{k} = {squared}")
                    rho = f"math.sqrt(rr{k})"
                else:
                    (rho,) = self.kernel(JOINT_KERNELS, "distance", separation)
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
        scaled = self.scaled_clearance_rows()
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
            else:  # the unit normal's entries, or d's where the row is scaled
                in_scaled = topo.joint_row[k] in scaled
                ex, ey = (f"dx{k}", f"dy{k}") if in_scaled else (f"ex{k}", f"ey{k}")
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

    def unit_normal_rows(self) -> dict[int, tuple[str, str, Coef]]:
        """The row of each clearance joint not under a contact law: its entries at a body's
        x and y are ± its unit normal (ex, ey) (under a law, n = 0 at the bearing's
        centre), or ± d (dx, dy) where the row is scaled, whose square is ρ² (rr), not 1.
        {row: (x entry, y entry, their squared norm)}."""
        if self.scaled_rows:
            return {r: (f"dx{k}", f"dy{k}", f"rr{k}") for r, k in self._link_rows().items()}
        return {r: (f"ex{k}", f"ey{k}", 1.0) for r, k in self._link_rows().items()}

    def scaled_clearance_rows(self) -> dict[int, int]:
        """{row: joint} of the clearance rows the solve takes multiplied by |d| (with
        :attr:`scaled_rows`; else none)."""
        return self._link_rows() if self.scaled_rows else {}

    def _link_rows(self) -> dict[int, int]:
        """{row: joint} of the clearance joints not under a contact law."""
        topo = self.topo
        return {
            topo.joint_row[k]: k
            for k in range(topo.njoint)
            if topo.joint_kind[k] == JOINT_CLEARANCE and k not in self.contact_row
        }

    def ground_revolutes(self) -> dict[frozenset[int], tuple[int, int, str, str]]:
        """The two rows of B of each ideal revolute joint k between the ground and one body b:
        {{row x, row y}: (k, b, slot of the joint's point on b in b's frame: x, y)}.

        Those rows' block of S = B M⁻¹ Bᵀ is 1/m_b I + 1/J_b w wᵀ with w the point turned a
        right angle (|w| = |s|, s the point in b's frame), whose determinant
        1/m_b (1/m_b + |s|²/J_b) does not change with the state (used by
        :meth:`mcchain.codegen.sparse_ldl.SchurComplement.schur_factor`). Only rows of
        exactly that pattern (x row: b's x and θ; y row: b's y and θ) are listed."""
        topo = self.topo
        rows = self.rows()
        pairs: dict[frozenset[int], tuple[int, int, str, str]] = {}
        for k in topo.ground_revolutes:
            a, b = topo.joint_a[k], topo.joint_b[k]
            body, side = (b, "sb") if a == GROUND else (a, "sa")
            r = topo.joint_row[k]
            cols = {3 * body, 3 * body + 2}, {3 * body + 1, 3 * body + 2}
            if set(rows[r]) == cols[0] and set(rows[r + 1]) == cols[1]:
                pairs[frozenset((r, r + 1))] = (k, body, f"{side}x{k}", f"{side}y{k}")
        return pairs

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
        """``gam{r}``: B q̈ = γ − 2α Φ̇ − β² Φ (after :meth:`constraint_values` with v); a
        scaled row's (:attr:`scaled_rows`) |d| times it."""
        topo = self.topo
        scaled = self.scaled_clearance_rows()
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
            elif r in scaled:  # |d| γ, |d| Φ̇ = d·ḋ and |d| Φ (Baumgarte) of the scaled row
                arguments = [f"dx{k}", f"dy{k}", f"cqx{k}", f"cqy{k}", f"ddx{k}", f"ddy{k}"]
                (gam,) = self.kernel(
                    JOINT_KERNELS, "clearance_gamma_scaled", [*arguments, f"irr{k}"], f"_g{k}"
                )
                rate_arguments = arguments[:2] + arguments[4:]  # d·ḋ = |d| Φ̇
                (rate,) = self.kernel(JOINT_KERNELS, "clearance_rate", rate_arguments)
                self.emit(
                    f"irr{k} = 1.0 / rr{k}",
                    f"gam{r} = {gam}",
                    f"sphid{r} = {rate}",
                    f"sphi{r} = rho{k} * phi{r}",
                )
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
                s = "s" if r in scaled else ""
                self.emit(f"gam{r} = gam{r} - balpha2 * {s}phid{r} - bbeta2 * {s}phi{r}")

    def _axis_gamma(self, wx: str, wy: str, k: int, wa: str) -> str:
        """γ of the row w·d of joint k (a prismatic offset row, w = n, or its slider
        driver's, w = u)."""
        arguments = [wx, wy, f"cqx{k}", f"cqy{k}", f"dx{k}", f"dy{k}", f"ddx{k}", f"ddy{k}", wa]
        return self.kernel(JOINT_KERNELS, "prismatic_gamma", arguments)[0]
