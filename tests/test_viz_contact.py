"""Report and playback of clearance joints with a contact law, on a synthetic ensemble.

The two-bar ensemble of ``test_viz_synthetic`` with joint O under ``model = "auto"``: its
journal is given a prescribed orbit d = c ρ(t) (cos φ, sin φ) — ρ = 1 while the link holds,
ρ = 1 + PRESS in contact, ρ < 1 in free flight — and the contact outputs (``contact_mode``,
``penetration``, ``peak_contact_force``, ``impact_count``, ...) that go with it. No numba
compile: the orbit the viewers draw is checked against that closed form.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import xarray as xr
from test_viz_playback import read_rrd
from test_viz_report import assert_real_picture, assert_texts_inside
from test_viz_synthetic import _rot, make_dataset, make_model

from mcchain.contact import AUTO
from mcchain.ensemble import queries
from mcchain.model import Model
from mcchain.status import CONTACT_STEP_TOO_LARGE
from mcchain.viz import contact, history, report, report_contact, scatter, show

HALF = 0.5  # m, half length of the synthetic bars (test_viz_synthetic.HALF)
PRESS = 0.02  # ρ − 1 in contact: a penetration of 2 % of the clearance
T_SEPARATE = 0.2  # s, sample s leaves the link at T_SEPARATE + 0.05 (s mod 3)
FAILED_SAMPLE = 3  # its contact_mode is -1 at O from FAIL_TIME on (contact_step_too_large)
FAIL_TIME = 0.6  # s
NSAMPLE, NTIME, DT = 12, 40, 0.025
ORBIT_ATOL = 1e-9  # d / c from float64 q of ~1 m over c >= 1e-4 m: round-off ~1e-12
RRD_ATOL = 1e-6  # rerun stores positions as float32; |d / c| <= 1.02
PARAM_PATHS = ("joint.O.clearance", "joint.O.contact.restitution")


def orbit_closed_form(ntime: int = NTIME, nsample: int = NSAMPLE) -> dict[str, np.ndarray]:
    """The prescribed orbit: time (T,), radius ratio ρ (n, T), angle φ (n, T), mode (n, T)."""
    t = np.arange(ntime) * DT
    s = np.arange(nsample)[:, None]
    separated = t >= separation_times(nsample)[:, None]
    flying = np.sin(20.0 * t + s) > 0.3
    mode = np.where(separated, np.where(flying, contact.FREE, contact.CONTACT), contact.LINK)
    rho = np.where(mode == contact.FREE, 0.6 + 0.3 * np.sin(7.0 * t + s), 1.0)
    rho = np.where(mode == contact.CONTACT, 1.0 + PRESS, rho)
    phi = -np.pi / 2 + 0.8 * np.sin(3.0 * t + 0.5 * s)
    if nsample > FAILED_SAMPLE:
        mode[FAILED_SAMPLE, t >= FAIL_TIME] = -1
    return {"time": t, "rho": rho, "phi": phi, "mode": mode.astype(np.int8)}


def separation_times(nsample: int) -> np.ndarray:
    """(n,) s: when each sample leaves the link (see :func:`orbit_closed_form`)."""
    return T_SEPARATE + 0.05 * (np.arange(nsample) % 3)


def make_contact_params(n: int = NSAMPLE, seed: int = 3) -> np.ndarray:
    """(n, 2): clearance of O in [1e-4, 1e-3] m and its restitution in [0.5, 0.99]."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(1e-4, 1e-3, n), rng.uniform(0.5, 0.99, n)])


