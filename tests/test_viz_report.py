"""``mcchain report``: every PNG from a run folder, and Sobol indices on an analytic case."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
import xarray as xr
from PIL import Image
from SALib.sample import sobol as salib_sobol
from scipy.stats import qmc, spearmanr
from test_viz_synthetic import SCENE_TEXT, make_dataset, pulsations, random_params

from mcchain import cli
from mcchain.ensemble import queries
from mcchain.scene import compile_model, load_scene_text
from mcchain.testing.factory import clearance_bar_text
from mcchain.viz import report, scatter

if TYPE_CHECKING:
    from matplotlib.figure import Figure

SALTELLI_ATOL = 0.01  # Saltelli/Jansen estimators on 2^11 scrambled-Sobol base points: observed
#                       error <= 0.004 against the quadrature for this smooth 2-input model
ISHIGAMI_ATOL = 0.03  # the scene's "saltelli" design, 2^12 base points, Ishigami (a=7, b=0.1):
#                       observed error <= 0.015 against the analytic indices over seeds 0-4
RBD_FAST_ATOL = 0.03  # RBD-FAST (M = 10 harmonics) on 2^12 given points, for the near-linear ω0
QUADRATURE_NODES = 96  # Gauss-Legendre nodes per input: the direct estimate is exact to ~1e-12

CLEARANCE = (1e-3, 0.3)  # m: wide enough that c moves the pendulum pulsation, not only rolling
MASS = (1.0, 3.0)  # kg
PROBLEM: dict[str, Any] = {
    "num_vars": 2,
    "names": ["joint.O.clearance", "body.bar.mass"],
    "bounds": [CLEARANCE, MASS],
}

EVERY_PNG = {
    "omega_histogram.png",
    "scatter_omega.png",
    "scatter_q_eq.png",
    "scatter_joint_force_eq.png",
    "scatter_peak_contact_force.png",
    "reaction_envelopes.png",
    "contact_loss.png",
    "status_counts.png",
    "sobol.png",
}


def assert_real_picture(path: Path, min_size: tuple[int, int] = (300, 200)) -> None:
    """A PNG of a reasonable size that is not blank: its pixels vary, and not only a few."""
    with Image.open(path) as img:
        assert img.format == "PNG"
        assert img.size[0] >= min_size[0] and img.size[1] >= min_size[1], img.size
        pixels = np.asarray(img.convert("RGB"), dtype=np.float64)
    assert pixels.var() > 0.0, f"{path.name} is blank"
    background = (pixels == pixels[0, 0]).all(axis=-1).mean()
    assert background < 0.995, f"{path.name} is {background:.1%} background"


def assert_texts_inside(fig: Figure) -> None:
    """Every title, axis label and text of ``fig`` lies inside the figure once drawn (nothing
    cut off at an edge)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    width, height = fig.bbox.width, fig.bbox.height
    texts = [fig._suptitle] if fig._suptitle is not None else []
    for ax in fig.axes:
        if ax.get_visible():
            texts += [ax.title, ax.xaxis.label, ax.yaxis.label, *ax.texts]
    for text in texts:
        if not text.get_text():
            continue
        box = text.get_window_extent(renderer)
        inside = box.x0 >= -1 and box.x1 <= width + 1 and box.y0 >= -1 and box.y1 <= height + 1
        assert inside, f"{text.get_text()!r} is cut off: {box} in {width} x {height}"


def make_run(folder: Path, params: np.ndarray, design: str, **kwargs: object) -> Path:
    """A run folder as ``mcchain run`` leaves it (ensemble.nc, scene.toml, run.json)."""
    folder.mkdir(parents=True)
    make_dataset(params, design=design, **kwargs).to_netcdf(folder / "ensemble.nc")  # type: ignore[arg-type]
    (folder / "scene.toml").write_text(SCENE_TEXT.format(count=len(params), design=design))
    (folder / "run.json").write_text("{}")
    return folder


