"""Contact-law data shared by the scene layer and the kernels (no numba here).

The clearance joint's contact model (``[joint.contact]`` in a scene) is a compliant force law
between the journal and its bearing: with ``d`` the vector from the bearing point to the
journal point, ``δ = |d| − c`` the penetration, ``n = d/|d|`` and ``δ̇ = n·ḋ``,

    F_n = K δ^m (1 + D δ̇)  for δ > 0, clipped at F_n ≥ 0;   F_n = 0 for δ ≤ 0,

with the hysteresis damping factor ``D`` fixed at the contact's onset from the restitution
``e`` and the approach speed ``δ̇⁻`` (see :data:`LAW_CODES`). The kernels evaluate the law
(:mod:`mcchain.kernels.contact`); this module holds what the scene loader needs without
importing numba: the law names and codes, the default friction regularisation velocities,
and the stiffness of internal cylindrical contact from radius, clearance and materials.
"""

from __future__ import annotations

import math
from typing import Literal, get_args

HERTZ = 0
"""Purely elastic Hertz law, D = 0."""
LANKARANI_NIKRAVESH = 1
"""D = 3 (1 − e²) / (4 δ̇⁻) (Lankarani & Nikravesh 1990, J. Mech. Des. 112, 369–376)."""
FLORES = 2
"""D = 8 (1 − e) / (5 e δ̇⁻) (Flores, Machado, Silva & Martins 2011, Multibody Syst. Dyn. 25,
357–375)."""
HUNT_CROSSLEY = 3
"""D = 3 (1 − e) / (2 δ̇⁻) (Hunt & Crossley 1975, J. Appl. Mech. 42, 440–445)."""
GONTHIER = 4
"""D = (1 − e²) / (e δ̇⁻) (Gonthier, McPhee, Lange & Piedbœuf 2004, Multibody Syst. Dyn. 11,
209–233)."""
HU_GUO = 5
"""D = 3 (1 − e) / (2 e δ̇⁻) (Hu & Guo 2015, Multibody Syst. Dyn. 35, 131–151)."""

HERTZ_EXPONENT = 1.5
"""The exponent m of Hertz's law for the contact of curved surfaces: the default exponent of
``[joint.contact]`` (:data:`mcchain.parameters.TABLE`) and the one
:func:`internal_cylinder_stiffness` gives K for."""

LawName = Literal["hertz", "lankarani-nikravesh", "flores", "hunt-crossley", "gonthier", "hu-guo"]
"""``[joint.contact] law`` as a scene spells it, in the order of the codes above (the scene
schema takes this type; χ(e) of each is :func:`mcchain.kernels.contact.restitution_factor`)."""

LAW_CODES: dict[str, int] = {name: code for code, name in enumerate(get_args(LawName))}
"""Scene spelling of ``[joint.contact] law`` → the integer code the kernels take."""

LAW_NAMES: dict[int, str] = {code: name for name, code in LAW_CODES.items()}
"""Integer code → scene spelling."""

DAMPED_LAWS = tuple(name for name, code in LAW_CODES.items() if code != HERTZ)
"""The laws whose damping needs a coefficient of restitution."""

LINK = 0
"""Joint model: the massless link |d| = c (the paper's model), a constraint row."""
CONTACT = 1
"""Joint model: the contact law from t = 0 (free flight and impacts), no constraint row."""
AUTO = 2
"""Joint model: the link while λ > 0, the contact law from the first λ ≤ 0 on."""

MODEL_CODES: dict[str, int] = {"link": LINK, "contact": CONTACT, "auto": AUTO}
"""Scene spelling of ``[[joint]] model`` → the integer code in ``Model.joint_model``."""

MODEL_NAMES: dict[int, str] = {code: name for name, code in MODEL_CODES.items()}
"""Integer code → scene spelling."""

START_LINK = 0
"""``Model.joint_start``: the joint starts on the link (model auto, the journal on the wall;
the kernels switch it to the law at once where the link's λ ≤ 0)."""
START_LAW = 1
"""``Model.joint_start``: the joint starts under the law, the journal off the wall (free,
δ < −tolerance, or pressed, δ > tolerance; a pressed start is a contact without onset:
undamped until it first separates)."""
START_SEATED = 2
"""``Model.joint_start``: the joint starts under the law with the journal on the wall
(|δ| ≤ :func:`seat_tolerance`): in contact from t = 0 whichever side of 0 rounding puts δ,
undamped and without an onset, until the journal is more than the tolerance off the wall."""

