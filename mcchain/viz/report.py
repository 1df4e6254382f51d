"""Plots of an ensemble as PNG files (``mcchain report RUN [--out DIR]``; the command and
its page are :mod:`mcchain.viz.report_page`, which imports this module, never the reverse).

Each figure is drawn only when the run holds what it needs; otherwise it is skipped and the
reason is logged, printed and returned (:class:`Report`). Files (in ``DIR``, default
``RUN/report``):

==============================  ==========================================================
``omega_histogram.png``         histogram of each eigenpulsation (``[modes]``), in rad/s
                                and Hz, with ``damped_omega`` overlaid if it differs
``modes_along_cycle.png``       natural frequencies along one turn of the driver of
                                ``[modes] along``, with the drive's harmonics
                                (:mod:`mcchain.viz.report_cycle`)
``scatter_<result>.png``        each result against each sampled parameter (axes named
                                ``key item [units]``), with the binned median, its 5–95 %
                                band and Spearman's ρ (:mod:`mcchain.viz.scatter`;
                                components constant over the samples are named with their
                                value, not drawn); results are ``omega`` (modes; a Hz axis
                                beside rad/s), ``q_eq`` (body, dof), ``joint_force_eq``
                                (magnitude per joint)
contact figures                 ``scatter_peak_contact_force.png``: peak normal force per
                                clearance joint against each sampled parameter;
                                ``scatter_impact_count.png``: impacts per joint with a
                                contact law; ``journal_orbit.png``: the journal in its
                                clearance circle for the worst samples (all three:
                                :mod:`mcchain.viz.report_contact`)
``reaction_envelopes.png``      per joint |f| over time (and the normal force of clearance
                                joints, driver torques): median and 5–95 % band over the
                                samples at the stored times (the title says so: peaks
                                between them are missed), the per-sample peaks tracked at
                                every step marked (median, 95 %), titled with each joint's
                                model; ``contact_lost``
                                samples left out after their ``contact_lost_time``
                                (:mod:`mcchain.viz.history`)
``contact_loss.png``            which samples lost contact, and when
                                (``contact_lost_time``): the fraction lost by time t, and
                                the time of loss against each sampled parameter
``status_counts.png/.svg``      how many samples carry each status flag
``requirements.png/.svg``       per ``[[requirement]]``: the output's exceedance curve with
                                its band, limit and target; P(fail) against each sampled
                                parameter on a log axis (zero-failure bins as upper
                                bounds) with the allocated bound
                                (:mod:`mcchain.viz.report_requirements`)
``index.html``                  the page that carries every figure: the answer first, then
                                the evidence, model form, ensemble and provenance
                                (:mod:`mcchain.viz.report_page`; ``mcchain report RUN`` only)
``sobol.png``, ``sobol.csv``    Sobol indices (SALib) of ω, |joint_force_eq| and the peak
                                contact force (an output constant over the samples is named
                                with its value instead of zero bars), for a ``design =
                                "saltelli"`` or ``"sobol"`` run only: first- and total-order
                                (``SALib.analyze.sobol``) when the samples have Saltelli's
                                layout (rows A, AB_1..AB_D[, BA_1..BA_D], B per base point, as
                                ``SALib.sample.sobol.sample`` makes them, and as
                                ``design = "saltelli"`` makes them without the BA rows);
                                for plain scrambled Sobol' points, first-order only
                                (``SALib.analyze.rbd_fast``, given data)
==============================  ==========================================================

Figures are made with :class:`matplotlib.figure.Figure` and the Agg canvas (no pyplot, no
global backend switch); the few read closely are also written as SVG
(:data:`mcchain.viz.figures.VECTOR_FIGURES`). A lazy ensemble is read in blocks, never
whole.
"""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mcchain.ensemble.histories import not_stored_reason, without_histories
from mcchain.ensemble.queries import dim_names
from mcchain.status import Status, counts
from mcchain.viz.contact import joint_models
from mcchain.viz.figures import (
    VECTOR_FIGURES,
    figure,
    grid,
    panel_title,
    save,
    save_or_reason,
    suptitle,
)
from mcchain.viz.history import contact_loss, reaction_envelopes
from mcchain.viz.report_contact import (
    impact_figure,
    orbit_figure,
    peak_contact_forces,
    peak_force_figure,
)
from mcchain.viz.report_cycle import campbell_figure
from mcchain.viz.scatter import param_axis, parameter_scatter

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

    from mcchain.model import Model

