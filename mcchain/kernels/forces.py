"""Applied forces of one sample: gravity, loads (constant or harmonic), linear spring-dampers.

``F`` is the generalised force vector (3 nbody,) [N, N, N m]*; ``K_out += −∂F/∂q`` adds the
load stiffness used by equilibrium Newton and the eigen step (at q̇ = 0, where dampers add
nothing). Loops run over the scene's own forces and springs only, so a scene without them
runs no code for them. Nothing here allocates or raises.
"""

from __future__ import annotations

import math

# numba reads module globals as compile-time constants
from mcchain.codes import LOAD_CONSTANT, LOAD_HARMONIC, LOAD_TABLE
from mcchain.kernels.config import JIT, hypot, njit
from mcchain.kernels.joints import (
    TWO_PI,
    add_pair_column,
    add_pair_outer,
    add_pair_product,
    body_pose,
    joint_separation_rate,
    pair_vectors,
    rotate,
)
from mcchain.kernels.tables import spline_at

# ---------------------------------------------------------------------------------------------
# Straight-line scalar laws: the one definition of each force's arithmetic. The loop kernels
# below call them; the lane generator inlines their text (mcchain.codegen.inline).


@njit(**JIT)
def moment(px, py, fx, fy):
    """p × f: the moment of force f (N) applied at the rotated point p (m), N m."""
    return px * fy - py * fx


@njit(**JIT)
def load_wrench(factor, fx, fy, px, py, torque):
    """A load's generalised force on its body, times its time factor: (factor f,
    factor (p × f + τ)), N and N m."""
    return factor * fx, factor * fy, factor * (moment(px, py, fx, fy) + torque)


@njit(**JIT)
def spring_force(ux, uy, dux, duy, stiffness, rest, damping):
    """Force (fx, fy), N, of a linear spring-damper on its b end, u = b − a its vector
    (m) and u̇ its rate (m/s): −(k (L − L₀) + c e·u̇) e, e = u/L; with L₀ = 0 an isotropic
    spring −k u − c u̇, defined also at L = 0. Branch-free (the isotropic flag is a 0/1
    factor), so that the lanes vectorise."""
    length = math.sqrt(ux * ux + uy * uy)
    iso = (rest == 0.0) * 1.0
    ilen = (1.0 - iso) / (length + iso)
    ex = ux * ilen
    ey = uy * ilen
    tension = stiffness * (length - rest) + damping * (ex * dux + ey * duy)
    fx = iso * (-stiffness * ux - damping * dux) - tension * ex
    fy = iso * (-stiffness * uy - damping * duy) - tension * ey
    return fx, fy


@njit(**JIT)
def spring_energy(ux, uy, stiffness, rest):
    """½ k (L − L₀)², J, of a spring of vector u (m)."""
    stretch = math.sqrt(ux * ux + uy * uy) - rest
    return 0.5 * stiffness * stretch * stretch


@njit(**JIT)
def load_potential(fx, fy, x, y, torque, theta):
    """f·(r + p) + τ θ of a constant load at the absolute point (x, y) of its body (at
    angle θ), J: the potential energy is its negative."""
    return fx * x + fy * y + torque * theta


@njit(**JIT)
def gravity_potential(mass, gx, gy, x, y):
    """m g·r, J: a body's potential energy in gravity is its negative."""
    return mass * (gx * x + gy * y)


@njit(**JIT)
def body_kinetic_energy(mass, inertia, vx, vy, w):
    """½ (m |ṙ|² + J θ̇²), J."""
    return 0.5 * (mass * (vx * vx + vy * vy) + inertia * w * w)


@njit(**JIT)
def load_factor(km, s, k, t):
    """The time factor of load ``k`` at ``t``: 1 (constant), sin(2π f t + φ) (harmonic) or
    its table's spline (table)."""
    if km.force_law[k] == LOAD_TABLE:
        n = km.force_table_size[k]
        return spline_at(km.force_table_knots[k], km.force_table_coef[k], n, t)[0]
    if km.force_law[k] != LOAD_HARMONIC:
        return 1.0
    w = TWO_PI * km.force_frequency[s % km.force_frequency.shape[0], k]
    return math.sin(w * t + km.force_phase[s % km.force_phase.shape[0], k])


@njit(**JIT)
def spring_vectors(km, s, q, k):
    """Rotated points p_a, p_b and the vector u from point a to point b of spring ``k``
    (:func:`mcchain.kernels.joints.pair_vectors`)."""
    a, b = km.spring_body_a[k], km.spring_body_b[k]
    return pair_vectors(q, s, a, b, km.spring_point_a, km.spring_point_b, k)


