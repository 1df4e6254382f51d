"""Constraints of one sample: joints (ideal, clearance) and drivers.

All functions take the kernel model ``km`` (:meth:`mcchain.model.Model.kernel_model`), the sample
index ``s`` (parameters are read with the broadcast index ``a[s % a.shape[0]]``) and the
coordinates ``q`` (3 nbody,) of that sample. Rows are ordered as ``km.joint_row`` /
``km.driver_row`` say. Nothing here allocates or raises.

For joint k between bearing body a and journal body b, with p = A(θ) s the rotated local
point, d = r_b + p_b − r_a − p_a (journal centre minus bearing centre):

* ideal:      Φ = d,          rows [I, Ω p_b] on b and [−I, −Ω p_a] on a;
* clearance:  Φ = |d| − c,    row e·∂d/∂q with e = d/|d|;
* prismatic:  Φ = (n·d, θ_b − θ_a − θ_0), n = A_a Ω u the normal of the unit axis u fixed
  in a: row n·∂d/∂q plus (Ω n)·d on θ_a (the normal turns with a), and the angle row;
* driver:     Φ = θ_j − f(t), f = θ_0 + ω t (law constant) or θ_0 + ω t + A (sin(2π f t + φ)
  − sin φ) (law harmonic): Φ_t = −ḟ, Φ_tt = −f̈ exactly (:func:`driver_swing`);
* slider driver of prismatic joint k: Φ = u·d − f(t), u = A_a u_0 the joint's unit axis (it
  turns with a), f = s_0 + v t (+ the same swing): the row u·∂d/∂q with (Ω u)·d on θ_a.
"""

from __future__ import annotations

import math

# numba reads module globals as compile-time constants
from mcchain.codes import (  # noqa: F401 (re-exported)
    DRIVER_CONSTANT,
    DRIVER_HARMONIC,
    DRIVER_TABLE,
    JOINT_CLEARANCE,
    JOINT_IDEAL,
    JOINT_PRISMATIC,
)
from mcchain.kernels.config import JIT, hypot, njit
from mcchain.kernels.tables import spline_at

TWO_PI = 2.0 * math.pi

# ---------------------------------------------------------------------------------------------
# Straight-line scalar laws: the one definition of each joint's, driver's and point's
# arithmetic. The loop kernels below call them; the lane generator inlines their text
# (mcchain.codegen.inline: same operations in the same order), with literal 0.0 / 1.0 for a
# ground body's terms, which it folds away.


@njit(**JIT)
def rotate(c, sn, px, py):
    """A(θ) p for (cos θ, sin θ) = (c, sn)."""
    return c * px - sn * py, sn * px + c * py


@njit(**JIT)
def point_velocity(vx, vy, w, px, py):
    """Velocity ṙ + θ̇ Ω p of the rotated point p of a body moving with (ẋ, ẏ, θ̇), m/s."""
    return vx - w * py, vy + w * px


@njit(**JIT)
def point_acceleration(ax, ay, al, w, px, py):
    """Acceleration r̈ + θ̈ Ω p − θ̇² p of the rotated point p of a body with accelerations
    (ẍ, ÿ, θ̈) turning at θ̇ = ``w``, m/s²."""
    return ax - al * py - w * w * px, ay + al * px - w * w * py


@njit(**JIT)
def separation(xa, ya, pax, pay, xb, yb, pbx, pby):
    """d = (r_b + p_b) − (r_a + p_a) from the centres r and rotated points p of bodies a and
    b (r = 0 for the ground), m: the world points first, so that a closed joint's d is their
    exact difference."""
    return (xb + pbx) - (xa + pax), (yb + pby) - (ya + pay)


@njit(**JIT)
def separation_rate(vax, vay, wa, pax, pay, vbx, vby, wb, pbx, pby):
    """ḋ = (ṙ_b + θ̇_b Ω p_b) − (ṙ_a + θ̇_a Ω p_a), m/s: the points' velocities first."""
    ubx, uby = point_velocity(vbx, vby, wb, pbx, pby)
    uax, uay = point_velocity(vax, vay, wa, pax, pay)
    return ubx - uax, uby - uay