ContactStart = Literal["pressed", "seated", "centred"]
"""``[joint.contact] start``: where the journal of an assembled state starts its time history
(:func:`mcchain.solvers.start.contact_start`): pressed into its wall along the ideal
mechanism's joint force at t = 0 by the δ₀ whose force K δ₀^m balances it, on its wall with
no force (the assembled state as it is), or at its bearing's centre (d = 0)."""

PLACE_SEATED, PLACE_PRESSED, PLACE_CENTRED = 0, 1, 2
"""The codes of :data:`ContactStart` the start kernel takes (``mcchain.kernels.start``)."""

PLACE_CODES: dict[str, int] = {
    "seated": PLACE_SEATED,
    "pressed": PLACE_PRESSED,
    "centred": PLACE_CENTRED,
}
"""Scene spelling of ``[joint.contact] start`` → its code."""

DEFAULT_START: dict[str, str] = {"contact": "pressed", "auto": "seated", "link": "seated"}
"""``[joint.contact] start`` by the joint's model when the file does not give it: model
contact starts pressed; model auto on the link, which carries the joint force from t = 0
(the rigid limit of a pressed start: the journal seated on its wall); the link has no law."""

SEAT_TOLERANCE = 1e-9
"""Relative to the clearance: a journal with |δ| ≤ SEAT_TOLERANCE · c is on the wall
(seated). Above the rounding of δ (≈ 1e-16 of the mechanism's size, i.e. ≲ 1e-13 c for
c ≥ 1e-4 of it) and of an assembled journal (1e-14 of the size), far below any contact's
penetration (≳ 1e-8 m)."""


def seat_tolerance(clearance: float) -> float:
    """|δ| (m) at or under which a journal of clearance ``clearance`` (m) is seated."""
    return SEAT_TOLERANCE * clearance


SEATED = -1.0
"""The kernels' approach-speed column (``VI``) of a seated contact: a start on the wall."""
SEATED_AT_SWITCH = -2.0
"""... and of the contact seated by the switch of model auto, while the journal stays within
the tolerance of the wall: the link's λ reached 0 there and the journal leaves the wall, so
its free flight counts from the switch (the instant ``first_separation_time`` records), not
from where it is the tolerance off the wall — that instant hangs on the link's constraint
residual at the switch (δ ≈ ±4e-14 m moves it by 3e-8 s on the Flores slider-crank). Should
δ exceed the tolerance first (the journal presses back), it is an ordinary seated contact
(:data:`SEATED`) from there, and its free flight ends there."""


MODE_LINK = 0
"""``contact_mode`` output: the joint is the link (constraint row active)."""
MODE_CONTACT = 1
"""``contact_mode`` output: the contact law is active and the journal presses (δ > 0)."""
MODE_FREE = 2
"""``contact_mode`` output: the contact law is active and the journal flies free (δ ≤ 0)."""

CONTACT_SUMMARY = ("nim", "pkf", "pkd", "tff", "tse")
"""Per-joint summaries the lane kernels keep for each contact-law joint, in the order of
their ``sum_ct`` columns: impacts, peak contact force, peak penetration, free-flight time,
first separation time."""

RESEAT_RATE = 0.1
"""Model auto goes back to the link when the journal is quasi-statically pressed on the wall:
|δ̇| < RESEAT_RATE ω_c δ (the normal motion's kinetic energy ≤ 1 % of the contact's
oscillation energy at amplitude δ; a rebound has |δ̇| ≈ ω_c δ_max; a journal sliding on the
wall of a swinging mechanism shows 0.005–0.03 from its slowly varying load), with δ > 0 and
F_n > 0, ..."""
RESEAT_PERIODS = 5.0
"""... continuously for RESEAT_PERIODS periods 2π/ω_c of the contact's linearised oscillation
(the rebounds have died out). Then q and v are projected onto the link (M-orthogonal), which
cannot add kinetic energy and drops the elastic energy K δ^(m+1)/(m+1)."""
RESEAT_TOLERANCE = 1e-13
"""max |Φ| (m, rad) at which the projection of a re-seat stops iterating."""
RESEAT_NEWTON = 20
"""Newton iterations of that projection at most."""