# -- every figure ---------------------------------------------------------------------------------
def test_report__writes_every_png_from_a_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 16 base points in Saltelli's layout (2 inputs, second order: 6 rows each)
    params = salib_sobol.sample(
        {"num_vars": 2, "names": ["c", "m"], "bounds": [[1e-4, 1e-3], [1.5, 2.5]]}, 16, seed=5
    )
    run = make_run(tmp_path / "run", params, "sobol", ntime=30)
    assert cli.main(["report", str(run)]) == 0
    out = run / "report"
    assert {p.name for p in out.glob("*.png")} == EVERY_PNG
    for name in sorted(EVERY_PNG):
        assert_real_picture(out / name)
    printed = capsys.readouterr().out
    assert str(out / "sobol.png") in printed
    # sample 2's equilibrium failed: ω and |f| have a NaN in the Saltelli rows, so only the
    # peak contact force is analysed, and the others say why
    with open(out / "sobol.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["output"] for r in rows} == {"peak |λ O|"}
    assert {r["method"] for r in rows} == {"sobol"}
    assert "skipped sobol ω0: 1 samples have no finite value" in printed


def test_report__skips_what_the_run_lacks_and_says_why(tmp_path: Path) -> None:
    ds = make_dataset(random_params(20), history=False)
    ds = ds.drop_vars(["omega"]).drop_dims("mode")
    result = report.make_report(ds, tmp_path / "out", design="random")
    assert {p.name for p in result.written} == {
        "scatter_q_eq.png",
        "scatter_joint_force_eq.png",
        "status_counts.png",
        "status_counts.svg",  # a vector copy for the page (figures.VECTOR_FIGURES)
    }
    assert set(result.skipped) == {
        "omega_histogram.png",
        "modes_along_cycle.png",
        "scatter_impact_count.png",
        "journal_orbit.png",
        "reaction_envelopes.png",
        "contact_loss.png",
        "sobol.png",
        "requirements.png",
    }
    assert "[simulate]" in result.skipped["reaction_envelopes.png"]
    assert result.skipped["sobol.png"] == (
        'the sample design is \'random\', not "saltelli" or "sobol"'
    )
    for path in result.written:
        if path.suffix == ".png":
            assert_real_picture(path)


def test_run_design__from_the_settings_the_scene_attribute_or_the_scene_copy(
    tmp_path: Path,
) -> None:
    run = make_run(tmp_path / "run", random_params(4), "lhs", history=False)
    assert queries.run_design(run) == "lhs"
    elsewhere = tmp_path / "elsewhere"
    ds = xr.Dataset(attrs={"scene": SCENE_TEXT.format(count=4, design="sobol")})
    assert queries.run_design(elsewhere, ds) == "sobol"
    assert queries.run_design(elsewhere, xr.Dataset(attrs={"scene": "[scene]"})) is None
    # the resolved settings the ensemble stores come first (its scene text is the same)
    settings = '{"scene": {"sample": {"design": "saltelli"}}, "samples": 4, "seed": 7}'
    assert queries.run_design(run, ds.assign_attrs(settings=settings)) == "saltelli"
    no_sample = '{"scene": {"sample": null}, "samples": 1, "seed": null}'
    assert queries.run_design(run, ds.assign_attrs(settings=no_sample)) is None


# -- Sobol indices ---------------------------------------------------------------------------------
def direct_indices(mode: int) -> tuple[np.ndarray, np.ndarray]:
    """S1 and ST of (c, m) for pulsation ``mode`` of the clearance bar, by the double loop
    Var_c(E_m[Y | c]) / Var(Y) and E_m[Var_c(Y | m)] / Var(Y) over a tensor Gauss-Legendre
    grid of the two uniform inputs."""
    x, w = np.polynomial.legendre.leggauss(QUADRATURE_NODES)
    w = w / w.sum()
    c = CLEARANCE[0] + (x + 1) / 2 * (CLEARANCE[1] - CLEARANCE[0])
    m = MASS[0] + (x + 1) / 2 * (MASS[1] - MASS[0])
    y = pulsations(c[:, None], m[None, :])[..., mode]  # y[i, j] = Y(c_i, m_j)
    mean = w @ y @ w
    var = w @ (y - mean) ** 2 @ w
    given_c, given_m = y @ w, w @ y  # E[Y | c_i], E[Y | m_j]
    s1 = np.array([w @ (given_c - mean) ** 2, w @ (given_m - mean) ** 2]) / var
    st = np.array([w @ ((y - given_m) ** 2).T @ w, w @ ((y - given_c[:, None]) ** 2) @ w]) / var
    return s1, st


def _read_csv(path: Path) -> dict[str, dict[str, np.ndarray]]:
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    out: dict[str, dict[str, np.ndarray]] = {}
    for output in dict.fromkeys(r["output"] for r in rows):
        mine = [r for r in rows if r["output"] == output]
        assert [r["parameter"] for r in mine] == PROBLEM["names"]
        out[output] = {k: np.array([float(r[k]) for r in mine]) for k in ("S1", "ST")}
        out[output]["method"] = np.array([r["method"] for r in mine])
    return out


def _pulsation_dataset(params: np.ndarray) -> xr.Dataset:
    omega = pulsations(params[:, 0], params[:, 1])
    return xr.Dataset(
        {
            "parameters": (("sample", "param"), params),
            "omega": (("sample", "mode"), omega),
        },
        coords={"sample": np.arange(len(params)), "param": PROBLEM["names"], "mode": [0, 1]},
    )


def test_sobol__clearance_bar_pulsations_agree_with_a_direct_estimate(tmp_path: Path) -> None:
    params = salib_sobol.sample(PROBLEM, 2**11, calc_second_order=True, seed=3)
    ds = _pulsation_dataset(params)
    produced = report.sobol_figure(ds, "sobol", tmp_path / "sobol.png", tmp_path / "sobol.csv")
    assert produced == tmp_path / "sobol.png"
    assert_real_picture(produced)
    found = _read_csv(tmp_path / "sobol.csv")
    for mode in (0, 1):
        s1, st = direct_indices(mode)
        got = found[f"ω{mode}"]
        assert set(got["method"]) == {"sobol"}
        np.testing.assert_allclose(got["S1"], s1, atol=SALTELLI_ATOL, err_msg=f"S1 of ω{mode}")
        np.testing.assert_allclose(got["ST"], st, atol=SALTELLI_ATOL, err_msg=f"ST of ω{mode}")
    # the analytic picture: the pendulum (ω0) depends on both, the rolling mode (ω1) on c
    s1_pendulum, _ = direct_indices(0)
    assert s1_pendulum.min() > 0.3
    assert direct_indices(1)[0][0] > 0.9


def test_sobol__plain_sobol_points_give_first_order_by_rbd_fast() -> None:
    """The scene's "sobol" design draws plain scrambled Sobol' points (no Saltelli rows)."""
    u = qmc.Sobol(2, scramble=True, rng=np.random.default_rng(1)).random(2**12)
    params = np.column_stack(
        [CLEARANCE[0] + u[:, 0] * np.ptp(CLEARANCE), MASS[0] + u[:, 1] * np.ptp(MASS)]
    )
    assert report.saltelli_layout(params) is None
    y = pulsations(params[:, 0], params[:, 1])[:, 0]
    result = report.sobol_indices(params, {"ω0": y}, ["joint.O.clearance", "body.bar.mass"])
    assert not isinstance(result, str), result
    (found,) = result
    assert found.method == "rbd_fast" and np.isnan(found.ST).all()
    np.testing.assert_allclose(found.S1, direct_indices(0)[0], atol=RBD_FAST_ATOL)


def test_saltelli_layout__recognises_salib_samples_only() -> None:
    for second in (True, False):
        params = salib_sobol.sample(PROBLEM, 8, calc_second_order=second, seed=1)
        assert report.saltelli_layout(params) == (8, second)
        shuffled = params[np.random.default_rng(0).permutation(len(params))]
        assert report.saltelli_layout(shuffled) is None
    assert report.saltelli_layout(np.random.default_rng(0).random((48, 2))) is None
    assert report.saltelli_layout(np.zeros((0, 2))) is None


# -- the scene's "saltelli" design --------------------------------------------------------------
def saltelli_scene_parameters(count: int, vary: dict[str, tuple[float, float]]) -> np.ndarray:
    """The parameters the scene's ``design = "saltelli"`` draws on the clearance bar."""
    lines = [f'"{path}" = {{ uniform = [{lo!r}, {hi!r}] }}' for path, (lo, hi) in vary.items()]
    text = clearance_bar_text() + (
        f'\n[sample]\ncount = {count}\nseed = 3\ndesign = "saltelli"\n[sample.vary]\n'
        + "\n".join(lines)
        + "\n"
    )
    model = compile_model(load_scene_text(text))
    assert model.meta["design"] == "saltelli"
    return model.parameters


def test_sobol__saltelli_design_clearance_bar_pulsations_agree_with_a_direct_estimate(
    tmp_path: Path,
) -> None:
    # CLEARANCE reaches 0.3 m, past what the scene check allows a real joint of this bar (it
    # would be a unit mistake there), so the design is drawn on a stand-in path with the
    # same bounds: the scene's draws depend on the design and the bounds, not on the path.
    stand_ins = ["body.bar.position[0]", "body.bar.mass"]
    params = saltelli_scene_parameters(
        4 * 2**11, dict(zip(stand_ins, PROBLEM["bounds"], strict=True))
    )
    assert report.saltelli_layout(params, second_order=False) == (2**11, False)
    produced = report.sobol_figure(
        _pulsation_dataset(params), "saltelli", tmp_path / "sobol.png", tmp_path / "sobol.csv"
    )
    assert produced == tmp_path / "sobol.png"
    assert_real_picture(produced)
    found = _read_csv(tmp_path / "sobol.csv")
    for mode in (0, 1):
        s1, st = direct_indices(mode)
        got = found[f"ω{mode}"]
        assert set(got["method"]) == {"sobol"}
        np.testing.assert_allclose(got["S1"], s1, atol=SALTELLI_ATOL, err_msg=f"S1 of ω{mode}")
        np.testing.assert_allclose(got["ST"], st, atol=SALTELLI_ATOL, err_msg=f"ST of ω{mode}")


def ishigami_indices(a: float = 7.0, b: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Analytic S1 and ST of sin x1 + a sin² x2 + b x3⁴ sin x1, x_i uniform on [-π, π]."""
    v1 = 0.5 * (1 + b * np.pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * np.pi**8 * (1 / 18 - 1 / 50)
    var = v1 + v2 + v13
    return np.array([v1, v2, 0.0]) / var, np.array([v1 + v13, v2, v13]) / var


def test_sobol__saltelli_design_ishigami_agrees_with_the_analytic_indices() -> None:
    paths = ["body.bar.position[0]", "body.bar.position[1]", "body.bar.angle"]
    x = saltelli_scene_parameters(5 * 2**12, dict.fromkeys(paths, (-np.pi, np.pi)))
    y = np.sin(x[:, 0]) + 7.0 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])
    result = report.sobol_indices(x, {"ishigami": y}, paths, design="saltelli")
    assert not isinstance(result, str), result
    (found,) = result
    s1, st = ishigami_indices()
    assert found.method == "sobol"
    np.testing.assert_allclose(found.S1, s1, atol=ISHIGAMI_ATOL)
    np.testing.assert_allclose(found.ST, st, atol=ISHIGAMI_ATOL)


def test_sobol__saltelli_design_needs_its_layout() -> None:
    names = ["joint.O.clearance", "body.bar.mass"]
    bounds = [(1e-4, 1e-3), (1.0, 3.0)]
    params = saltelli_scene_parameters(4 * 16, dict(zip(names, bounds, strict=True)))
    assert report.saltelli_layout(params) == (16, False)
    result = report.sobol_indices(params, {"ω0": pulsations(*params.T)[:, 0]}, names, "saltelli")
    assert not isinstance(result, str), result
    assert result[0].method == "sobol" and np.isfinite(result[0].ST).all()
    # SALib's second-order rows are not the "saltelli" design's, nor are rows out of step
    second = salib_sobol.sample(PROBLEM, 16, calc_second_order=True, seed=1)
    assert report.saltelli_layout(second, second_order=False) is None
    for bad in (second, np.roll(params, 1, axis=0)):
        y = pulsations(*bad.T)[:, 0]
        reason = report.sobol_indices(bad, {"ω0": y}, names, design="saltelli")
        assert isinstance(reason, str) and 'design "saltelli" without its layout' in reason


def test_omega_histogram__labels_hz_and_overlays_damped_pulsations() -> None:
    """Each panel: a title with the mean in rad/s and in Hz (÷ 2π), a top axis in Hz, and,
    with dampers (damped_omega ≠ omega), a second histogram of the damped pulsations."""
    omega = np.array([[2 * np.pi, 20.0], [2 * np.pi, 22.0]])
    ds = xr.Dataset(
        {"omega": (("sample", "mode"), omega), "damped_omega": (("sample", "mode"), 0.9 * omega)},
        coords={"sample": [0, 1], "mode": [0, 1]},
    )
    fig = report.omega_histogram_figure(ds)
    assert_texts_inside(fig)
    first = fig.axes[0]
    assert " ".join(first.get_title().split()) == "ω0: mean 6.283 rad/s (1 Hz), sd 0 (0 Hz)"
    assert [c.get_xlabel() for c in first.child_axes] == ["Hz"]
    assert [t.get_text() for t in first.get_legend().get_texts()] == ["undamped ω", "damped |Im s|"]
    undamped = ds.assign(damped_omega=ds["omega"])
    assert report.omega_histogram_figure(undamped).axes[0].get_legend() is None


# -- scatter against the parameters ----------------------------------------------------------------
def _clearance_mass_dataset(n: int) -> tuple[xr.Dataset, np.ndarray]:
    rng = np.random.default_rng(11)
    params = np.column_stack([rng.uniform(1e-4, 1e-3, n), rng.uniform(1.5, 2.5, n)])
    ds = xr.Dataset(
        {"parameters": (("sample", "param"), params)},
        coords={"sample": np.arange(n), "param": PROBLEM["names"]},
    )
    return ds, params


def test_scatter__a_nonlinear_relation_gets_binned_medians_not_a_straight_line() -> None:
    n = 400
    ds, params = _clearance_mass_dataset(n)
    bowl = 10.0 + 1e7 * (params[:, 0] - 5.5e-4) ** 2  # not monotone: Pearson r would say ~0
    values = np.column_stack([bowl, np.full(n, 7.0)])
    fig = report.scatter_figure(ds, report.Result("omega", ("ω0", "ω1"), values, "rad/s"))
    assert not isinstance(fig, str)
    clearance_ax, mass_ax = fig.axes
    assert [clearance_ax.get_xlabel(), mass_ax.get_xlabel()] == [
        "clearance O [mm]",
        "mass bar [kg]",
    ]
    assert clearance_ax.get_ylabel() == "ω0 [rad/s]"
    assert [c.get_ylabel() for c in mass_ax.child_axes] == ["Hz"]
    # the red line: the median of each of 10 bins of 40 samples, sorted by clearance
    (trend,) = clearance_ax.lines
    bins = np.array_split(np.argsort(params[:, 0], kind="stable"), scatter.MAX_BINS)
    np.testing.assert_allclose(trend.get_xdata(), [1e3 * np.median(params[b, 0]) for b in bins])
    np.testing.assert_allclose(trend.get_ydata(), [np.median(bowl[b]) for b in bins])
    ends, lowest = trend.get_ydata()[[0, -1]].min() - 10.0, trend.get_ydata().min() - 10.0
    assert ends > 50.0 * lowest  # the bowl shows
    rho = spearmanr(params[:, 0], bowl).statistic
    assert f"Spearman ρ = {rho:+.2f}" in [t.get_text() for t in clearance_ax.texts]
    title = " ".join(fig.get_suptitle().split())
    assert title == (
        f"omega against the sampled parameters, {n} samples: binned median (red) and 5–95 % "
        f"band constant (not drawn): ω1 = 7 in all {n} samples"
    )
    assert_texts_inside(fig)


def test_spearman__scipys_rank_correlation_on_ties_nan_and_no_spread() -> None:
    """The report's Spearman ρ (mid-ranks' correlation, no scipy.stats) against
    scipy.stats.spearmanr over the finite pairs: random, tied, monotone, NaN-holed data;
    NaN where fewer than 3 pairs or no spread is left."""
    rng = np.random.default_rng(4)
    for n in (3, 4, 17, 400):
        for x, y in (
            (rng.normal(size=n), rng.normal(size=n)),
            (rng.integers(0, 3, n).astype(float), rng.integers(0, 4, n).astype(float)),
            (np.arange(n, dtype=float), np.exp(np.arange(n) / n)),
            (np.arange(n, dtype=float), -(np.arange(n, dtype=float) ** 3)),
        ):
            want = spearmanr(x, y).statistic
            if np.isfinite(want):
                assert scatter.spearman(x, y) == pytest.approx(want, abs=1e-14)
            holed = np.where(rng.random(n) < 0.2, np.nan, x)
            ok = np.isfinite(holed)
            if ok.sum() >= 3 and np.ptp(holed[ok]) > 0 and np.ptp(y[ok]) > 0:
                want = spearmanr(holed[ok], y[ok]).statistic
                assert scatter.spearman(holed, y) == pytest.approx(want, abs=1e-14)
    assert np.isnan(scatter.spearman(np.array([1.0, 2.0, np.nan]), np.array([3.0, 1.0, 2.0])))
    assert np.isnan(scatter.spearman(np.ones(5), np.arange(5.0)))


def test_scatter__a_constant_result_is_named_not_drawn() -> None:
    ds, _ = _clearance_mass_dataset(8)
    flat = report.Result("q_eq", ("x bar", "θ bar"), np.full((8, 2), 0.25), "m or rad")
    assert report.scatter_figure(ds, flat) == (
        "q_eq is constant: x bar = 0.25 in all 8 samples; θ bar = 0.25 in all 8 samples"
    )


def test_scatter__rounding_noise_about_zero_is_constant_against_the_results_size() -> None:
    """A coordinate at 0 ± 1e-16 m in a mechanism of 0.1 m is round-off, not a result: named
    "constant to 2e-15", not drawn (judged against the largest length of q_eq, not against
    its own 1e-16)."""
    ds, _ = _clearance_mass_dataset(8)
    noise = 1e-16 * np.sin(np.arange(8.0))  # spread 1.9e-16 m
    values = np.column_stack([0.1 + 0.01 * np.arange(8.0), noise, np.full(8, -1.5)])
    flat = report.Result(
        "q_eq", ("bar.x", "bar.y", "bar.theta"), values, "m, rad", ("m", "m", "rad")
    )
    fig = report.scatter_figure(ds, flat)
    assert not isinstance(fig, str)
    assert [ax.get_ylabel() for ax in fig.axes] == ["bar.x [m]", "bar.x [m]"]  # one row
    spread = np.ptp(noise) / 0.17  # against the largest length, 0.17 m
    title = " ".join(fig.get_suptitle().split())
    assert f"bar.y = 0 in all 8 samples (constant to {spread:.0e})" in title
    assert (
        "bar.theta = -1.5 in all 8 samples;" not in title and "bar.theta = -1.5 in all 8" in title
    )


def test_sobol__a_constant_output_is_named_with_its_value_not_given_zero_bars() -> None:
    params = salib_sobol.sample(PROBLEM, 64, calc_second_order=True, seed=3)
    n = len(params)
    flat = np.full(n, 7.0) * (1.0 + 1e-13 * np.sin(np.arange(n)))  # round-off only
    outputs = {"ω0": pulsations(*params.T)[:, 0], "ω1": flat}
    skipped: dict[str, str] = {}
    found = report.sobol_indices(params, outputs, PROBLEM["names"], skipped, "sobol")
    assert not isinstance(found, str)
    assert [s.output for s in found] == ["ω0"]
    note = f"ω1 = 7 in all {n} samples (constant to 2e-13)"  # 1e-13 sin: spread 2e-13
    assert skipped == {"sobol ω1": f"constant: {note}"}
    reason = report.sobol_indices(params, {"ω1": flat}, PROBLEM["names"], design="sobol")
    assert reason == f"no output with finite, varying values to analyse: ω1: constant: {note}"


def test_reaction_envelopes__say_they_are_stored_points_and_mark_the_peaks() -> None:
    """The bands come from the stored points (the title says so, with their spacing); each
    |f| panel marks the median and 95 % quantile of the per-sample peaks tracked at every
    step (``peak_joint_force``)."""
    from mcchain.viz.history import reaction_envelopes_figure

    ds = make_dataset(random_params(20), ntime=40, dt=0.025)
    fig = reaction_envelopes_figure(ds, ["link", None])
    assert not isinstance(fig, str)
    title = fig._suptitle.get_text()  # type: ignore[union-attr]
    assert "stored points (every 25 ms)" in title and "true per-sample peaks" in title
    peaks = ds["peak_joint_force"].values
    for k, ax in enumerate(fig.axes[:2]):  # |f O|, |f A|
        marks = sorted(line.get_ydata()[0] for line in ax.get_lines()[1:])
        np.testing.assert_allclose(marks, np.nanquantile(peaks[:, k], [0.5, 0.95]))


def test_method_rows__every_simulate_setting_in_effect_as_the_scene_writes_it() -> None:
    from mcchain.viz.report_provenance import _method

    simulate = {
        "method": "rk45",
        "t_end": 0.024,
        "dt": 1e-7,
        "output_dt": 1e-5,
        "start": "scene",
        "perturb": {},
        "rtol": 1e-7,
        "atol": 1e-10,
        "baumgarte": None,
        "rho_inf": 0.8,
        "max_newton": 20,
        "constraint_tolerance": 1e-6,
        "retry_failed": False,
        "kernels": "lanes",
    }
    ((name, row),) = _method({"simulate": simulate})
    assert name == "[simulate]"
    assert "retry_failed = false" in row and "start = scene" in row
    # what rk45 does not read, or what was left at "none", is not listed
    assert "rho_inf" not in row and "max_newton" not in row
    assert "perturb" not in row and "baumgarte" not in row
    implicit = dict(simulate, method="generalized-alpha", baumgarte=[5.0, 5.0])
    implicit["perturb"] = {"body.crank.angle": 0.01}
    ((_, row),) = _method({"simulate": implicit})
    assert "rho_inf = 0.8" in row and "max_newton = 20" in row
    assert "baumgarte = [5.0, 5.0] 1/s" in row
    assert "perturb = {&quot;body.crank.angle&quot;: 0.01}" in row