log = logging.getLogger(__name__)

CONSTANT_RTOL = 1e-9
"""A result whose spread is below this, relative to its largest magnitude, is constant (round-off
only): not drawn, and no sensitivity index is computed for it."""
SOBOL_RESAMPLES = 200
"""Bootstrap resamples of SALib's confidence intervals."""
MIN_RBD_SAMPLES = 64
"""Fewest samples for RBD-FAST first-order indices (its harmonics need a few per period)."""
SOBOL_SEED = 12345
"""Seed of SALib's bootstrap, so reports are reproducible."""


@dataclass
class Report:
    """What :func:`make_report` wrote and what it skipped (figure name -> reason)."""

    written: list[Path] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Result:
    """One family of per-sample results: ``values`` (nsample, ncomponent), labelled."""

    name: str
    labels: tuple[str, ...]
    values: np.ndarray
    units: str
    component_units: tuple[str, ...] | None = None
    """Units of each component when they differ (``q_eq``: m for x, y and rad for θ)."""

    def units_of(self, k: int) -> str:
        """Units of component ``k``."""
        return self.units if self.component_units is None else self.component_units[k]


@dataclass(frozen=True)
class SobolIndices:
    """Sobol indices of one output over the sampled parameters (arrays of length nparam)."""

    output: str
    S1: np.ndarray
    S1_conf: np.ndarray
    ST: np.ndarray
    ST_conf: np.ndarray
    method: str = "sobol"
    """``"sobol"`` (Saltelli layout: S1 and ST) or ``"rbd_fast"`` (S1 only, ST NaN)."""


# -- reading -----------------------------------------------------------------------------------
def results(ds: xr.Dataset, models: list[str | None] | None = None) -> list[Result]:
    """The per-sample results present in the ensemble (see the module docstring);
    ``models``: :func:`mcchain.viz.contact.joint_models` (default: from the data)."""
    out: list[Result] = []
    if "omega" in ds.data_vars and ds.sizes.get("mode", 0):
        omega = np.asarray(ds["omega"].transpose("sample", "mode").values, float)
        out.append(Result("omega", tuple(f"ω{k}" for k in range(omega.shape[1])), omega, "rad/s"))
    if "q_eq" in ds.data_vars:
        q = np.asarray(ds["q_eq"].transpose("sample", "body", "dof").values, float)
        pairs = [(b, d) for b in dim_names(ds, "body") for d in dim_names(ds, "dof")]
        labels = tuple(f"{b}.{d}" for b, d in pairs)
        units = tuple("rad" if d == "theta" else "m" for _, d in pairs)
        out.append(Result("q_eq", labels, q.reshape(q.shape[0], -1), "m, rad", units))
    if "joint_force_eq" in ds.data_vars and ds.sizes.get("joint", 0):
        f = np.asarray(ds["joint_force_eq"].transpose("sample", "joint", "xy").values, float)
        out.append(
            Result(
                "joint_force_eq",
                tuple(f"|f {j}|" for j in dim_names(ds, "joint")),
                np.hypot(f[..., 0], f[..., 1]),
                "N",
            )
        )
    peak_labels, peaks, _ = peak_contact_forces(ds, models or joint_models(ds))
    keep = np.isfinite(peaks).any(axis=0)
    if keep.any():
        chosen = tuple(label for label, k in zip(peak_labels, keep, strict=True) if k)
        out.append(Result("peak_contact_force", chosen, peaks[:, keep], "N"))
    return out


# -- figures -----------------------------------------------------------------------------------
def omega_histogram(ds: xr.Dataset, path: Path) -> Path | str:
    """Histogram of each eigenpulsation (rad/s below, Hz above), with the damped pulsations
    overlaid when the run has dampers."""
    if "omega" not in ds.data_vars or not ds.sizes.get("mode", 0):
        return "the run has no eigenpulsations ([modes] absent)"
    return save(omega_histogram_figure(ds), path)