@njit(**JIT)
def distance(dx, dy):
    """|d|, m: libm's hypot in the kernels; the lanes write it √(dx² + dy²), which
    vectorises (mcchain.codegen.inline; the two differ by at most an ulp)."""
    return hypot(dx, dy)


@njit(**JIT)
def point_row(sign, wx, wy, px, py):
    """B's entries (x, y, θ) of the row sign · w·(r + p) on the point's body: sign · (wx,
    wy, w·Ω p) for the rotated point p = A s (w·Ω p = −wx py + wy px, m)."""
    return sign * wx, sign * wy, sign * (-wx * py + wy * px)


@njit(**JIT)
def centripetal(pax, pay, pbx, pby, wa, wb):
    """g = p_b θ̇_b² − p_a θ̇_a²: the part of d̈ that B q̈ leaves out (d̈ = ∂d/∂q q̈ − g), m/s²."""
    return pbx * wb * wb - pax * wa * wa, pby * wb * wb - pay * wa * wa


@njit(**JIT)
def inverse_distance(rho, guarded):
    """1/|d| of a clearance joint; with ``guarded`` = 1 (a journal that may sit at its
    bearing centre: under a contact law, and in the loop kernels) 0 at |d| = 0, where there
    is no normal and none is needed."""
    if guarded == 1.0:
        return 1.0 / rho if rho > 0.0 else 0.0
    return 1.0 / rho


@njit(**JIT)
def clearance_rate(ex, ey, ddx, ddy):
    """Φ̇ = e·ḋ of a clearance row |d| − c, m/s."""
    return ex * ddx + ey * ddy


@njit(**JIT)
def clearance_gamma(ex, ey, gx, gy, ddx, ddy, along, irho):
    """γ of a clearance row |d| − c: e·g − (|ḋ|² − (e·ḋ)²)/|d|, with e = d/|d|, ``along``
    = e·ḋ and ``irho`` = 1/|d| (0 where there is no normal: γ = 0)."""
    return ex * gx + ey * gy - (ddx * ddx + ddy * ddy - along * along) * irho


@njit(**JIT)
def distance_squared(dx, dy):
    """|d|², m²."""
    return dx * dx + dy * dy


@njit(**JIT)
def clearance_gamma_scaled(dx, dy, gx, gy, ddx, ddy, inverse_square):
    """|d| γ: γ of a clearance row |d| − c (:func:`clearance_gamma`) for the row multiplied
    by |d| (entries d·∂d/∂q), with ``inverse_square`` = 1/|d|²: d·g − (d × ḋ)²/|d|², as
    |ḋ|²|d|² − (d·ḋ)² = (d × ḋ)² (no √ and no 1/|d| in it), m²/s²."""
    cross = dx * ddy - dy * ddx
    return dx * gx + dy * gy - cross * cross * inverse_square


@njit(**JIT)
def axis_normal(c, sn, ux, uy):
    """n = A_a Ω u_0 of a prismatic joint's unit axis u_0 fixed in body a at angle θ_a
    (c, sn = cos θ_a, sin θ_a): the world normal to the axis."""
    return rotate(c, sn, -uy, ux)


@njit(**JIT)
def axis_turn(wx, wy, pax, pay, dx, dy):
    """B's θ_a entry of w·d for a vector w fixed in body a: w·(−Ω p_a) + (Ω w)·d."""
    return wx * (pay + dy) - wy * (pax + dx)


@njit(**JIT)
def prismatic_residual(nx, ny, dx, dy, tha, thb, rel):
    """Φ of a prismatic joint: (n·d, θ_b − θ_a − θ_0), m and rad."""
    return nx * dx + ny * dy, thb - tha - rel


@njit(**JIT)
def prismatic_rate(nx, ny, dx, dy, ddx, ddy, wa, wb):
    """Φ̇ of a prismatic joint: (n·ḋ + θ̇_a (Ω n)·d, θ̇_b − θ̇_a), m/s and rad/s (ṅ = θ̇_a Ω n)."""
    return nx * ddx + ny * ddy + wa * (-ny * dx + nx * dy), wb - wa