def make_contact_dataset(params: np.ndarray, ntime: int = NTIME) -> xr.Dataset:
    """The synthetic ensemble with O under a contact law (see the module docstring)."""
    n = len(params)
    c, e = params[:, 0], params[:, 1]
    ds = make_dataset(np.column_stack([c, np.full(n, 2.0)]), ntime, DT, history_dtype=np.float64)
    ds = ds.assign_coords(param=list(PARAM_PATHS))
    ds["parameters"].values[:] = params
    orbit = orbit_closed_form(ntime, n)
    rho, phi, mode = orbit["rho"], orbit["phi"], orbit["mode"]
    d = (c[:, None] * rho)[..., None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    q = ds["q"].values.copy()
    q[:, :, 0, :2] = d - _rot(q[:, :, 0, 2], (-HALF, 0.0))  # bearing of O at the origin
    ds["q"] = (("sample", "time", "body", "dof"), q)
    law_force = np.where(mode == contact.CONTACT, 50.0 * (1.0 + np.arange(n))[:, None], 0.0)
    cf = ds["contact_force"].values.copy()
    cf[:, :, 0] = np.where(mode == contact.LINK, np.abs(cf[:, :, 0]), law_force)
    ds["contact_force"] = (("sample", "time", "joint"), cf)
    penetration = np.full((n, ntime, 2), np.nan)
    penetration[:, :, 0] = np.where(mode < 0, np.nan, c[:, None] * (rho - 1.0))
    modes = np.full((n, ntime, 2), -1, dtype=np.int8)
    modes[:, :, 0] = mode
    status = np.zeros(n, dtype=np.uint32)
    if n > FAILED_SAMPLE:
        status[FAILED_SAMPLE] = CONTACT_STEP_TOO_LARGE

    def per_joint(values: np.ndarray, other: float) -> np.ndarray:
        out = np.full((n, 2), other, dtype=values.dtype)
        out[:, 0] = values
        return out

    impacts = np.round(3.0 + 60.0 * e**8).astype(np.int32)
    ds = ds.assign(
        penetration=(("sample", "time", "joint"), penetration),
        contact_mode=(("sample", "time", "joint"), modes),
        peak_contact_force=(("sample", "joint"), per_joint(300.0 * np.sqrt(c / 1e-4), np.nan)),
        impact_count=(("sample", "joint"), per_joint(impacts, -1)),
        max_penetration=(("sample", "joint"), per_joint(PRESS * c, np.nan)),
        first_separation_time=(("sample", "joint"), per_joint(separation_times(n), np.nan)),
        contact_lost_time=(("sample",), np.full(n, np.nan)),
        status=(("sample",), status),
    )
    return ds


def make_contact_model(params: np.ndarray) -> Model:
    """The two-bar model with O under ``model = "auto"``."""
    model = make_model(np.column_stack([params[:, 0], np.full(len(params), 2.0)]))
    return replace(
        model,
        param_paths=PARAM_PATHS,
        joint_model=np.array([AUTO, 0], dtype=np.int64),
        joint_contact_restitution=np.column_stack([params[:, 1], np.ones(len(params))]),
    )


@pytest.fixture(scope="module")
def contact_run() -> tuple[xr.Dataset, Model, np.ndarray]:
    params = make_contact_params()
    return make_contact_dataset(params), make_contact_model(params), params


def _titles(fig: Any) -> list[str]:
    return [ax.get_title() for ax in fig.axes if ax.get_visible()]


# -- queries and labels ---------------------------------------------------------------------------
def test_param_axis__key_item_and_display_units() -> None:
    small, large = np.array([5e-5, 2e-4]), np.array([0.2, 0.3])
    assert scatter.param_axis("joint.B.clearance", small) == ("clearance B [mm]", 1e3)
    assert scatter.param_axis("joint.B.clearance", large) == ("clearance B [m]", 1.0)
    assert scatter.param_axis("joint.B.contact.restitution", small) == (
        "restitution B [-]",
        1.0,
    )
    assert scatter.param_axis("body.bar.mass", large) == ("mass bar [kg]", 1.0)
    assert scatter.param_axis("scene.gravity[1]", large) == ("gravity[1] [m/s²]", 1.0)
    assert scatter.param_axis("joint.B.points[1][0]", large)[0] == "points[1][0] B [m]"


def test_largest__finite_values_largest_first() -> None:
    values = np.array([3.0, np.nan, 7.0, 3.0, -1.0])
    np.testing.assert_array_equal(queries.largest(values, 3), [2, 0, 3])
    np.testing.assert_array_equal(queries.largest(values, 10), [2, 0, 3, 4])
    assert len(queries.largest(np.full(3, np.nan), 2)) == 0


def test_joint_states__mode_failure_and_invalid_link() -> None:
    time = np.array([0.0, 0.1, 0.2, 0.3])
    mode = np.array([[0, -1], [1, -1], [2, -1], [-1, -1]])
    law = np.array([True, False])
    states = contact.joint_states(mode, law, time, lost_time=0.2)
    expected = [
        [contact.LINK, contact.LINK],
        [contact.CONTACT, contact.LINK],
        [contact.FREE, contact.LINK_LOST],
        [contact.FAILED, contact.LINK_LOST],
    ]
    np.testing.assert_array_equal(states, expected)


def test_joint_models__from_the_model_or_the_data(contact_run: Any) -> None:
    ds, model, _ = contact_run
    assert contact.joint_models(ds, model) == ["auto", None]
    assert contact.joint_models(ds) == ["contact law", None]
    link_only = make_dataset(make_contact_params(4))
    assert contact.joint_models(link_only) == ["link", None]


def test_peak_contact_forces__law_variable_or_tracked_peak_of_lambda(contact_run: Any) -> None:
    ds, _, params = contact_run
    labels, peaks, joints = report_contact.peak_contact_forces(ds, ["auto", None])
    assert (labels, joints) == (["peak F_n O"], [0])
    np.testing.assert_array_equal(peaks[:, 0], 300.0 * np.sqrt(params[:, 0] / 1e-4))
    link_only = make_dataset(make_contact_params(4))
    labels, peaks, _ = report_contact.peak_contact_forces(link_only, ["link", None])
    assert labels == ["peak |λ O|"]  # the link's peak |λ|, tracked at every step
    np.testing.assert_array_equal(peaks[:, 0], link_only["peak_joint_force"].values[:, 0])
    older = link_only.drop_vars("peak_joint_force")  # a run from before the tracked peaks
    labels, peaks, _ = report_contact.peak_contact_forces(older, ["link", None])
    assert labels == ["peak |λ O| (stored points)"]
    expected = np.abs(older["contact_force"].values[:, :, 0]).max(axis=1)
    np.testing.assert_allclose(peaks[:, 0], expected, rtol=0, atol=0)


# -- report ---------------------------------------------------------------------------------------
def test_report__contact_run_writes_the_contact_figures(contact_run: Any, tmp_path: Path) -> None:
    ds, model, _ = contact_run
    result = report.make_report(ds, tmp_path, design="random", model=model)
    written = {p.name for p in result.written}
    assert {
        "scatter_peak_contact_force.png",
        "scatter_impact_count.png",
        "journal_orbit.png",
        "reaction_envelopes.png",
    } <= written
    for path in result.written:
        if path.suffix == ".png":
            assert_real_picture(path)


def test_peak_force_figure__unit_axes_and_no_straight_line(contact_run: Any) -> None:
    ds, _, params = contact_run
    fig = report_contact.peak_force_figure(ds, ["auto", None])
    assert not isinstance(fig, str)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_xlabel() for ax in axes] == ["clearance O [mm]", "restitution O [-]"]
    assert {ax.get_ylabel() for ax in axes} == {"peak F_n O (auto) [N]"}
    # the points are the samples, x in mm; the line is the binned median (one point per bin)
    np.testing.assert_allclose(axes[0].collections[0].get_offsets()[:, 0], 1e3 * params[:, 0])
    trend = axes[0].lines[0]
    nbin = NSAMPLE // scatter.MIN_PER_BIN
    assert len(trend.get_xdata()) == nbin
    # peak = 300 sqrt(c / 0.1 mm) rises with c: every bin median above the one before
    assert np.all(np.diff(trend.get_ydata()) > 0)
    assert "Spearman ρ = +1.00" in [t.get_text() for t in axes[0].texts]
    assert_texts_inside(fig)