@njit(**JIT)
def force_lever(km, s, q, k):
    """Rotated application point p = A(θ) s and value f of constant force ``k``.

    Returns:
        (px, py, fx, fy): m and N, global frame.
    """
    b = km.force_body[k]
    _, _, c, sn = body_pose(q, b)
    ip = s % km.force_point.shape[0]
    px, py = rotate(c, sn, km.force_point[ip, k, 0], km.force_point[ip, k, 1])
    iv = s % km.force_value.shape[0]
    return px, py, km.force_value[iv, k, 0], km.force_value[iv, k, 1]


@njit(**JIT)
def _add_generalised(F_out, body, sign, fx, fy, px, py):
    """F += sign · (f, p × f) on ``body`` (nothing for the ground)."""
    if body < 0:
        return
    F_out[3 * body] += sign * fx
    F_out[3 * body + 1] += sign * fy
    F_out[3 * body + 2] += sign * moment(px, py, fx, fy)


@njit(**JIT)
def applied_forces(km, s, q, v, t, F_out):
    """F(q, q̇, t) into ``F_out`` (3 nbody,): gravity, loads (times :func:`load_factor`),
    springs.

    A spring's force on body b is −(k (L − L₀) + c L̇) e along u/L from a to b; with
    L₀ = 0 the spring is isotropic, −k u − c u̇, defined also at L = 0.
    """
    F_out[:] = 0.0
    ig = s % km.gravity.shape[0]
    gx = km.gravity[ig, 0]
    gy = km.gravity[ig, 1]
    im = s % km.body_mass.shape[0]
    for b in range(km.body_mass.shape[1]):
        F_out[3 * b] = km.body_mass[im, b] * gx
        F_out[3 * b + 1] = km.body_mass[im, b] * gy
    for k in range(km.force_body.shape[0]):
        b = km.force_body[k]
        if b < 0:
            continue
        px, py, fx, fy = force_lever(km, s, q, k)
        torque = km.force_torque[s % km.force_torque.shape[0], k]
        wx, wy, wt = load_wrench(load_factor(km, s, k, t), fx, fy, px, py, torque)
        F_out[3 * b] += wx
        F_out[3 * b + 1] += wy
        F_out[3 * b + 2] += wt
    for k in range(km.spring_body_a.shape[0]):
        a = km.spring_body_a[k]
        b = km.spring_body_b[k]
        pax, pay, pbx, pby, ux, uy = spring_vectors(km, s, q, k)
        dux, duy = joint_separation_rate(v, a, b, pax, pay, pbx, pby)
        stiffness = km.spring_stiffness[s % km.spring_stiffness.shape[0], k]
        rest = km.spring_rest_length[s % km.spring_rest_length.shape[0], k]
        damping = km.spring_damping[s % km.spring_damping.shape[0], k]
        fx, fy = spring_force(ux, uy, dux, duy, stiffness, rest, damping)
        _add_generalised(F_out, b, 1.0, fx, fy, pbx, pby)
        _add_generalised(F_out, a, -1.0, fx, fy, pax, pay)


@njit(**JIT)
def damper_stiffness_add(km, s, q, v, K_out):
    """K += −∂F/∂q of the spring-dampers' damping forces at fixed q̇ (exact; not symmetric).

    With u̇ = G q̇ (G = ∂u/∂q), a damper pulls body b with f = −c Q u̇, Q = e eᵀ (rest length
    > 0, e = u/L) or I (rest length 0), and F = Gᵀ f, so
    −∂F/∂q = −(∂Gᵀ/∂q) f + c Gᵀ Q ∂u̇/∂q + (c/L) Gᵀ h nᵀ G (the last for Q = e eᵀ only),
    n ⟂ e, h = n (e·u̇) + e (n·u̇); ∂u̇/∂θ_b = −ω_b p_b, ∂u̇/∂θ_a = ω_a p_a, and
    f·∂²u/∂θ_b² = −f·p_b, f·∂²u/∂θ_a² = f·p_a. The elastic part is applied_stiffness_add's.
    """
    for k in range(km.spring_body_a.shape[0]):
        damping = km.spring_damping[s % km.spring_damping.shape[0], k]
        if damping == 0.0:
            continue
        a = km.spring_body_a[k]
        b = km.spring_body_b[k]
        pax, pay, pbx, pby, ux, uy = spring_vectors(km, s, q, k)
        dux, duy = joint_separation_rate(v, a, b, pax, pay, pbx, pby)
        isotropic = km.spring_rest_length[s % km.spring_rest_length.shape[0], k] == 0.0
        ex, ey = 1.0, 0.0
        if isotropic:
            fx, fy = -damping * dux, -damping * duy
        else:
            length = hypot(ux, uy)
            ex, ey = ux / length, uy / length
            nx, ny = -ey, ex
            along, across = ex * dux + ey * duy, nx * dux + ny * duy
            fx, fy = -damping * along * ex, -damping * along * ey
            hx, hy = nx * along + ex * across, ny * along + ey * across
            add_pair_product(K_out, damping / length, a, b, hx, hy, nx, ny, pax, pay, pbx, pby)
        if b >= 0:
            K_out[3 * b + 2, 3 * b + 2] += fx * pbx + fy * pby
            _damper_column(K_out, damping, isotropic, ex, ey, 3 * b + 2, -v[3 * b + 2], pbx, pby,
                           a, b, pax, pay, pbx, pby)  # fmt: skip
        if a >= 0:
            K_out[3 * a + 2, 3 * a + 2] -= fx * pax + fy * pay
            _damper_column(K_out, damping, isotropic, ex, ey, 3 * a + 2, v[3 * a + 2], pax, pay,
                           a, b, pax, pay, pbx, pby)  # fmt: skip


