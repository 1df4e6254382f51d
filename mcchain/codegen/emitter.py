"""Straight-line code of one lane of a :class:`~mcchain.codegen.topology.Topology`: the
blocks the generator (``generate.py``) puts into the time loops of ``templates.py``.

:class:`Emitter` writes the applied forces, the contact law's rows (normal force, friction,
the step-size check), and from them the whole blocks: the index-1 acceleration, the
constraint projection and the outputs (joint forces, energy, max |Φ|). It stands on the
constraint kinematics (:mod:`mcchain.codegen.kinematics`: Φ, Φ̇, γ, B) and the Schur
complement S = B M⁻¹ Bᵀ with its sparse LDLᵀ (:mod:`mcchain.codegen.sparse_ldl`).

The physics is not written here: the driver and load laws, the spring-dampers, the
energies and the contact law are the straight-line functions of ``mcchain/kernels/forces.py``
and ``contact.py``, which the loop kernels call and :meth:`Emitter.kernel` inlines
(:mod:`mcchain.codegen.inline`), a ground body's terms as literal 0.0 / 1.0 folded away.
"""

from __future__ import annotations

from mcchain.codegen.kinematics import ConstraintKinematics
from mcchain.codegen.lane_text import FORCE_KERNELS, JOINT_KERNELS
from mcchain.codegen.sincos import TWO_PI, sincos_code
from mcchain.codegen.sparse_ldl import Coef, SchurComplement, _mul, _sum
from mcchain.model import GROUND, JOINT_IDEAL, JOINT_PRISMATIC


