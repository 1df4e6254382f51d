"""A synthetic ensemble for the viz tests, plus checks that it is self-consistent.

Two bars hang from the ground: ``crank`` on a clearance joint ``O`` (radial clearance c,
sampled) and ``bar`` on an ideal joint ``A`` at the crank's far end; a force ``tip`` acts at
the bar's end and a spring ``s1`` ties the bar to the ground. The dataset has the variables,
dims and coordinates of the ensemble with prescribed (not simulated) motions, so the viz code can
be tested before the solvers exist; its positions satisfy the joint constraints exactly.
Other viz tests import the builders from here.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from mcchain.model import GROUND, JOINT_CLEARANCE, JOINT_IDEAL, Model, constraint_rows
from mcchain.status import CONTACT_LOST, EQUILIBRIUM_NOT_CONVERGED, FLAG_MASKS, FLAG_MEANINGS
from mcchain.testing.closed_forms import G, clearance_bar_pulsations

HALF = 0.5  # half length l of each bar, m
J_BAR = 2.0 / 12.0  # centroidal inertia of a 1 m, 2 kg bar, kg m^2 (kept fixed when m varies)
PARAM_PATHS = ("joint.O.clearance", "body.bar.mass")

SCENE_TEXT = """\
[scene]
name = "synthetic-two-bars"

[sample]
count = {count}
seed = 7
design = "{design}"
[sample.vary]
"joint.O.clearance" = {{ uniform = [1e-4, 1e-3] }}
"body.bar.mass" = {{ uniform = [1.5, 2.5] }}
"""


def pulsations(
    c: np.ndarray | float, m: np.ndarray | float, l: float = HALF, J: float = J_BAR
) -> np.ndarray:
    """Both roots p (ascending) of the clearance bar's quartic."""
    return clearance_bar_pulsations(m, J, l, G, c)


def make_model(params: np.ndarray) -> Model:
    """The two-bar model for the sampled ``params`` (n, 2) = [clearance of O, mass of bar]."""
    params = np.asarray(params, dtype=np.float64).reshape(-1, 2)
    n = len(params)
    kind = np.array([JOINT_CLEARANCE, JOINT_IDEAL], dtype=np.int64)
    joint_row, driver_row = constraint_rows(kind, 0)
    clearance = np.zeros((n, 2))
    clearance[:, 0] = params[:, 0]
    mass = np.empty((n, 2))
    mass[:, 0], mass[:, 1] = 2.0, params[:, 1]
    q0 = np.array([[0.0, -0.5, -np.pi / 2, 0.0, -1.5, -np.pi / 2]])
    return Model(
        body_names=("crank", "bar"),
        joint_names=("O", "A"),
        driver_names=(),
        force_names=("tip",),
        spring_names=("s1",),
        param_paths=PARAM_PATHS,
        parameters=params.copy(),
        nsample=n,
        joint_body_a=np.array([GROUND, 0], dtype=np.int64),
        joint_body_b=np.array([0, 1], dtype=np.int64),
        joint_kind=kind,
        joint_row=joint_row,
        driver_body=np.zeros(0, dtype=np.int64),
        driver_row=driver_row,
        force_body=np.array([1], dtype=np.int64),
        spring_body_a=np.array([GROUND], dtype=np.int64),
        spring_body_b=np.array([1], dtype=np.int64),
        gravity=np.array([[0.0, -G]]),
        body_mass=mass,
        body_inertia=np.full((1, 2), J_BAR),
        joint_point_a=np.array([[[0.0, 0.0], [HALF, 0.0]]]),
        joint_point_b=np.array([[[-HALF, 0.0], [-HALF, 0.0]]]),
        joint_clearance=clearance,
        joint_eccentricity=np.full((1, 2), np.nan),
        driver_angle0=np.zeros((1, 0)),
        driver_omega=np.zeros((1, 0)),
        force_point=np.array([[[HALF, 0.0]]]),
        force_value=np.array([[[1.0, 0.0]]]),
        force_torque=np.zeros((1, 1)),
        spring_point_a=np.array([[[0.8, 0.0]]]),
        spring_point_b=np.array([[[0.25, 0.0]]]),
        spring_stiffness=np.full((1, 1), 100.0),
        spring_rest_length=np.full((1, 1), 1.0),
        spring_damping=np.zeros((1, 1)),
        q0=q0,
        v0=np.zeros((1, 6)),
    )