@njit(**JIT)
def prismatic_gamma(nx, ny, gx, gy, dx, dy, ddx, ddy, wa):
    """γ of a prismatic joint's offset row n·d: n·(p_b θ̇_b² − p_a θ̇_a²) (``gx``, ``gy``)
    + θ̇_a² n·d − 2 θ̇_a (Ω n)·ḋ, from n̈ = θ̈_a Ω n − θ̇_a² n and ṅ = θ̇_a Ω n."""
    return nx * gx + ny * gy + wa * wa * (nx * dx + ny * dy) - 2.0 * wa * (-ny * ddx + nx * ddy)


@njit(**JIT)
def harmonic_swing(amp, w, sin_arg, cos_arg, sin_phase):
    """A harmonic driver law's swing and its derivatives, from sin/cos of Ωt + φ and sin φ:
    (A (sin(Ωt + φ) − sin φ), A Ω cos(Ωt + φ), −A Ω² sin(Ωt + φ)), Ω = ``w`` in rad/s."""
    return amp * (sin_arg - sin_phase), amp * w * cos_arg, -amp * w * w * sin_arg


@njit(**JIT)
def driver_residual(coordinate, start, rate, t, swing):
    """Φ = x − f(t), f = f(0) + rate · t + swing: θ_j (rad) or a slider's u·d (m)."""
    return coordinate - start - rate * t - swing


@njit(**JIT)
def driver_speed(rate, swing_rate):
    """ḟ = rate + the swing's rate (rad/s or m/s): ν = −Φ_t of the driver's row."""
    return rate + swing_rate


@njit(**JIT)
def driver_swing(km, s, j, t):
    """What driver ``j``'s law adds at ``t`` to the steady f(0) + rate · t, with its first and
    second derivatives: (A (sin(Ωt + φ) − sin φ), A Ω cos(Ωt + φ), −A Ω² sin(Ωt + φ)), Ω = 2π f,
    for a harmonic law; (g(t) − g(0), ġ, g̈) of the spline g of a table law (whose f(0) is
    g(0) and rate 0); zeros at constant speed."""
    if km.driver_law[j] == DRIVER_TABLE:
        n = km.driver_table_size[j]
        knots = km.driver_table_knots[j]
        coef = km.driver_table_coef[j]
        value, rate, acc = spline_at(knots, coef, n, t)
        return value - spline_at(knots, coef, n, 0.0)[0], rate, acc
    if km.driver_law[j] != DRIVER_HARMONIC:
        return 0.0, 0.0, 0.0
    amp = km.driver_amplitude[s % km.driver_amplitude.shape[0], j]
    w = TWO_PI * km.driver_frequency[s % km.driver_frequency.shape[0], j]
    phase = km.driver_phase[s % km.driver_phase.shape[0], j]
    arg = w * t + phase
    return harmonic_swing(amp, w, math.sin(arg), math.cos(arg), math.sin(phase))


@njit(**JIT)
def driver_start(km, s, j):
    """(f(0), steady rate) of driver ``j``: (θ_0, ω) in rad, rad/s, or (s_0, v) in m, m/s for
    a slider driver."""
    if km.driver_joint[j] >= 0:
        return (
            km.driver_displacement0[s % km.driver_displacement0.shape[0], j],
            km.driver_speed[s % km.driver_speed.shape[0], j],
        )
    return (
        km.driver_angle0[s % km.driver_angle0.shape[0], j],
        km.driver_omega[s % km.driver_omega.shape[0], j],
    )


@njit(**JIT)
def driver_rate(km, s, j, t):
    """ḟ of driver ``j`` at ``t`` (rad/s, or m/s for a slider driver): the steady rate plus
    the swing's."""
    return driver_speed(driver_start(km, s, j)[1], driver_swing(km, s, j, t)[1])