SWITCH_OVERSHOOT = 1.0001
"""An adaptive step in which the link's λ of a model-auto joint falls to ≤ 0 is retried with
this multiple of the linearly interpolated crossing's fraction of the step: it lands just past
the crossing, where the law takes over."""

CONTACT_STEP_LIMIT = 0.5
"""Largest ω_c h a fixed-step method may take in contact (ω_c = √(∂F_n/∂δ / m*), m* the
journal's effective mass along n): RK4 loses ~1e-4 of the contact energy per step there and
takes ≥ 6 steps per contact; past it a sample is flagged ``contact_step_too_large``."""

FRICTION_V0 = 1e-4
"""Tangential speed (m/s) below which the regularised Coulomb friction is zero (Ambrósio's
``v0``). Chosen here, not taken from a paper: well under the sliding speeds of a journal."""
FRICTION_V1 = 1e-3
"""Tangential speed (m/s) above which the regularised Coulomb friction is fully developed
(Ambrósio's ``v1``); between ``v0`` and ``v1`` it ramps linearly. Chosen here."""


def material_compliance(youngs_modulus: float, poisson_ratio: float) -> float:
    """σ = (1 − ν²) / E (1/Pa) of one body's material."""
    return (1.0 - poisson_ratio**2) / youngs_modulus


def internal_cylinder_stiffness(
    radius: float,
    clearance: float,
    youngs_modulus: float,
    poisson_ratio: float,
    bearing_youngs_modulus: float | None = None,
    bearing_poisson_ratio: float | None = None,
) -> float:
    """Generalised stiffness K (N/m^1.5) of a journal of radius R_i in a bearing of radius
    R_j = R_i + c, for the law with exponent m = 1.5:

        K = 4 / (3 (σ_i + σ_j)) · (R_i R_j / (R_j − R_i))^½,   σ_k = (1 − ν_k²) / E_k.

    This is the Hertz sphere formula with the relative radius of two conforming surfaces
    (concave bearing), as used for revolute clearance joints by Lankarani & Nikravesh (1990,
    J. Mech. Des. 112, 369–376, with h_k = σ_k / π), Flores & Ambrósio (2004, Comput. Struct.
    82, 1359–1369) and Flores, Ambrósio, Claro & Lankarani (2008, *Kinematics and Dynamics of
    Multibody Systems with Imperfect Joints*, Springer). Pereira, Ramalho & Ambrósio (2011,
    Nonlinear Dyn. 63, 681–697) review it against cylinder-specific laws: it is the usual
    choice in the field, not an exact line-contact result, and it stiffens without bound as
    c → 0.

    Args:
        radius: R_i, the journal radius, m.
        clearance: c = R_j − R_i > 0, m.
        youngs_modulus, poisson_ratio: the journal's E_i (Pa) and ν_i.
        bearing_youngs_modulus, bearing_poisson_ratio: the bearing's E_j, ν_j; default: the
            journal's material.

    Raises:
        ValueError: a non-positive radius, clearance or modulus, or ν outside (−1, 0.5].
    """
    e_j = youngs_modulus if bearing_youngs_modulus is None else bearing_youngs_modulus
    nu_j = poisson_ratio if bearing_poisson_ratio is None else bearing_poisson_ratio
    for name, value in (
        ("radius", radius),
        ("clearance", clearance),
        ("youngs_modulus", youngs_modulus),
        ("bearing_youngs_modulus", e_j),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"`{name}` must be a positive number, got {value!r}.")
    for name, value in (("poisson_ratio", poisson_ratio), ("bearing_poisson_ratio", nu_j)):
        if not (-1.0 < value <= 0.5):
            raise ValueError(f"`{name}` must lie in (-1, 0.5], got {value!r}.")
    r_i = radius
    r_j = radius + clearance
    sigma = material_compliance(youngs_modulus, poisson_ratio) + material_compliance(e_j, nu_j)
    # R_j − R_i is the clearance itself: no cancellation for c ≪ R.
    return 4.0 / (3.0 * sigma) * math.sqrt(r_i * r_j / clearance)
