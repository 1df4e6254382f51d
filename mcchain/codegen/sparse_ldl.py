"""The Schur complement S = B M⁻¹ Bᵀ of a lane and its sparse LDLᵀ, written symbolically.

:class:`SchurComplement` is the linear-algebra half of :class:`mcchain.codegen.emitter.
Emitter`: from the non-zeros of B (:meth:`rows`, coefficients as :data:`Coef`) it emits
M⁻¹Bᵀ, S in a bandwidth-reducing row order, its LDLᵀ with the fill-in found symbolically,
the two triangular solves and the product by M⁻¹Bᵀ. Structure only: the physics (Φ, B's
values, γ: :mod:`mcchain.codegen.kinematics`; forces: the emitter's) is inlined from the
kernels.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType

import numpy as np

from mcchain.codegen.topology import Topology

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


def _block_order(pattern: list[set[int]], own: list[int]) -> list[int]:
    """:func:`_row_order` of a mechanism's own rows ``own`` (all: the usual case), then of
    the others' (an ideal copy after it, Topology.reference: a block of S of its own), each
    ordered as it would be alone, so that the mechanism's factorisation is the one it has
    without the copy, operation for operation."""
    if len(own) == len(pattern):
        return _row_order(pattern)
    blocks = []
    for rows in (own, [r for r in range(len(pattern)) if r not in set(own)]):
        local = {r: i for i, r in enumerate(rows)}
        sub = [{local[j] for j in pattern[r] if j in local} for r in rows]
        blocks += [rows[i] for i in _row_order(sub)]
    return blocks


class SchurComplement:
    """Emits S = B M⁻¹ Bᵀ, its sparse LDLᵀ and the solves; the host class provides
    :meth:`rows` (B's non-zeros), :meth:`emit`, :meth:`_reload` and :meth:`_row_law`
    (the contact-law rows, replaced by λ_r = F_n)."""

    topo: Topology
    coupling: dict[tuple[int, int], str]
    order: list[int]
    emit: Callable[..., None]
    rows: Callable[[], list[dict[int, Coef]]]
    _reload: Callable[[str], str]
    _row_law: Callable[[int], str | None]
    parallel_pivots = False
    """Whether a pivot whose column has one earlier entry divides beside that entry's pivot
    (:meth:`_single_pivot`) rather than after it: a shorter chain of divisions, other bits
    of 1/d_j. The generator sets it for the fixed-step variants only (why, and what it
    gives: benchmarks/results/roofline/reading.md)."""

    invariant_pivots: Mapping[frozenset[int], tuple[str, str]] = MappingProxyType({})
    """Pairs of rows of B (by their index) whose 2×2 block of S has a determinant that does
    not change with the state (an ideal revolute joint to the ground:
    :meth:`mcchain.codegen.kinematics.ConstraintKinematics.ground_revolutes`), each with the
    texts of that determinant and of its inverse, computed once per sample. With
    :attr:`parallel_pivots`, the second pivot of such a pair is :meth:`_ground_pivot`'s: no
    division in the stage. The generator fills it for the fixed-step variants."""

    unit_rows: Mapping[int, tuple[str, str, Coef]] = MappingProxyType({})
    """Rows of B whose entries at each body's x and y are ± one vector w of a known squared
    norm, by row: the names of w_x, w_y and of |w|² (a clearance joint's unit normal, |w|² =
    1, or its d where the row is scaled, |w|² = ρ²; not under a contact law, where n is 0 at
    the bearing's centre). In S_rr such bodies' terms w_x² /m + w_y² /m are |w|² Σ 1/m
    (equal in exact arithmetic, within an ulp or two as written out); the generator fills it
    for the fixed-step variants."""

    eliminated_rows: frozenset[int] = frozenset()
    """Rows of B left out of S (rows that fix a body's accelerations alone, while
    :meth:`mcchain.codegen.emitter.Emitter.acceleration` eliminates them: their λ come from
    the body's own equations after the solve)."""

    eliminated_columns: frozenset[int] = frozenset()
    """Columns of B left out of S and of M⁻¹Bᵀ (the coordinates those rows fix: their
    accelerations are known before the solve)."""

    def schur_rows(self) -> list[dict[int, Coef]]:
        """The rows of B that S is made of: :meth:`rows` without :attr:`eliminated_rows`
        (empty) and :attr:`eliminated_columns`."""
        rows = self.rows()
        if not self.eliminated_rows and not self.eliminated_columns:
            return rows
        return [
            {} if r in self.eliminated_rows else
            {c: v for c, v in row.items() if c not in self.eliminated_columns}
            for r, row in enumerate(rows)
        ]  # fmt: skip

    @staticmethod
    def _flag(condition: str) -> str:
        """A pivot's flag ``okp``: 1.0 where ``condition`` holds, else 0.0 (NaN: 0.0), as a
        select (the comparison times 1.0, the same values, took three instructions to convert;
        what the select gives, and why the pivots' inverses are not selects too:
        benchmarks/results/roofline/reading.md)."""
        return f"1.0 if {condition} else 0.0"

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
        rows = self.schur_rows()
        for r, row in enumerate(rows):
            for col, val in row.items():
                self.emit(f"Wt{r}_{col} = {_mul(val, self._minv(col))}")
        pattern = [{j for j in range(len(rows)) if set(rows[i]) & set(rows[j])} for i in
                   range(len(rows))]  # fmt: skip
        order = _block_order(pattern, [r for r in range(len(rows)) if self.topo.own_row(r)])
        order = [r for r in order if r not in self.eliminated_rows]
        self.order = order
        n = len(order)  # from here on, positions in the order
        # Entries of S in the permuted numbering (i, j: positions), lower part.
        pos = {r: i for i, r in enumerate(order)}
        S: dict[tuple[int, int], str] = {}
        # A row whose joint is under the contact law (fm = 1) is replaced by λ_r = F_n:
        # its S row and column become the unit vector (so the factors keep their pattern)
        # and the coupling S_jr F_n moves to the right-hand side (:meth:`acceleration`). In
        # link mode (fm = 0) the selects give the values of the link alone.
        self.coupling: dict[tuple[int, int], str] = {}
        for ri in range(len(rows)):
            for rj in pattern[ri]:
                i, j = pos[ri], pos[rj]
                if j > i:
                    continue
                cols = list(set(rows[ri]) & set(rows[rj]))
                terms = [_mul(rows[ri][c], f"Wt{rj}_{c}") for c in cols]
                if ri == rj and ri in self.unit_rows:
                    terms = self._unit_terms(ri, rows[ri], cols, self.unit_rows[ri])
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
            k = min(lower[j], default=-1)
            invariant = None
            if self.parallel_pivots and len(lower[j]) == 1 and not lower[k]:
                invariant = self.invariant_pivots.get(frozenset((order[k], order[j])))
            if invariant is not None:
                self._ground_pivot(j, k, S[j, j], *invariant)
            elif self.parallel_pivots and len(lower[j]) == 1:
                self._single_pivot(j, k, S[j, j])
            else:
                prods = [f"L{j}_{k} * E{j}_{k}" for k in sorted(lower[j])]
                dj = S[j, j] + ("" if not prods else " - (" + " + ".join(prods) + ")")
                self.emit(
                    f"D{j} = {dj}",
                    f"okp{j} = {self._flag(f'D{j} > tau * {S[j, j]}')}",
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

    def _single_pivot(self, j: int, k: int, sjj: str) -> None:
        """Pivot j of a column whose only earlier entry is L_jk: d_j = N_j / d_k with
        N_j = S_jj d_k − E_jk², so 1/d_j = d_k / N_j divides without waiting for 1/d_k
        (the stage's chain of divisions is one shorter). The drop test d_j ≤ tau S_jj is
        N_j ≤ tau S_jj d_k (d_k > 0 where pivot k is kept); a dropped pivot k counts as
        d_k = 1, E_jk = 0, so that d_j = S_jj exactly, as L_jk = 0 gives."""
        self.emit(
            f"Dp{j}_{k} = D{k} if okp{k} > 0.0 else 1.0",
            f"Ep{j}_{k} = E{j}_{k} if okp{k} > 0.0 else 0.0",
            f"N{j} = {sjj} * Dp{j}_{k} - Ep{j}_{k} * Ep{j}_{k}",
            f"okp{j} = {self._flag(f'N{j} > tau * {sjj} * Dp{j}_{k}')}",
            f"Di{j} = Dp{j}_{k} / N{j} if okp{j} > 0.0 else 0.0",
            # d_j for a next such column (else dead code): a product, not one more division
            f"D{j} = N{j} * (Di{k} if okp{k} > 0.0 else 1.0)",
        )

    def _unit_terms(
        self, r: int, row: dict[int, Coef], cols: list[int], unit: tuple[str, str, Coef]
    ) -> list[Coef]:
        """The terms of S_rr for a row of :attr:`unit_rows`: |w|² times the sum of 1/m of the
        bodies whose x and y entries are ±(w_x, w_y), then the products for the other
        entries."""
        masses: list[Coef] = []
        terms: list[Coef] = []
        for c in cols:
            b, k = divmod(c, 3)
            pair = (row.get(3 * b), row.get(3 * b + 1))
            signed = [tuple(_mul(sign, e) for e in unit[:2]) for sign in (1.0, -1.0)]
            if k < 2 and pair in signed:
                if k == 0:
                    masses.append(self._minv(c))
                continue
            terms.append(_mul(row[c], f"Wt{r}_{c}"))
        if not masses:
            return terms
        return [_mul(unit[2], _sum(masses)), *terms]

    def _ground_pivot(self, j: int, k: int, sjj: str, det: str, inverse: str) -> None:
        """:meth:`_single_pivot` where pivot k is the first of its column (d_k = S_kk, E_jk =
        S_jk) and rows k, j are a pair of :attr:`invariant_pivots`: N_j = S_jj S_kk − S_jk²
        is the block's determinant ``det``, the same at every state (a few ulp from the
        product written out, which it replaces), so 1/d_j = d_k · ``inverse``: no division.
        The drop test is N_j ≤ tau S_jj d_k as there. Pivot k is dropped only in a NaN lane
        (S_kk ≥ 1/m > 0 with m > 0: the scene's rule), whose S_jj is NaN too: pivot j is then
        dropped as well, as there (1/d_j = 0)."""
        self.emit(
            f"Dp{j}_{k} = D{k} if okp{k} > 0.0 else 1.0",
            f"N{j} = {det}",
            f"okp{j} = {self._flag(f'N{j} > tau * {sjj} * Dp{j}_{k}')}",
            f"Di{j} = Dp{j}_{k} * {inverse} if okp{j} > 0.0 else 0.0",
            f"D{j} = N{j} * (Di{k} if okp{k} > 0.0 else 1.0)",
        )

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
        rows = self.schur_rows()
        for c in range(self.topo.ndof):
            terms = [_mul(row[c], f"{x}{r}") for r, row in enumerate(rows) if c in row]
            head = base[c] if base else 0.0
            if not terms:
                self.emit(f"{out}{c} = {float(head) if isinstance(head, float) else head}")
                continue
            total = f"{self._reload(self._minv_slot(c))} * ({_sum(terms)})"
            self.emit(f"{out}{c} = -{total}" if head == 0.0 else f"{out}{c} = {head} - {total}")