@njit(**JIT)
def slider_axis(km, s, q, k):
    """World unit axis u = A_a u_0 of prismatic joint ``k`` (u_0 fixed in body a)."""
    i = s % km.joint_axis.shape[0]
    _, _, ca, sa = body_pose(q, km.joint_body_a[k])
    return rotate(ca, sa, km.joint_axis[i, k, 0], km.joint_axis[i, k, 1])


@njit(**JIT)
def slider_displacement(km, s, q, j):
    """u·d of slider driver ``j``'s prismatic joint, m, and the joint's vectors: (u·d, k, ux,
    uy, pax, pay, pbx, pby, dx, dy)."""
    k = km.driver_joint[j]
    pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
    ux, uy = slider_axis(km, s, q, k)
    return ux * dx + uy * dy, k, ux, uy, pax, pay, pbx, pby, dx, dy


@njit(**JIT)
def body_pose(q, b):
    """Centre (x, y) and (cos θ, sin θ) of body ``b``; the ground (b < 0) is at rest at 0."""
    if b < 0:
        return 0.0, 0.0, 1.0, 0.0
    theta = q[3 * b + 2]
    return q[3 * b], q[3 * b + 1], math.cos(theta), math.sin(theta)


@njit(**JIT)
def body_velocity(v, b):
    """Velocity (ẋ, ẏ, θ̇) of body ``b``; zero for the ground."""
    if b < 0:
        return 0.0, 0.0, 0.0
    return v[3 * b], v[3 * b + 1], v[3 * b + 2]


@njit(**JIT)
def pair_vectors(q, s, a, b, points_a, points_b, k):
    """Rotated points p_a, p_b and separation d = (r_b + p_b) − (r_a + p_a) of the point
    pair ``k`` of bodies a and b, whose local points are ``points_a[s, k]`` and
    ``points_b[s, k]`` (broadcast over samples): a joint's or a spring's.

    Returns:
        (pax, pay, pbx, pby, dx, dy), m.
    """
    ia = s % points_a.shape[0]
    ib = s % points_b.shape[0]
    xa, ya, ca, sa = body_pose(q, a)
    xb, yb, cb, sb = body_pose(q, b)
    pax, pay = rotate(ca, sa, points_a[ia, k, 0], points_a[ia, k, 1])
    pbx, pby = rotate(cb, sb, points_b[ib, k, 0], points_b[ib, k, 1])
    dx, dy = separation(xa, ya, pax, pay, xb, yb, pbx, pby)
    return pax, pay, pbx, pby, dx, dy


@njit(**JIT)
def joint_vectors(km, s, q, k):
    """:func:`pair_vectors` of joint ``k`` (d: journal centre minus bearing centre)."""
    a, b = km.joint_body_a[k], km.joint_body_b[k]
    return pair_vectors(q, s, a, b, km.joint_point_a, km.joint_point_b, k)


@njit(**JIT)
def prismatic_normal(km, s, q, k):
    """World normal n = A_a Ω u of prismatic joint ``k``'s unit axis u (fixed in body a)."""
    i = s % km.joint_axis.shape[0]
    _, _, ca, sa = body_pose(q, km.joint_body_a[k])
    return axis_normal(ca, sa, km.joint_axis[i, k, 0], km.joint_axis[i, k, 1])


@njit(**JIT)
def joint_separation_rate(v, a, b, pax, pay, pbx, pby):
    """ḋ = ṙ_b + Ω p_b θ̇_b − ṙ_a − Ω p_a θ̇_a, m/s."""
    vax, vay, wa = body_velocity(v, a)
    vbx, vby, wb = body_velocity(v, b)
    return separation_rate(vax, vay, wa, pax, pay, vbx, vby, wb, pbx, pby)