@njit(**JIT)
def _damper_column(K_out, damping, isotropic, ex, ey, col, omega, px, py, a, b, pax, pay, pbx,
                   pby):  # fmt: skip
    """K[:, col] += c Gᵀ Q ∂u̇/∂θ for the angle column ``col`` (∂u̇/∂θ = omega · p)."""
    wx, wy = omega * px, omega * py
    if not isotropic:
        along = ex * wx + ey * wy
        wx, wy = along * ex, along * ey
    add_pair_column(K_out, damping, col, a, b, wx, wy, pax, pay, pbx, pby)


@njit(**JIT)
def damping_matrix_add(km, s, q, scale, C_out):
    """C += scale · (−∂F/∂q̇), the dampers' velocity derivative at q (exact; symmetric, ≥ 0).

    F is linear in q̇: a damper adds c gᵀg with g = e·∂u/∂q (along the spring, rest length
    > 0) or c (gₓᵀgₓ + g_yᵀg_y) (isotropic, rest length 0).
    """
    for k in range(km.spring_body_a.shape[0]):
        damping = scale * km.spring_damping[s % km.spring_damping.shape[0], k]
        if damping == 0.0:
            continue
        a = km.spring_body_a[k]
        b = km.spring_body_b[k]
        pax, pay, pbx, pby, ux, uy = spring_vectors(km, s, q, k)
        if km.spring_rest_length[s % km.spring_rest_length.shape[0], k] == 0.0:
            add_pair_outer(C_out, damping, a, b, 1.0, 0.0, pax, pay, pbx, pby)
            add_pair_outer(C_out, damping, a, b, 0.0, 1.0, pax, pay, pbx, pby)
        else:
            length = hypot(ux, uy)
            add_pair_outer(C_out, damping, a, b, ux / length, uy / length, pax, pay, pbx, pby)


@njit(**JIT)
def applied_stiffness_add(km, s, q, t, K_out):
    """K += −∂F/∂q at q̇ = 0 and time ``t`` (exact; symmetric: at a given t every load here
    derives from a potential).

    Force f at p (times :func:`load_factor`): −∂F_θ/∂θ = p·f. Spring with V = ½ k (L − L₀)²:
    ∂²V/∂q² = k gₑᵀgₑ + k (L − L₀)/L gₙᵀgₙ + k (L − L₀) e·∂²u/∂q², gₑ/gₙ = e/n·∂u/∂q.
    """
    for k in range(km.force_body.shape[0]):
        b = km.force_body[k]
        if b < 0:
            continue
        px, py, fx, fy = force_lever(km, s, q, k)
        K_out[3 * b + 2, 3 * b + 2] += load_factor(km, s, k, t) * (px * fx + py * fy)
    for k in range(km.spring_body_a.shape[0]):
        a = km.spring_body_a[k]
        b = km.spring_body_b[k]
        pax, pay, pbx, pby, ux, uy = spring_vectors(km, s, q, k)
        stiffness = km.spring_stiffness[s % km.spring_stiffness.shape[0], k]
        rest = km.spring_rest_length[s % km.spring_rest_length.shape[0], k]
        if rest == 0.0:
            # V = ½ k |u|²: k (∂u/∂q)ᵀ(∂u/∂q) + k u·∂²u/∂q².
            add_pair_outer(K_out, stiffness, a, b, 1.0, 0.0, pax, pay, pbx, pby)
            add_pair_outer(K_out, stiffness, a, b, 0.0, 1.0, pax, pay, pbx, pby)
            wx = stiffness * ux
            wy = stiffness * uy
        else:
            length = hypot(ux, uy)
            ex = ux / length
            ey = uy / length
            tension = stiffness * (length - rest)
            add_pair_outer(K_out, stiffness, a, b, ex, ey, pax, pay, pbx, pby)
            add_pair_outer(K_out, tension / length, a, b, -ey, ex, pax, pay, pbx, pby)
            wx = tension * ex
            wy = tension * ey
        # w·∂²u/∂θ_b² = −w·p_b, w·∂²u/∂θ_a² = +w·p_a.
        if b >= 0:
            K_out[3 * b + 2, 3 * b + 2] -= wx * pbx + wy * pby
        if a >= 0:
            K_out[3 * a + 2, 3 * a + 2] += wx * pax + wy * pay