def _rot(theta: np.ndarray, s: tuple[float, float]) -> np.ndarray:
    """A(θ) s for an array of angles: (..., 2)."""
    c, sn = np.cos(theta), np.sin(theta)
    return np.stack([c * s[0] - sn * s[1], sn * s[0] + c * s[1]], axis=-1)


def make_dataset(
    params: np.ndarray,
    ntime: int = 40,
    dt: float = 0.025,
    design: str = "random",
    history: bool = True,
    history_dtype: type = np.float32,
) -> xr.Dataset:
    """An ensemble of the two-bar model with prescribed motions (see the module docstring).

    Sample 1 loses contact at O (its λ goes negative), sample 2's equilibrium did not
    converge (its q_eq, joint_force_eq and omega are NaN).
    """
    params = np.asarray(params, dtype=np.float64).reshape(-1, 2)
    n = len(params)
    c, m = params[:, 0], params[:, 1]
    s = np.arange(n)[:, None]
    t = np.arange(ntime) * dt
    amp = 0.3 + 0.05 * np.sin(s)
    th1 = -np.pi / 2 + amp * np.sin(4.0 * t)  # (n, T)
    th2 = th1 + 0.4 * np.sin(6.0 * t + s)
    d = c[:, None, None] * np.stack([np.cos(th1), np.sin(th1)], axis=-1)  # journal − bearing
    r1 = d - _rot(th1, (-HALF, 0.0))
    r2 = r1 + _rot(th1, (HALF, 0.0)) - _rot(th2, (-HALF, 0.0))
    q = np.stack(
        [np.concatenate([r1, th1[..., None]], -1), np.concatenate([r2, th2[..., None]], -1)],
        axis=2,
    )  # (n, T, body, dof)
    v = np.gradient(q, dt, axis=1)
    lam_o = (2.0 + m[:, None]) * G * (1.0 + 0.3 * np.cos(4.0 * t)) - 40.0 * (s == 1) * t
    f_o = lam_o[..., None] * -np.stack([np.cos(th1), np.sin(th1)], axis=-1)
    f_a = m[:, None, None] * G * np.stack([0.1 * np.sin(6.0 * t + s), 1.0 + 0 * t + 0 * s], -1)
    joint_force = np.stack([f_o, f_a], axis=2)  # (n, T, joint, xy)
    contact = np.stack([lam_o, np.full_like(lam_o, np.nan)], axis=2)
    lost = lam_o <= 0.0
    contact_lost_time = np.where(lost.any(axis=1), t[np.argmax(lost, axis=1)], np.nan)
    status = np.zeros(n, dtype=np.uint32)
    status[lost.any(axis=1)] |= CONTACT_LOST
    bad = np.zeros(n, dtype=bool)
    if n > 2:
        bad[2] = True
        status[2] |= EQUILIBRIUM_NOT_CONVERGED
    omega = pulsations(c, m)
    omega[bad] = np.nan
    q_eq = np.zeros((n, 2, 3))
    q_eq[:, 0] = np.stack([0 * c, -c - HALF, -np.pi / 2 + 0 * c], -1)
    q_eq[:, 1] = np.stack([0 * c, -c - 3 * HALF, -np.pi / 2 + 0 * c], -1)
    q_eq[bad] = np.nan
    jf_eq = np.zeros((n, 2, 2))
    jf_eq[:, 0, 1] = (2.0 + m) * G
    jf_eq[:, 1, 1] = m * G
    jf_eq[bad] = np.nan

    def var(dims: tuple[str, ...], values: np.ndarray, units: str, long_name: str) -> xr.Variable:
        return xr.Variable(dims, values, {"units": units, "long_name": long_name})

    data = {
        "parameters": var(("sample", "param"), params, "1", "sampled parameter values"),
        "q_eq": var(("sample", "body", "dof"), q_eq, "m or rad", "equilibrium configuration"),
        "joint_force_eq": var(
            ("sample", "joint", "xy"), jf_eq, "N", "force on body b by body a at equilibrium"
        ),
        "stable": var(("sample",), ~bad, "1", "equilibrium stability"),
        "omega": var(("sample", "mode"), omega, "rad/s", "eigenpulsations"),
        "status": xr.Variable(
            ("sample",),
            status,
            {"flag_masks": FLAG_MASKS, "flag_meanings": FLAG_MEANINGS, "long_name": "status"},
        ),
    }
    if history:
        h = history_dtype
        data |= {
            "q": var(("sample", "time", "body", "dof"), q.astype(h), "m or rad", "positions"),
            "v": var(("sample", "time", "body", "dof"), v.astype(h), "m/s or rad/s", "velocities"),
            "joint_force": var(
                ("sample", "time", "joint", "xy"), joint_force.astype(h), "N", "joint force"
            ),
            "contact_force": var(
                ("sample", "time", "joint"), contact.astype(h), "N", "λ of clearance joints"
            ),
            "constraint_error": var(
                ("sample", "time"), (1e-9 * (1 + s + 0 * t)).astype(h), "m", "max |Φ|"
            ),
            "energy": var(
                ("sample", "time"), (G * (2 + m[:, None]) * (1 + 0.01 * t)).astype(h), "J", "energy"
            ),
            "contact_lost_time": var(("sample",), contact_lost_time, "s", "first contact loss"),
            # a prescribed motion has nothing between its points: its peak is theirs
            "peak_joint_force": var(
                ("sample", "joint"),
                np.hypot(joint_force[..., 0], joint_force[..., 1]).max(axis=1),
                "N",
                "continuous peak of |joint_force|",
            ),
        }
    coords = {
        "sample": np.arange(n),
        "body": ["crank", "bar"],
        "dof": ["x", "y", "theta"],
        "joint": ["O", "A"],
        "xy": ["x", "y"],
        "mode": np.arange(2),
        "param": list(PARAM_PATHS),
    }
    if history:
        coords["time"] = xr.Variable(("time",), t, {"units": "s"})
    attrs = {"scene": SCENE_TEXT.format(count=n, design=design), "seed": 7}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def random_params(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(1e-4, 1e-3, n), rng.uniform(1.5, 2.5, n)])