@njit(**JIT)
def constraint_residual(km, s, q, t, phi_out):
    """Φ(q, t) into ``phi_out`` (ncon,): m for joints, rad for drivers."""
    for k in range(km.joint_body_a.shape[0]):
        _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
        row = km.joint_row[k]
        if km.joint_kind[k] == JOINT_IDEAL:
            phi_out[row] = dx
            phi_out[row + 1] = dy
        elif km.joint_kind[k] == JOINT_PRISMATIC:
            nx, ny = prismatic_normal(km, s, q, k)
            a = km.joint_body_a[k]
            b = km.joint_body_b[k]
            tha = q[3 * a + 2] if a >= 0 else 0.0
            thb = q[3 * b + 2] if b >= 0 else 0.0
            rel = km.joint_relative_angle[s % km.joint_relative_angle.shape[0], k]
            phi_out[row], phi_out[row + 1] = prismatic_residual(nx, ny, dx, dy, tha, thb, rel)
        else:
            c = km.joint_clearance[s % km.joint_clearance.shape[0], k]
            phi_out[row] = distance(dx, dy) - c
    for j in range(km.driver_body.shape[0]):
        if km.driver_joint[j] >= 0:
            start, rate = driver_start(km, s, j)
            along = slider_displacement(km, s, q, j)[0]
            swing = driver_swing(km, s, j, t)[0]
            phi_out[km.driver_row[j]] = driver_residual(along, start, rate, t, swing)
            continue
        i = s % km.driver_omega.shape[0]
        i0 = s % km.driver_angle0.shape[0]
        theta = q[3 * km.driver_body[j] + 2]
        swing = driver_swing(km, s, j, t)[0]  # 0.0 at constant speed: x − 0.0 is x
        phi_out[km.driver_row[j]] = driver_residual(
            theta, km.driver_angle0[i0, j], km.driver_omega[i, j], t, swing
        )


@njit(**JIT)
def _add_point_rows(B_out, row, body, sign, wx, wy, px, py):
    """Add ``sign * w·∂(r + p)/∂q_body`` to row ``row`` of B (nothing for the ground)."""
    if body < 0:
        return
    bx, by, bt = point_row(sign, wx, wy, px, py)
    B_out[row, 3 * body] += bx
    B_out[row, 3 * body + 1] += by
    B_out[row, 3 * body + 2] += bt


@njit(**JIT)
def axis_row(B_out, row, a, b, wx, wy, pax, pay, pbx, pby, dx, dy):
    """Add w·∂d/∂q to row ``row`` of B for a vector w fixed in body a (∂w/∂θ_a = Ω w: the
    term (Ω w)·d on θ_a): a prismatic joint's offset row (w = n) or a slider driver's (w = u)."""
    _add_point_rows(B_out, row, b, 1.0, wx, wy, pbx, pby)
    if a >= 0:
        B_out[row, 3 * a] -= wx
        B_out[row, 3 * a + 1] -= wy
        B_out[row, 3 * a + 2] += axis_turn(wx, wy, pax, pay, dx, dy)


@njit(**JIT)
def prismatic_rows(B_out, row, a, b, nx, ny, pax, pay, pbx, pby, dx, dy):
    """Add the two rows of a prismatic joint to B: n·∂d/∂q with (Ω n)·d on θ_a (∂n/∂θ_a =
    Ω n), then θ_b − θ_a."""
    axis_row(B_out, row, a, b, nx, ny, pax, pay, pbx, pby, dx, dy)
    if a >= 0:
        B_out[row + 1, 3 * a + 2] -= 1.0
    if b >= 0:
        B_out[row + 1, 3 * b + 2] += 1.0