def test_impact_figure__counts_of_law_joints_only(contact_run: Any) -> None:
    ds, _, params = contact_run
    fig = report_contact.impact_figure(ds)
    assert not isinstance(fig, str)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_ylabel() for ax in axes] == ["impacts O [-]"] * 2
    expected = np.round(3.0 + 60.0 * params[:, 1] ** 8)
    np.testing.assert_array_equal(axes[1].collections[0].get_offsets()[:, 1], expected)
    no_law = make_dataset(make_contact_params(4))
    assert "no joint with a contact law" in str(report_contact.impact_figure(no_law))


def test_orbit_figure__worst_samples_at_their_closed_form_offsets(contact_run: Any) -> None:
    ds, model, params = contact_run
    fig = report_contact.orbit_figure(ds, model, ["auto", None], count=2)
    assert not isinstance(fig, str)
    assert_texts_inside(fig)
    worst = np.argsort(-params[:, 0])[:2]  # peak = 300 sqrt(c / 0.1 mm): largest c first
    orbit = orbit_closed_form()
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == 2
    for ax, s in zip(axes, worst, strict=True):
        assert ax.get_title().startswith(f"sample {s}: peak F_n O = ")
        assert f"clearance O = {1e3 * params[s, 0]:.3g} mm" in ax.get_title()
        circle, path = ax.lines[0], ax.lines[1]
        np.testing.assert_allclose(np.hypot(circle.get_xdata(), circle.get_ydata()), 1.0)
        rho, phi = orbit["rho"][s], orbit["phi"][s]
        np.testing.assert_allclose(path.get_xdata(), rho * np.cos(phi), atol=ORBIT_ATOL)
        np.testing.assert_allclose(path.get_ydata(), rho * np.sin(phi), atol=ORBIT_ATOL)
        # one scatter per state, coloured as STATE_COLORS, holding that state's times
        for points in ax.collections:
            rgb = np.round(points.get_facecolor()[0, :3] * 255).astype(int)
            code = int(np.flatnonzero((contact.STATE_COLORS == rgb).all(axis=1))[0])
            mode = np.where(orbit["mode"][s] < 0, contact.FAILED, orbit["mode"][s])
            at = mode == code
            expected = np.column_stack([rho[at] * np.cos(phi[at]), rho[at] * np.sin(phi[at])])
            np.testing.assert_allclose(points.get_offsets(), expected, atol=ORBIT_ATOL)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend[:3] == ["link", "contact", "free"] and legend[-1] == "t = 0"