# -- the fixture itself -------------------------------------------------------------------------
TIGHT = 1e-12  # float64 round-off of a few products


def test_synthetic__joints_are_satisfied() -> None:
    ds = make_dataset(random_params(4), history_dtype=np.float64)
    q = ds["q"].values
    c = ds["parameters"].values[:, 0]
    th1, th2 = q[..., 0, 2], q[..., 1, 2]
    journal_o = q[..., 0, :2] + _rot(th1, (-HALF, 0.0))
    np.testing.assert_allclose(np.linalg.norm(journal_o, axis=-1), c[:, None] + 0 * th1, atol=TIGHT)
    end_crank = q[..., 0, :2] + _rot(th1, (HALF, 0.0))
    start_bar = q[..., 1, :2] + _rot(th2, (-HALF, 0.0))
    np.testing.assert_allclose(end_crank, start_bar, atol=TIGHT)


def test_synthetic__quartic_roots() -> None:
    c, m = np.array([1e-4, 1e-2, 0.1]), np.array([1.0, 2.0, 3.0])
    p = pulsations(c, m)
    for k in range(2):
        residual = (
            c * J_BAR * p[:, k] ** 4
            - G * (m * HALF**2 + J_BAR + m * c * HALF) * p[:, k] ** 2
            + m * G**2 * HALF
        )
        assert np.all(np.abs(residual) < 1e-9 * m * G**2 * HALF * (1 + c * p[:, k] ** 4))
    # no clearance: the ideal pendulum p² = m g l / (J + m l²)
    np.testing.assert_allclose(
        pulsations(0.0, 2.0)[0], np.sqrt(2 * G * HALF / (J_BAR + 2 * HALF**2)), rtol=1e-14
    )