@njit(**JIT)
def constraint_jacobian(km, s, q, B_out):
    """B = ∂Φ/∂q into ``B_out`` (ncon, 3 nbody); the array is overwritten.

    A clearance row whose |d| is 0 has no direction: it is left as zeros, which the solvers
    see as rank loss (status SINGULAR).
    """
    B_out[:, :] = 0.0
    for k in range(km.joint_body_a.shape[0]):
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
        row = km.joint_row[k]
        if km.joint_kind[k] == JOINT_IDEAL:
            _add_point_rows(B_out, row, b, 1.0, 1.0, 0.0, pbx, pby)
            _add_point_rows(B_out, row, a, -1.0, 1.0, 0.0, pax, pay)
            _add_point_rows(B_out, row + 1, b, 1.0, 0.0, 1.0, pbx, pby)
            _add_point_rows(B_out, row + 1, a, -1.0, 0.0, 1.0, pax, pay)
        elif km.joint_kind[k] == JOINT_PRISMATIC:
            prismatic_rows(
                B_out, row, a, b, *prismatic_normal(km, s, q, k), pax, pay, pbx, pby, dx, dy
            )
        else:
            dist = distance(dx, dy)
            if dist > 0.0:
                ex = dx / dist
                ey = dy / dist
                _add_point_rows(B_out, row, b, 1.0, ex, ey, pbx, pby)
                _add_point_rows(B_out, row, a, -1.0, ex, ey, pax, pay)
    for j in range(km.driver_body.shape[0]):
        if km.driver_joint[j] >= 0:
            _, k, ux, uy, pax, pay, pbx, pby, dx, dy = slider_displacement(km, s, q, j)
            a = km.joint_body_a[k]
            b = km.joint_body_b[k]
            axis_row(B_out, km.driver_row[j], a, b, ux, uy, pax, pay, pbx, pby, dx, dy)
            continue
        B_out[km.driver_row[j], 3 * km.driver_body[j] + 2] = 1.0


@njit(**JIT)
def joint_rate_terms(km, s, q, v, k):
    """:func:`joint_vectors` of joint ``k``, θ̇_a, and g = p_b θ̇_b² − p_a θ̇_a² (the part of
    d̈ that B q̈ leaves out, with a minus sign: d̈ = ∂d/∂q q̈ − g).

    Returns:
        (pax, pay, pbx, pby, dx, dy, wa, gx, gy).
    """
    a = km.joint_body_a[k]
    b = km.joint_body_b[k]
    pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
    wa = v[3 * a + 2] if a >= 0 else 0.0
    wb = v[3 * b + 2] if b >= 0 else 0.0
    gx, gy = centripetal(pax, pay, pbx, pby, wa, wb)
    return pax, pay, pbx, pby, dx, dy, wa, gx, gy


@njit(**JIT)
def constraint_gamma(km, s, q, v, t, gamma_out):
    """γ = −(Ḃ q̇ + Φ_tt) at ``t`` into ``gamma_out`` (ncon,), so that B q̈ = γ. m/s² or
    rad/s².

    Ideal: γ = p_b θ̇_b² − p_a θ̇_a². Clearance: γ = e·(p_b θ̇_b² − p_a θ̇_a²)
    − (|ḋ|² − (e·ḋ)²)/|d|. Prismatic: :func:`prismatic_gamma`, 0 for the angle row.
    Drivers: γ = f̈ (0 at constant speed).
    """
    for k in range(km.joint_body_a.shape[0]):
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy, wa, gx, gy = joint_rate_terms(km, s, q, v, k)
        row = km.joint_row[k]
        if km.joint_kind[k] == JOINT_IDEAL:
            gamma_out[row] = gx
            gamma_out[row + 1] = gy
        elif km.joint_kind[k] == JOINT_PRISMATIC:
            nx, ny = prismatic_normal(km, s, q, k)
            ddx, ddy = joint_separation_rate(v, a, b, pax, pay, pbx, pby)
            gamma_out[row] = prismatic_gamma(nx, ny, gx, gy, dx, dy, ddx, ddy, wa)
            gamma_out[row + 1] = 0.0
        else:
            # a journal at its bearing centre (under a law): no normal, 1/|d| = 0, γ = 0
            irho = inverse_distance(distance(dx, dy), 1.0)
            ex = dx * irho
            ey = dy * irho
            ddx, ddy = joint_separation_rate(v, a, b, pax, pay, pbx, pby)
            along = clearance_rate(ex, ey, ddx, ddy)
            gamma_out[row] = clearance_gamma(ex, ey, gx, gy, ddx, ddy, along, irho)
    for j in range(km.driver_body.shape[0]):
        acc = driver_swing(km, s, j, t)[2]  # −Φ_tt = f̈
        if km.driver_joint[j] >= 0:  # −(Ḃ q̇) of u·d: as a prismatic offset row, u for n
            k = km.driver_joint[j]
            a = km.joint_body_a[k]
            b = km.joint_body_b[k]
            pax, pay, pbx, pby, dx, dy, wa, gx, gy = joint_rate_terms(km, s, q, v, k)
            ux, uy = slider_axis(km, s, q, k)
            ddx, ddy = joint_separation_rate(v, a, b, pax, pay, pbx, pby)
            acc += prismatic_gamma(ux, uy, gx, gy, dx, dy, ddx, ddy, wa)
        gamma_out[km.driver_row[j]] = acc