def test_orbit_figure__a_known_offset_is_plotted_there(tmp_path: Path) -> None:
    """One sample, journal put at d = (0.6 c, −0.3 c) at every time: every point is there."""
    params = make_contact_params(1)
    ds = make_contact_dataset(params)
    model = make_contact_model(params)
    c = params[0, 0]
    q = ds["q"].values.copy()
    q[0, :, 0, :2] = np.array([0.6 * c, -0.3 * c]) - _rot(q[0, :, 0, 2], (-HALF, 0.0))
    ds["q"] = (("sample", "time", "body", "dof"), q)
    fig = report_contact.orbit_figure(ds, model, ["auto", None])
    assert not isinstance(fig, str)
    path = fig.axes[0].lines[1]
    np.testing.assert_allclose(path.get_xdata(), 0.6, atol=ORBIT_ATOL)
    np.testing.assert_allclose(path.get_ydata(), -0.3, atol=ORBIT_ATOL)


def test_orbit_figure__needs_the_model_and_says_so(contact_run: Any) -> None:
    ds, _, _ = contact_run
    reason = report_contact.orbit_figure(ds, None, ["auto", None])
    assert reason == (
        "the model of the samples is unknown (its scene cannot be rebuilt): no joint points"
    )


# -- reaction envelopes ---------------------------------------------------------------------------
def test_reaction_envelopes__titles_name_the_model_and_states_are_shown(contact_run: Any) -> None:
    ds, model, _ = contact_run
    fig = history.reaction_envelopes_figure(ds, contact.joint_models(ds, model))
    assert not isinstance(fig, str)
    assert_texts_inside(fig)
    titles = _titles(fig)
    assert "|f O| — contact law (auto)" in titles
    assert "|f A|" in titles
    assert "λ (link) / F_n (law) O — contact law (auto)" in titles
    state_ax = next(ax for ax in fig.axes if ax.get_title() == "state of O — contact law (auto)")
    legend = [t.get_text() for t in state_ax.get_legend().get_texts()]
    assert legend == ["link", "contact", "free", "failed"]
    # the shares the panel stacks: at every time, the fraction of samples in each state
    orbit = orbit_closed_form()
    mode = np.where(orbit["mode"] < 0, contact.FAILED, orbit["mode"])
    idx = np.arange(NTIME)
    shares = history.state_shares(ds, 0, idx, np.full(NSAMPLE, np.nan))
    for code in range(len(contact.STATES)):
        np.testing.assert_allclose(shares[code], (mode == code).mean(axis=0), rtol=0, atol=0)
    # a sample that lost contact at t = 0 counts as "link after contact lost" where it is a link
    lost = np.full(NSAMPLE, np.nan)
    lost[0] = 0.0
    shares = history.state_shares(ds, 0, idx, lost)
    link0 = (mode[0] == contact.LINK) / NSAMPLE
    np.testing.assert_allclose(shares[contact.LINK_LOST], link0, rtol=0, atol=1e-15)