def omega_histogram_figure(ds: xr.Dataset) -> Figure:
    """The figure of :func:`omega_histogram`."""
    omega = np.asarray(ds["omega"].transpose("sample", "mode").values, float)
    damped = None
    if "damped_omega" in ds.data_vars:
        damped = np.asarray(ds["damped_omega"].transpose("sample", "mode").values, float)
        if np.array_equal(damped, np.maximum(omega, 0.0), equal_nan=True):
            damped = None  # no dampers: nothing to add
    nrow, ncol = grid(omega.shape[1])
    fig, axes = figure(nrow, ncol)
    for k, ax in enumerate(axes.flat):
        if k >= omega.shape[1]:
            ax.set_visible(False)
            continue
        w = omega[:, k][np.isfinite(omega[:, k])]
        if len(w):
            bins = min(60, max(5, int(np.sqrt(len(w)))))
            ax.hist(w, bins=bins, color="C0", alpha=0.85, label="undamped ω")
            if damped is not None:
                wd = damped[:, k][np.isfinite(damped[:, k])]
                ax.hist(wd, bins=bins, color="C1", alpha=0.6, label="damped |Im s|")
                ax.legend(fontsize=7, frameon=False)
            panel_title(ax, f"ω{k}: {_in_hz(w)}")
        else:
            ax.text(0.5, 0.5, "no finite value", ha="center", transform=ax.transAxes)
            panel_title(ax, f"ω{k}")
        ax.set_xlabel("rad/s")
        ax.set_ylabel("samples")
        ax.secondary_xaxis("top", functions=(_to_hz, _to_rad_s)).set_xlabel("Hz", fontsize=8)
    suptitle(fig, f"eigenpulsations, {omega.shape[0]} samples")
    return fig


def _to_hz(omega: Any) -> Any:
    """rad/s -> Hz (arrays or scalars)."""
    return omega / (2.0 * np.pi)


def _to_rad_s(frequency: Any) -> Any:
    """Hz -> rad/s (arrays or scalars)."""
    return frequency * (2.0 * np.pi)


def _in_hz(w: np.ndarray) -> str:
    """'mean … rad/s (… Hz), sd … rad/s (… Hz)' of finite pulsations ``w``."""
    mean, sd = float(w.mean()), float(w.std())
    return f"mean {mean:.4g} rad/s ({_to_hz(mean):.4g} Hz), sd {sd:.3g} ({_to_hz(sd):.3g} Hz)"


def is_constant(y: np.ndarray, scale: float | None = None) -> bool:
    """Whether the finite values ``y`` (non-empty) differ by round-off only: a spread of at
    most :data:`CONSTANT_RTOL` times ``scale``, the size of the quantity (default: the
    largest ``|y|``; pass the largest value of the whole result, so that a coordinate that
    stays at 0 ± 1e-16 m in a mechanism of 0.1 m is constant too)."""
    size = float(np.abs(y).max()) if scale is None else float(scale)
    return bool(np.ptp(y) <= CONSTANT_RTOL * size)


def constant_note(label: str, y: np.ndarray, scale: float | None = None) -> str:
    """``"ω1 = 12.5 in all 64 samples"``, with ``" (constant to 2e-15)"`` when the values
    differ by round-off (the spread relative to ``scale``, as :func:`is_constant`): what a
    plot says instead of drawing a constant output's rounding noise."""
    spread, middle = float(np.ptp(y)), float(np.median(y))
    value = middle if abs(middle) > spread else 0.0  # 0 ± round-off reads as 0
    text = f"{label} = {value:.6g} in all {len(y)} samples"
    if spread > 0.0:
        size = float(np.abs(y).max()) if scale is None else float(scale)
        text += f" (constant to {spread / size:.0e})" if size > 0.0 else ""
    return text


def _sizes_by_units(result: Result) -> list[float]:
    """Per component, the largest finite |value| over the components of the same units
    (the quantity's size, against which round-off is judged)."""
    units = [result.units_of(k) for k in range(len(result.labels))]
    values = result.values.reshape(result.values.shape[0], -1)
    largest = np.where(np.isfinite(values), np.abs(values), 0.0).max(axis=0, initial=0.0)
    size: dict[str, float] = {}
    for u, m in zip(units, largest, strict=True):
        size[u] = max(size.get(u, 0.0), float(m))
    return [size[u] for u in units]


def scatter(ds: xr.Dataset, result: Result, path: Path) -> Path | str:
    """``scatter_<result>.png``: :func:`scatter_figure`, saved."""
    return save_or_reason(scatter_figure(ds, result), path)