@njit(**JIT)
def constraint_velocity_rhs(km, s, t, nu_out):
    """ν = −Φ_t at ``t`` into ``nu_out`` (ncon,), so that B q̇ = ν: ḟ for drivers, 0 for
    joints."""
    nu_out[:] = 0.0
    for j in range(km.driver_body.shape[0]):
        nu_out[km.driver_row[j]] = driver_rate(km, s, j, t)


@njit(**JIT)
def _pair_gradient(a, b, wx, wy, pax, pay, pbx, pby):
    """Indices and values of g = w·∂d/∂q, d = (r_b + p_b) − (r_a + p_a): six non-zeros,
    (+wx, +wy, w·Ωp_b) on b and their negatives on a; the ground's indices are negative."""
    idx = (3 * b, 3 * b + 1, 3 * b + 2, 3 * a, 3 * a + 1, 3 * a + 2)
    return idx, point_row(1.0, wx, wy, pbx, pby) + point_row(-1.0, wx, wy, pax, pay)


@njit(**JIT)
def add_pair_product(K_out, scale, a, b, xx, xy, yx, yy, pax, pay, pbx, pby):
    """K += scale · g_xᵀ g_y with g_w = w·∂d/∂q for the point pair (see _pair_gradient)."""
    idx, gx = _pair_gradient(a, b, xx, xy, pax, pay, pbx, pby)
    _, gy = _pair_gradient(a, b, yx, yy, pax, pay, pbx, pby)
    for i in range(6):
        if idx[i] < 0:
            continue
        for j in range(6):
            if idx[j] >= 0:
                K_out[idx[i], idx[j]] += scale * gx[i] * gy[j]


@njit(**JIT)
def add_pair_outer(K_out, scale, a, b, wx, wy, pax, pay, pbx, pby):
    """K += scale · gᵀg with g = w·∂d/∂q, d = (r_b + p_b) − (r_a + p_a) for any point pair."""
    add_pair_product(K_out, scale, a, b, wx, wy, wx, wy, pax, pay, pbx, pby)


@njit(**JIT)
def add_pair_column(K_out, scale, col, a, b, wx, wy, pax, pay, pbx, pby):
    """K[:, col] += scale · gᵀ with g = w·∂d/∂q for the point pair."""
    idx, g = _pair_gradient(a, b, wx, wy, pax, pay, pbx, pby)
    for i in range(6):
        if idx[i] >= 0:
            K_out[idx[i], col] += scale * g[i]


@njit(**JIT)
def _prismatic_hessian_add(K_out, lam, a, b, nx, ny, pax, pay, pbx, pby, dx, dy):
    """K += λ ∂²(n·d)/∂q² of a prismatic joint's offset row (its angle row is linear):
    ∂²/∂r_b∂θ_a = Ω n, ∂²/∂r_a∂θ_a = −Ω n, ∂²/∂θ_b² = −n·p_b, ∂²/∂θ_a∂θ_b = n·p_b,
    ∂²/∂θ_a² = −n·d − n·p_a (n turns with a: ∂n/∂θ_a = Ω n, ∂²n/∂θ_a² = −n)."""
    npb = nx * pbx + ny * pby
    if b >= 0:
        K_out[3 * b + 2, 3 * b + 2] -= lam * npb
    if a >= 0:
        ta = 3 * a + 2
        K_out[ta, ta] -= lam * (nx * dx + ny * dy + nx * pax + ny * pay)
        for i, w in ((0, -ny), (1, nx)):  # Ω n
            K_out[3 * a + i, ta] -= lam * w
            K_out[ta, 3 * a + i] -= lam * w
            if b >= 0:
                K_out[3 * b + i, ta] += lam * w
                K_out[ta, 3 * b + i] += lam * w
        if b >= 0:
            K_out[ta, 3 * b + 2] += lam * npb
            K_out[3 * b + 2, ta] += lam * npb