@njit(**JIT)
def own_items(km, kind, total):
    """How many of the ``total`` items of ``kind`` (0 bodies, 1 joints, 2 drivers, 3 loads,
    4 springs) are the mechanism's own: all, but in a model that carries an ideal copy
    after them (``Model.reference``: ``[[output]] relative_to``), whose energy and max |Φ|
    are left out of the mechanism's."""
    return km.reference[kind] if km.reference.shape[0] > 0 else total


@njit(**JIT)
def own_row(km, r):
    """Whether constraint row ``r`` is the mechanism's own (see :func:`own_items`): a row of
    its joints (the first ``reference[5]``) or of its drivers."""
    if km.reference.shape[0] == 0 or r < km.reference[5]:
        return True
    for d in range(km.reference[2]):
        if km.driver_row[d] == r:
            return True
    return False


@njit(**JIT)
def potential_energy(km, s, q):
    """Potential energy, J: −m g·r, −f·(r + p) and −τ θ of constant loads, and
    ½ k (L − L₀)². A load that varies in time has no potential (it does work, as a driver
    does). The mechanism's own (:func:`own_items`)."""
    energy = 0.0
    ig = s % km.gravity.shape[0]
    im = s % km.body_mass.shape[0]
    gx, gy = km.gravity[ig, 0], km.gravity[ig, 1]
    for b in range(own_items(km, 0, km.body_mass.shape[1])):
        energy -= gravity_potential(km.body_mass[im, b], gx, gy, q[3 * b], q[3 * b + 1])
    for k in range(own_items(km, 3, km.force_body.shape[0])):
        b = km.force_body[k]
        if b < 0 or km.force_law[k] != LOAD_CONSTANT:
            continue
        px, py, fx, fy = force_lever(km, s, q, k)
        torque = km.force_torque[s % km.force_torque.shape[0], k]
        x, y = q[3 * b] + px, q[3 * b + 1] + py
        energy -= load_potential(fx, fy, x, y, torque, q[3 * b + 2])
    for k in range(own_items(km, 4, km.spring_body_a.shape[0])):
        _, _, _, _, ux, uy = spring_vectors(km, s, q, k)
        stiffness = km.spring_stiffness[s % km.spring_stiffness.shape[0], k]
        rest = km.spring_rest_length[s % km.spring_rest_length.shape[0], k]
        energy += spring_energy(ux, uy, stiffness, rest)
    return energy


@njit(**JIT)
def kinetic_energy(km, s, v):
    """Kinetic energy ½ q̇ᵀ M q̇, J, of the mechanism's own bodies (:func:`own_items`)."""
    energy = 0.0
    im = s % km.body_mass.shape[0]
    ij = s % km.body_inertia.shape[0]
    for b in range(own_items(km, 0, km.body_mass.shape[1])):
        mass, inertia = km.body_mass[im, b], km.body_inertia[ij, b]
        energy += body_kinetic_energy(mass, inertia, v[3 * b], v[3 * b + 1], v[3 * b + 2])
    return energy


@njit(**JIT)
def mass_diagonal(km, s, m_out):
    """diag(M) into ``m_out`` (3 nbody,): m, m, J per body."""
    im = s % km.body_mass.shape[0]
    ij = s % km.body_inertia.shape[0]
    for b in range(km.body_mass.shape[1]):
        m_out[3 * b] = km.body_mass[im, b]
        m_out[3 * b + 1] = km.body_mass[im, b]
        m_out[3 * b + 2] = km.body_inertia[ij, b]