class Emitter(ConstraintKinematics, SchurComplement):
    """Generates the straight-line code of one lane for a :class:`Topology` (the names it
    uses: :class:`mcchain.codegen.lane_text.LaneText`)."""

    cancel_gravity = False
    """Drop from B M⁻¹F the pairs of terms that cancel in exact arithmetic (:func:`_cancelling`):
    the fixed-step lanes set it; the adaptive lanes and the radau right-hand side keep the
    terms and their bits (their round-off, a few 1e-16 |g|, is part of their values)."""

    eliminate_fixed = True
    """Take out of S the rows that fix a body's accelerations alone
    (:meth:`fixed_accelerations`: a driven crank's three, a slider's angle): those
    accelerations from the rows before the solve, the rows' λ from the body's equations after
    it. The same solution in exact arithmetic, a smaller S (the verdict's slider-crank: four
    of eight rows; benchmarks/results/verdict/prescribed.md). Every variant's acceleration
    takes it; the projection's corrections keep the rows."""

    prescribe = True
    """Write the coordinates that :meth:`prescribed_coordinates` lists in closed form in the
    adaptive stage (:meth:`prescribed_state`), not integrated: a driven crank's angle and
    centre, a slider's angle (benchmarks/results/verdict/prescribed.md)."""

    def fixed_accelerations(self) -> dict[int, list[tuple[int, int]]]:
        """Per body, rows of B that fix some of its accelerations alone: rows whose columns
        are all the body's (a driver on it; an ideal revolute or a prismatic joint to the
        ground), no clearance row, solved one at a time by substitution, each with one
        coordinate left and a ±1 coefficient (no division): a driven crank's pivot and driver
        fix all three, a slider's guide its angle. {body: [(row, column), ...] in solving
        order}. A body in a contact joint with friction keeps its rows (its friction force is
        in its free acceleration, not in the equations its reactions come from); so does one
        with a row those fix entirely beside them (redundant: S keeps it, and its dropped
        pivot flags the sample as before)."""
        topo = self.topo
        rows = self.rows()
        clearance = set(topo.clearance_rows)
        rough = {topo.joint_a[k] for k in self.contact_row if topo.friction(k)}
        rough |= {topo.joint_b[k] for k in self.contact_row if topo.friction(k)}
        found = {}
        for b in range(topo.nbody):
            cols = {3 * b, 3 * b + 1, 3 * b + 2}
            own = {r: rows[r] for r, row in enumerate(rows)
                   if row and set(row) <= cols and r not in clearance}  # fmt: skip
            plan = _substitution(own, cols) if b not in rough else []
            fixed = {c for _, c in plan}
            solved = {r for r, _ in plan}
            if any(set(row) <= fixed for r, row in own.items() if r not in solved):
                continue  # a redundant row (nothing of it left for S): the rows stay
            if plan:
                found[b] = plan
        return found

    def prescribed_coordinates(self) -> list[tuple[int, int, int]]:
        """The coordinates of :meth:`fixed_accelerations` that their row fixes as a closed
        form of the time and the parameters, [(body, row, column), ...] in solving order:
        the angle of a body driven at constant speed (θ = θ0 + ω t) or held by a prismatic
        joint to the ground (θ = ±θ_rel), then the position of its ideal revolute to the
        ground (r = the ground point − A(θ) s); each body's up to its first row of another
        kind (a harmonic or table law, whose swing the constraint rows keep)."""
        topo = self.topo
        drivers, joint_of = self._row_sources()
        found = []
        for b, plan in self.fixed_accelerations().items():
            for r, c in plan:
                if r in drivers:
                    d = drivers[r]
                    tabled = bool(topo.driver_tables) and bool(topo.driver_tables[d])
                    closed = d not in topo.harmonic_drivers and not tabled
                else:
                    k = joint_of[r]
                    angle_row = r == topo.joint_row[k] + 1
                    closed = topo.joint_kind[k] == JOINT_IDEAL or (
                        topo.joint_kind[k] == JOINT_PRISMATIC and angle_row
                    )
                if not closed:
                    break
                found.append((b, r, c))
        return found

    def _row_sources(self) -> tuple[dict[int, int], dict[int, int]]:
        """{row: driver} of the drivers' rows and {row: joint} of the joints' (a joint's
        second row included)."""
        topo = self.topo
        drivers = {r: d for d, r in enumerate(topo.driver_row)}
        joint_of = {topo.joint_row[k] + i: k for k in range(topo.njoint) for i in range(2)}
        return drivers, joint_of

    def prescribed_state(self, t: str = "t") -> None:
        """``q{c}``, ``v{c}`` of the :meth:`prescribed_coordinates` at time ``t`` in closed
        form (each row's Φ = 0 and Φ̇ = 0 solved for its coordinate, in the plan's order), and
        the sin/cos of each such angle, which :meth:`bodies` then leaves alone
        (:attr:`angles_ready`)."""
        topo = self.topo
        drivers, joint_of = self._row_sources()
        pointed: set[int] = set()
        for b, r, c in self.prescribed_coordinates():
            th = 3 * b + 2
            if r in drivers:  # Φ = θ − θ0 − ω t at θ = 0, negated; θ̇ = ω
                d = drivers[r]
                start, speed = f"p_th0_{d}", f"p_om{d}"
                arguments = ["0.0", start, speed, t, "0.0"]
                (phi,) = self.kernel(JOINT_KERNELS, "driver_residual", arguments)
                (rate,) = self.kernel(JOINT_KERNELS, "driver_speed", [speed, "0.0"])
                self.emit(f"q{c} = -({phi})", f"v{c} = {rate}")
            else:
                k = joint_of[r]
                own_side = topo.joint_b[k] == b  # Φ's sign at the body's coordinate: +1 on b
                if topo.joint_kind[k] == JOINT_PRISMATIC:  # θ_b − θ_a − θ_rel = 0
                    (_, angle) = self.kernel(
                        JOINT_KERNELS, "prismatic_residual",
                        ["0.0", "0.0", "0.0", "0.0", "0.0", "0.0", f"p_rel{k}"],
                    )  # fmt: skip
                    value = f"-({angle})" if own_side else angle
                    self.emit(f"q{c} = {value}", f"v{c} = 0.0")
                else:  # d = (r_b + A_b s_b) − (r_a + A_a s_a) = 0, ḋ = 0, the ground still
                    if k not in pointed:
                        self._point(topo.joint_a[k], f"p_sax{k}", f"p_say{k}", f"pa{k}")
                        self._point(topo.joint_b[k], f"p_sbx{k}", f"p_sby{k}", f"pb{k}")
                        pointed.add(k)
                    ground, body = (f"pa{k}", f"pb{k}") if own_side else (f"pb{k}", f"pa{k}")
                    if c == 3 * b:
                        self.emit(f"q{c} = {ground}x - {body}x", f"v{c} = v{th} * {body}y")
                    else:
                        self.emit(f"q{c} = {ground}y - {body}y", f"v{c} = -(v{th} * {body}x)")
            if c == th:
                self.emit(*sincos_code(f"q{th}", f"sn{b}", f"cs{b}", f"{b}"))
                self.angles_ready.add(b)

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
        fixed = self.fixed_accelerations() if self.eliminate_fixed else {}
        for plan in fixed.values():
            # B_E q̈ = γ_E over the body's rows E that fix them, by substitution (±1 pivots)
            for r, c in plan:
                known = [_mul(val, a0[d]) for d, val in rows[r].items() if d != c]
                value = f"gam{r}" if not known else f"gam{r} - {_sum(known)}"
                self.emit(f"fqdd{c} = {value if rows[r][c] == 1.0 else f'-({value})'}")
                a0[c] = f"fqdd{c}"
        self.eliminated_rows = frozenset(r for plan in fixed.values() for r, _ in plan)
        self.eliminated_columns = frozenset(c for plan in fixed.values() for _, c in plan)
        for k in self.contact_row:
            self.contact_law(k)
            if self.topo.friction(k):  # else its terms, exact zeros at μ = 0, are left out
                self.contact_friction(k, a0)
        for r, row in enumerate(rows):
            if r in self.eliminated_rows:
                continue
            gone = _cancelling(row, a0) if self.cancel_gravity else set()
            terms = [_mul(val, a0[c]) for c, val in row.items() if c not in gone]
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
        for b, plan in fixed.items():
            self._fixed_reactions(b, plan, rows)
        for r, k in self.scaled_clearance_rows().items():  # the solve's λ/|d|: λ
            self.emit(f"lam{r} = rho{k} * lam{r}")
        self.eliminated_rows = self.eliminated_columns = frozenset()

    def _fixed_reactions(
        self, b: int, plan: list[tuple[int, int]], rows: list[dict[int, Coef]]
    ) -> None:
        """``lam{r}`` of the rows E of :meth:`fixed_accelerations` ``plan`` (body ``b``) from
        the body's equations at the columns C they fix, B_ECᵀ λ_E = F_C − M_C q̈_C −
        Σ_(other rows) B_rCᵀ λ_r: the plan's transpose, backwards (±1 pivots)."""
        loaded = self.loaded_bodies()
        own = {r for r, _ in plan}
        transposed: dict[int, dict[int, Coef]] = {c: {} for _, c in plan}
        for r in own:
            for c, val in rows[r].items():
                if c in transposed:
                    transposed[c][r] = val
        for c in transposed:
            gravity: Coef = (f"p_m{b} * p_gx", f"p_m{b} * p_gy", 0.0)[c % 3]
            mass = f"p_{'J' if c % 3 == 2 else 'm'}{b}"
            others = [_mul(row[c], f"lam{r}") for r, row in enumerate(rows)
                      if c in row and r not in own]  # fmt: skip
            terms: list[Coef] = [f"F{c}" if b in loaded else gravity, f"(-{mass} * qdd{c})"]
            terms += [f"(-{t})" for t in others]
            self.emit(f"fres{c} = {_sum(terms)}")
        backward = _substitution(transposed, own)
        assert len(backward) == len(own)  # a triangular plan's transpose is triangular
        for c, r in backward:
            known = [_mul(val, f"lam{s}") for s, val in transposed[c].items() if s != r]
            value = f"fres{c}" if not known else f"fres{c} - {_sum(known)}"
            self.emit(f"lam{r} = {value if transposed[c][r] == 1.0 else f'-({value})'}")

    def contact_law(self, k: int) -> None:
        """The normal force of contact joint ``k`` (after :meth:`constraint_values` with v):
        ``pen{k}`` δ, ``pdot{k}`` δ̇, ``fn{k}`` F_n, and ``kc{k}`` = fm ∂F_n/∂δ (for the
        step-size check only), from :func:`mcchain.kernels.contact.contact_law` inlined
        (the loop kernels call the same function).
        """
        r = self.contact_row[k]
        self.emit(f"pen{k} = rho{k} - p_cl{k}", f"pdot{k} = phid{r}")
        arguments = [f"{x}{k}" for x in ("pen", "pdot", "ins", "vi", "p_K", "p_mx", "p_lw", "p_er")]
        if self.hertz_exponent:  # lanes whose exponents are all 1.5: contact_power's branch
            arguments[5] = "1.5"
        law = self.topo.law(k)
        if law is not None:  # the scene's law: its branch of restitution_factor alone
            arguments[6] = f"{float(law)!r}"
        fn, delta_slope, _rate_slope = self.inline("contact_law", arguments, k)
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
        for r, k in self.scaled_clearance_rows().items():  # |d| Φ, |d| Φ̇ of a scaled row
            self.emit(f"phi{r} = rho{k} * phi{r}", f"phid{r} = rho{k} * phid{r}")
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