def test_reaction_envelopes__link_samples_left_out_after_contact_lost() -> None:
    """Sample 1 of the synthetic link run loses contact: from its contact_lost_time on, the
    envelopes are those of the other samples, and the times are shaded."""
    ds = make_dataset(make_contact_params(4), history_dtype=np.float64)
    t_lost = float(ds["contact_lost_time"].values[1])
    assert np.isfinite(t_lost) and np.isnan(np.delete(ds["contact_lost_time"].values, 1)).all()
    fig = history.reaction_envelopes_figure(ds)
    assert not isinstance(fig, str)
    ax = next(ax for ax in fig.axes if ax.get_title() == "λ O — link")
    median = ax.lines[0].get_ydata()
    lam = ds["contact_force"].values[:, :, 0].copy()
    time = ds["time"].values
    lam[1, time >= t_lost] = np.nan
    np.testing.assert_allclose(median, np.nanmedian(lam, axis=0), rtol=1e-12)
    assert "samples left out (contact_lost)" in [t.get_text() for t in ax.get_legend().texts]
    assert "1 samples lost contact under the link model" in fig.get_suptitle()


def test_contact_loss__first_separations_against_the_sampled_parameters(
    contact_run: Any,
) -> None:
    ds, _, params = contact_run
    fig = history.contact_loss_figure(ds)
    assert not isinstance(fig, str)
    share_ax, clearance_ax, restitution_ax = (ax for ax in fig.axes if ax.get_visible())
    title = " ".join(fig.get_suptitle().split())
    assert title.startswith(f"contact loss: {NSAMPLE} of {NSAMPLE} samples: first separation")
    assert "contact_lost (link model)" not in title  # no sample lost contact under the link
    (separated,) = share_ax.lines
    assert separated.get_label() == "first separation (contact law)"
    time, expected = ds["time"].values, separation_times(NSAMPLE)
    share = (time[:, None] >= expected[None, :]).mean(axis=1)
    np.testing.assert_allclose(separated.get_ydata(), 100.0 * share)
    assert clearance_ax.get_xlabel() == "clearance O [mm]"
    assert restitution_ax.get_xlabel() == "restitution O [-]"
    assert clearance_ax.get_ylabel() == "time of loss [s]"
    points = clearance_ax.collections[0].get_offsets()
    np.testing.assert_allclose(points[:, 0], 1e3 * params[:, 0])
    np.testing.assert_allclose(points[:, 1], expected)
    assert_texts_inside(fig)


# -- show -----------------------------------------------------------------------------------------
def test_show__orbit_entity_holds_d_over_c_coloured_by_state(
    contact_run: Any, tmp_path: Path
) -> None:
    ds, model, _ = contact_run
    out = tmp_path / "orbit.rrd"
    show.show(ds, model, [0, FAILED_SAMPLE], save=out)
    rrd = read_rrd(out)
    orbit = orbit_closed_form()
    for s in (0, FAILED_SAMPLE):
        journal = rrd[f"/sample/{s}/orbit/O/journal"]
        positions = np.array([row[0] for row in journal["Points2D:positions"]])
        rho, phi = orbit["rho"][s], orbit["phi"][s]
        # the view draws y negated, as the mechanism view does
        expected = np.column_stack([rho * np.cos(phi), -rho * np.sin(phi)])
        np.testing.assert_allclose(positions, expected, atol=RRD_ATOL)
        mode = np.where(orbit["mode"][s] < 0, contact.FAILED, orbit["mode"][s])
        packed = np.array([row[0] for row in journal["Points2D:colors"]], dtype=np.uint64)
        rgb = np.stack([(packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255], -1)
        np.testing.assert_array_equal(rgb, contact.STATE_COLORS[mode])
        path = rrd[f"/sample/{s}/orbit/O/path"]["static"]
        np.testing.assert_allclose(np.array(path["Points2D:positions"]), expected, atol=RRD_ATOL)
        circle = np.array(rrd[f"/sample/{s}/orbit/O/circle"]["static"]["LineStrips2D:strips"][0])
        np.testing.assert_allclose(np.hypot(circle[:, 0], circle[:, 1]), 1.0, atol=RRD_ATOL)
    assert "/sample/0/orbit/A/journal" not in rrd  # the ideal joint has no orbit