def scatter_figure(ds: xr.Dataset, result: Result) -> Figure | str:
    """Each varying component of ``result`` against each sampled
    parameter (:func:`mcchain.viz.scatter.parameter_scatter`); constant components are named
    in the title, not drawn."""
    rows, constant = [], []
    sizes = _sizes_by_units(result)
    for k, label in enumerate(result.labels):
        y = result.values[:, k]
        finite = y[np.isfinite(y)]
        if len(finite) and not is_constant(finite, sizes[k]):
            rows.append((f"{label} [{result.units_of(k)}]", y))
        elif len(finite):
            constant.append(constant_note(label, finite, sizes[k]))
    if not rows:
        if constant:
            return f"{result.name} is constant: " + "; ".join(constant)
        return f"{result.name} has no finite value"
    notes = ["constant (not drawn): " + "; ".join(constant)] if constant else []
    hz = ("Hz", _to_hz, _to_rad_s) if result.units == "rad/s" else None
    title = f"{result.name} against the sampled parameters"
    return parameter_scatter(ds, rows, title, notes, hz)


def status_counts(ds: xr.Dataset, path: Path) -> Path | str:
    """Bar chart of how many samples carry each status flag."""
    if "status" not in ds.data_vars:
        return "the run has no status variable"
    c = counts(np.asarray(ds["status"].values))
    names = ["ok", *(flag.meaning for flag in Status)]
    values = [c[n] for n in names]
    fig, axes = figure(1, 1, w=7.0, h=3.6)
    ax = axes[0, 0]
    colors = ["C2"] + ["C3" if f.value & 0b1111 else "C1" for f in Status]
    bars = ax.bar(range(len(names)), values, color=colors)
    ax.bar_label(bars, fontsize=8)
    ax.set_xticks(range(len(names)), [n.replace("_", "\n") for n in names], fontsize=8)
    ax.set_ylabel("samples")
    panel_title(ax, f"status of {ds.sizes['sample']} samples (flags may overlap)", 10.0)
    return save(fig, path)