def _substitution(
    equations: dict[int, dict[int, Coef]], unknowns: set[int]
) -> list[tuple[int, int]]:
    """Solve ``equations`` ({equation: {unknown: coefficient}}) for as many of
    ``unknowns`` as substitution reaches, each step an equation with one unknown left whose
    coefficient is ±1 (no division): [(equation, unknown), ...] in solving order (the
    equations left over, and their unknowns, are not in it)."""
    left = set(unknowns)
    pending = dict(sorted(equations.items()))
    plan: list[tuple[int, int]] = []
    while True:
        step = None
        for e, eq in pending.items():
            open_ = set(eq) & left
            if len(open_) == 1 and eq[next(iter(open_))] in (1.0, -1.0):
                step = (e, open_.pop())
                break
        if step is None:
            return plan
        plan.append(step)
        left.discard(step[1])
        del pending[step[0]]


def _negated(x: Coef, y: Coef) -> bool:
    """Whether coefficient ``y`` is ``-x`` as written: floats, or the texts ``x`` and
    ``(-x)`` (a coefficient's text is a name or parenthesised: ``lane_text._coef``)."""
    if isinstance(x, str) and isinstance(y, str):
        return y == f"(-{x})" or x == f"(-{y})"
    return not isinstance(x, str) and not isinstance(y, str) and x == -y


def _cancelling(row: dict[int, Coef], a0: dict[int, Coef]) -> set[int]:
    """Columns of a row of B whose terms of B a0 cancel in exact arithmetic: two bodies under
    gravity alone (a0 the same name, g_x or g_y) with opposite coefficients, as a joint
    between them has (its Φ depends on their points' difference): uniform gravity does not
    load it. Written out, the pair's round-off (fused: a few 1e-16 |g|) entered the
    constraint's right-hand side."""
    gone: set[int] = set()
    for c, x in row.items():
        if c in gone or a0[c] not in ("p_gx", "p_gy"):
            continue
        for d, y in row.items():
            if d != c and d not in gone and a0[d] == a0[c] and _negated(x, y):
                gone |= {c, d}
                break
    return gone