@njit(**JIT)
def constraint_hessian_add(km, s, q, lam, K_out):
    """K += Σ_r λ_r ∂²Φ_r/∂q² = ∂(Bᵀλ)/∂q at fixed λ (exact second derivatives).

    ∂²d/∂θ_b² = −p_b and ∂²d/∂θ_a² = +p_a; a clearance row adds (λ/|d|) gᵀg with
    g = n·∂d/∂q, n ⟂ e (the curvature of |d|); prismatic: :func:`_prismatic_hessian_add`.
    Drivers of an angle are linear in q; a slider driver's row u·d is curved as a prismatic
    offset row (:func:`_prismatic_hessian_add` with u for n).
    """
    for k in range(km.joint_body_a.shape[0]):
        a = km.joint_body_a[k]
        b = km.joint_body_b[k]
        pax, pay, pbx, pby, dx, dy = joint_vectors(km, s, q, k)
        row = km.joint_row[k]
        if km.joint_kind[k] == JOINT_IDEAL:
            lx = lam[row]
            ly = lam[row + 1]
        elif km.joint_kind[k] == JOINT_PRISMATIC:
            nx, ny = prismatic_normal(km, s, q, k)
            _prismatic_hessian_add(K_out, lam[row], a, b, nx, ny, pax, pay, pbx, pby, dx, dy)
            continue
        else:
            dist = distance(dx, dy)
            ex = dx / dist
            ey = dy / dist
            lx = lam[row] * ex
            ly = lam[row] * ey
            add_pair_outer(K_out, lam[row] / dist, a, b, -ey, ex, pax, pay, pbx, pby)
        if b >= 0:
            K_out[3 * b + 2, 3 * b + 2] -= lx * pbx + ly * pby
        if a >= 0:
            K_out[3 * a + 2, 3 * a + 2] += lx * pax + ly * pay
    for j in range(km.driver_body.shape[0]):
        if km.driver_joint[j] >= 0:
            _, k, ux, uy, pax, pay, pbx, pby, dx, dy = slider_displacement(km, s, q, j)
            a = km.joint_body_a[k]
            b = km.joint_body_b[k]
            lam_j = lam[km.driver_row[j]]
            _prismatic_hessian_add(K_out, lam_j, a, b, ux, uy, pax, pay, pbx, pby, dx, dy)


@njit(**JIT)
def joint_forces(km, s, q, lam, force_out, contact_out):
    """Force on the journal body b by the bearing body a, and each joint's scalar reaction.

    Args:
        lam: (ncon,) multipliers.
        force_out: (njoint, 2) global frame, N: −λ (ideal), −λ e (clearance), −λ₁ n
            (prismatic: normal to the axis, acting at the point on b).
        contact_out: (njoint,) λ of clearance joints (> 0: real contact); the couple −λ₂ on
            b by a of prismatic joints, N m (with the force at b's point, the whole
            reaction); NaN for ideal revolute ones.
    """
    for k in range(km.joint_body_a.shape[0]):
        row = km.joint_row[k]
        if km.joint_kind[k] == JOINT_IDEAL:
            force_out[k, 0] = -lam[row]
            force_out[k, 1] = -lam[row + 1]
            contact_out[k] = math.nan
        elif km.joint_kind[k] == JOINT_PRISMATIC:
            nx, ny = prismatic_normal(km, s, q, k)
            force_out[k, 0] = -lam[row] * nx
            force_out[k, 1] = -lam[row] * ny
            contact_out[k] = -lam[row + 1]
        else:
            _, _, _, _, dx, dy = joint_vectors(km, s, q, k)
            dist = distance(dx, dy)
            if not dist > 0.0:  # a journal at its bearing centre (under a law): no force
                dist = math.inf
            force_out[k, 0] = -lam[row] * dx / dist
            force_out[k, 1] = -lam[row] * dy / dist
            contact_out[k] = lam[row]