# -- Sobol -------------------------------------------------------------------------------------
def saltelli_layout(
    params: np.ndarray, second_order: bool | None = None
) -> tuple[int, bool] | None:
    """``(N, calc_second_order)`` if the rows of ``params`` (n, D) have Saltelli's layout
    (``SALib.sample.sobol.sample``: per base point the rows A, AB_1..AB_D, [BA_1..BA_D,] B,
    where AB_j is A with column j from B), else ``None``. ``second_order`` True/False looks
    for that layout only (the scene's ``"saltelli"`` design has no BA rows: False)."""
    params = np.asarray(params, dtype=np.float64)
    n, d = params.shape
    if d == 0 or n == 0:
        return None
    for second in (True, False) if second_order is None else (second_order,):
        step = 2 * d + 2 if second else d + 2
        if n % step:
            continue
        groups = params.reshape(n // step, step, d)
        a, b = groups[:, 0], groups[:, -1]
        ok = True
        for j in range(d):
            ab = a.copy()
            ab[:, j] = b[:, j]
            ok &= bool(np.array_equal(groups[:, 1 + j], ab, equal_nan=True))
            if second:
                ba = b.copy()
                ba[:, j] = a[:, j]
                ok &= bool(np.array_equal(groups[:, 1 + d + j], ba, equal_nan=True))
        if ok and not np.array_equal(a, b, equal_nan=True):
            return n // step, second
    return None


def sobol_indices(
    params: np.ndarray,
    outputs: dict[str, np.ndarray],
    names: list[str],
    skipped: dict[str, str] | None = None,
    design: str | None = None,
) -> list[SobolIndices] | str:
    """Sobol indices of each output over the sampled parameters, with SALib.

    * Samples in Saltelli's layout (:func:`saltelli_layout`): first- and total-order indices
      by ``SALib.analyze.sobol`` (Saltelli 2010 / Jansen estimators). With ``design =
      "saltelli"`` (the scene's design: D + 2 rows per base point, no second order) that
      layout is required (``calc_second_order=False``); without it there is no fallback.
    * Any other sample (e.g. plain scrambled Sobol' points, as the ``"sobol"`` design draws
      them): first-order indices only, by ``SALib.analyze.rbd_fast`` (a given-data estimator
      valid for any sample of independent inputs); ``ST`` is NaN, since total-order indices
      need the A/B/AB_j rows.

    Args:
        params: (n, D) sampled parameters.
        outputs: output label -> (n,) values; outputs with a non-finite value or no variance
            are left out (their reason goes into ``skipped``).
        names: the D parameter names.
        design: the run's ``[sample] design``; ``"saltelli"`` requires its layout.

    Returns:
        The indices, or the reason why none could be computed.
    """
    from SALib.analyze import rbd_fast, sobol

    skipped = {} if skipped is None else skipped
    params = np.asarray(params, dtype=np.float64)
    d = len(names)
    if design == "saltelli":
        layout = saltelli_layout(params, second_order=False)
        if layout is None:
            return (
                f'{params.shape[0]} samples of design "saltelli" without its layout (groups of '
                f"{d + 2} rows A, AB_1..AB_{d}, B per base point, in sample order)"
            )
    else:
        layout = saltelli_layout(params)
    problem = {"num_vars": d, "names": list(names), "bounds": [[0.0, 1.0]] * d}
    if layout is None:
        if params.shape[0] < MIN_RBD_SAMPLES:
            return (
                f"{params.shape[0]} samples without Saltelli's layout: too few for first-order "
                f"indices by RBD-FAST (at least {MIN_RBD_SAMPLES})"
            )
        log.info(
            "sobol: the samples do not have Saltelli's layout (A, AB_j[, BA_j], B rows): "
            "first-order indices by RBD-FAST only, no total-order indices"
        )
    found: list[SobolIndices] = []
    for label, y in outputs.items():
        y = np.asarray(y, dtype=np.float64)
        finite = np.isfinite(y)
        reason = None
        if layout is not None and not finite.all():
            reason = f"{int((~finite).sum())} samples have no finite value (Saltelli rows)"
        elif layout is None and finite.sum() < MIN_RBD_SAMPLES:
            reason = f"only {int(finite.sum())} samples have a finite value"
        elif is_constant(y[finite]):
            reason = "constant: " + constant_note(label, y[finite])
        if reason is not None:
            log.info("sobol: %s left out: %s", label, reason)
            skipped[f"sobol {label}"] = reason
            continue
        if layout is not None:
            si = sobol.analyze(
                problem,
                y,
                calc_second_order=layout[1],
                num_resamples=SOBOL_RESAMPLES,
                seed=SOBOL_SEED,
            )
            st, st_conf = np.asarray(si["ST"], float), np.asarray(si["ST_conf"], float)
        else:
            if not finite.all():
                log.info("sobol: %s: %d failed samples left out", label, (~finite).sum())
            si = rbd_fast.analyze(
                problem,
                params[finite],
                y[finite],
                num_resamples=SOBOL_RESAMPLES,
                seed=SOBOL_SEED,
            )
            st, st_conf = np.full(d, np.nan), np.full(d, np.nan)
        found.append(
            SobolIndices(
                label,
                np.asarray(si["S1"], float),
                np.asarray(si["S1_conf"], float),
                st,
                st_conf,
                "sobol" if layout is not None else "rbd_fast",
            )
        )
    if not found:
        return "no output with finite, varying values to analyse: " + "; ".join(
            f"{label.removeprefix('sobol ')}: {why}" for label, why in skipped.items()
        )
    return found


def sobol_figure(
    ds: xr.Dataset,
    design: str | None,
    path: Path,
    csv_path: Path,
    skipped: dict[str, str] | None = None,
) -> Path | str:
    """``sobol.png`` (grouped bars S1/ST with confidence intervals) and ``sobol.csv``, for
    the designs ``"saltelli"`` (S1 and ST) and ``"sobol"`` (see :func:`sobol_indices`)."""
    if design not in ("saltelli", "sobol"):
        return f'the sample design is {design!r}, not "saltelli" or "sobol"'
    if "parameters" not in ds.data_vars or not ds.sizes.get("param", 0):
        return "the run samples no parameter"
    params = np.asarray(ds["parameters"].transpose("sample", "param").values, float)
    names = dim_names(ds, "param")
    outputs: dict[str, np.ndarray] = {}
    for result in results(ds):
        if result.name == "q_eq":
            continue
        for k, label in enumerate(result.labels):
            outputs[label] = result.values[:, k]
    if not outputs:
        return "the run has no scalar result to analyse"
    left_out: dict[str, str] = {}
    found = sobol_indices(params, outputs, names, left_out, design)
    if skipped is not None:
        skipped.update(left_out)
    if isinstance(found, str):
        return found
    with open(csv_path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["output", "parameter", "method", "S1", "S1_conf", "ST", "ST_conf"])
        for s in found:
            for j, name in enumerate(names):
                values = (f"{v[j]:.6g}" for v in (s.S1, s.S1_conf, s.ST, s.ST_conf))
                writer.writerow([s.output, name, s.method, *values])
    nrow, ncol = grid(len(found), 3)
    fig, axes = figure(nrow, ncol, w=max(3.2, 0.9 * len(names) + 1.5), h=2.8)
    x = np.arange(len(names))
    ticks = [param_axis(path, params[:, j])[0] for j, path in enumerate(names)]
    for ax, s in zip(axes.flat, found, strict=False):
        ax.bar(x - 0.2, s.S1, 0.4, yerr=s.S1_conf, capsize=2, label="first order S1")
        if np.isfinite(s.ST).any():
            ax.bar(x + 0.2, s.ST, 0.4, yerr=s.ST_conf, capsize=2, label="total order ST")
        ax.set_xticks(x, ticks, rotation=30, ha="right", fontsize=7)
        ax.set_ylim(min(0.0, float(np.nanmin(s.S1 - s.S1_conf))) - 0.02, 1.05)
        panel_title(ax, s.output)
        ax.legend(fontsize=7, frameon=False)
    for ax in list(axes.flat)[len(found) :]:
        ax.set_visible(False)
    if found[0].method != "sobol":
        how = "first order only (RBD-FAST):\nthe samples lack Saltelli's layout"
    elif design == "saltelli":
        how = 'SALib sobol (S1, ST) on the "saltelli" design'
    else:
        how = "SALib sobol on Saltelli's layout"
    constant = [why.removeprefix("constant: ") for why in left_out.values() if "constant" in why]
    if constant:  # said, not drawn as zero bars
        how += "\nconstant, no indices: " + "; ".join(constant)
    suptitle(fig, f"Sobol indices, {params.shape[0]} samples, 95 % CI\n{how}")
    return save(fig, path)


# -- command -----------------------------------------------------------------------------------
def make_report(
    ds: xr.Dataset,
    out_dir: str | Path,
    *,
    design: str | None = None,
    model: Model | None = None,
) -> Report:
    """Write every figure the ensemble allows into ``out_dir`` (created if needed).

    ``model``: the model of the samples (row = global sample index), which gives the joint
    points of the journal orbit and the model (link, contact, auto) of each clearance joint;
    ``None``: the orbit is skipped and the models are inferred from the data.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = Report()
    # A light run ([storage] histories = "none" | "failed"): the figures over every
    # sample's history say why they are missing; the others read the per-sample variables.
    not_stored = not_stored_reason(ds)
    if not_stored is not None:
        ds = without_histories(ds)

    def record(name: str, produced: Path | str) -> None:
        if isinstance(produced, Path):
            report.written.append(produced)
            vector = produced.with_suffix(".svg")
            if produced.stem in VECTOR_FIGURES and vector.is_file():
                report.written.append(vector)
        else:
            log.info("report: %s skipped: %s", name, produced)
            report.skipped[name] = produced

    record("omega_histogram.png", omega_histogram(ds, out / "omega_histogram.png"))
    cycle = out / "modes_along_cycle.png"
    record("modes_along_cycle.png", save_or_reason(campbell_figure(ds), cycle))
    models = joint_models(ds, model)
    found = results(ds, models)
    if not found:
        record("scatter_*.png", "the run has no equilibrium, mode or contact result")
    for result in found:
        name = f"scatter_{result.name}.png"
        if result.name == "peak_contact_force":
            record(name, save_or_reason(peak_force_figure(ds, models), out / name))
        else:
            record(name, scatter(ds, result, out / name))
    record(
        "scatter_impact_count.png",
        save_or_reason(impact_figure(ds), out / "scatter_impact_count.png"),
    )
    for name, draw in (
        ("journal_orbit.png", lambda path: save_or_reason(orbit_figure(ds, model, models), path)),
        ("reaction_envelopes.png", lambda path: reaction_envelopes(ds, path, models)),
    ):
        record(name, not_stored if not_stored is not None else draw(out / name))
    record("contact_loss.png", contact_loss(ds, out / "contact_loss.png"))
    record("status_counts.png", status_counts(ds, out / "status_counts.png"))
    record(
        "sobol.png",
        sobol_figure(ds, design, out / "sobol.png", out / "sobol.csv", report.skipped),
    )
    from mcchain.viz.report_requirements import requirements_figure

    found_requirements = requirements_figure(ds)
    record("requirements.png", save_or_reason(found_requirements, out / "requirements.png"))
    return report
