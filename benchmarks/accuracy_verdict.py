r"""How accurate is the slider-crank verdict's integration (issue 37, item 6)? rk45 on
``configs/slider-crank-requirement.toml`` (``[storage] histories = "none"``), in process,
against a tight reference of the same samples.

The clearance joint's impacts make the per-sample values sensitive to any perturbation of the
step sequence: a difference between two settings at the scene's tolerance says nothing about
which is the more accurate one. So each variant is compared with a reference: the same
samples at tolerances several decades tighter (rk45, and radau, an independent integrator),
whose own convergence is shown by two tight tolerances against each other.

Variants (``--variants``, the names of :data:`VARIANTS`; the scene's rtol/atol unless a
name says otherwise):

* ``landing``: steps that land on every output time (``output_dt`` 1e-5 s: at most 10 µs),
  as shipped;
* ``free``: steps as the error control chooses them (the output grid would be read from the
  Dormand-Prince dense output; with ``histories = "none"`` nothing is stored, so the
  per-sample values are those of a run whose only output time is t_end);
* ``free-1e-N`` / ``landing-1e-N``: rk45 at rtol 1e-N, atol 1e-(N+3); ``radau-1e-N``: radau
  likewise.

Per variant against each of ``--references``: per-sample errors of ``slider_error`` (m,
absolute), ``peak_contact_force`` at the pin and ``pin_force_after_startup`` (relative to the
reference's value), median, p90 and max, the samples whose status differs; and per
requirement what the user reads: failures, P(fail) with its one-sided bounds at the
requirement's confidence, the verdict, and the samples whose pass/fail differs from the
reference's. The commands of ``benchmarks/results/verdict/accuracy.md``:

    python benchmarks/accuracy_verdict.py --samples 1024 \
        --variants landing,free,landing-1e-8,free-1e-8,free-1e-9,free-1e-10,free-1e-11,\
free-1e-12,landing-1e-12,free-1e-13 --references free-1e-13,free-1e-12 --out accuracy_1024.md
    python benchmarks/accuracy_verdict.py --samples 32 \
        --variants landing,free,free-1e-12,free-1e-13,radau-1e-10,radau-1e-11 \
        --references free-1e-13,radau-1e-11 --out accuracy_radau.md

Results (with the command, the load average, the steps, rejections, evaluations and CPU
seconds of each variant) go to ``benchmarks/results/verdict/`` under ``--out``; the
reading of them is ``accuracy.md`` there.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from profile_verdict import light_scene, write_result

VARIANTS: dict[str, dict[str, Any]] = {
    "landing": {"steps": "landing"},
    "free": {"steps": "free"},
    "free-1e-8": {"steps": "free", "rtol": 1e-8, "atol": 1e-11},
    "free-1e-9": {"steps": "free", "rtol": 1e-9, "atol": 1e-12},
    "landing-1e-8": {"steps": "landing", "rtol": 1e-8, "atol": 1e-11},
    "landing-1e-10": {"steps": "landing", "rtol": 1e-10, "atol": 1e-13},
    "free-1e-10": {"steps": "free", "rtol": 1e-10, "atol": 1e-13},
    "free-1e-11": {"steps": "free", "rtol": 1e-11, "atol": 1e-14},
    "free-1e-12": {"steps": "free", "rtol": 1e-12, "atol": 1e-15},
    "landing-1e-12": {"steps": "landing", "rtol": 1e-12, "atol": 1e-15},
    "free-1e-13": {"steps": "free", "rtol": 1e-13, "atol": 1e-16},
    "radau-1e-10": {"method": "radau", "rtol": 1e-10, "atol": 1e-13},
    "radau-1e-11": {"method": "radau", "rtol": 1e-11, "atol": 1e-14},
}
"""Each variant's changes to the scene's ``[simulate]``; ``steps``: how rk45's steps meet the
output times (``free`` is emulated on a tree without the setting by one output time, t_end)."""

OUTPUTS = ("slider_error", "peak_contact_force", "pin_force_after_startup")
"""The per-sample values the requirements read (the peak at the pin joint)."""


def variant_scene(scene: Any, name: str) -> Any:
    """The scene with ``[simulate]`` as variant ``name`` says."""
    update = dict(VARIANTS[name])
    steps = update.pop("steps", None)
    sim = scene.simulate
    if steps is not None:
        if "steps" in type(sim).model_fields:
            update["steps"] = steps
        elif steps == "free":
            update["output_dt"] = sim.t_end
    return scene.model_copy(update={"simulate": sim.model_copy(update=update)})


def solve(scene: Any, model: Any, name: str) -> tuple[dict[str, np.ndarray], float]:
    """Per-sample values of variant ``name`` (with its steps, rejected steps and
    evaluations a sample), and the CPU seconds of its integration (the kernels compiled or
    loaded before, unmeasured). As :func:`mcchain.solvers.solve_chunk` solves a chunk,
    with the solver's diagnostics kept."""
    from mcchain.solvers import _Ideal
    from mcchain.solvers.outputs import simulate_outputs
    from mcchain.solvers.statics import assemble

    sim = variant_scene(scene, name).simulate
    timed = [o for o in scene.output if o.at is None]

    def run(part: Any) -> tuple[dict[str, np.ndarray], float]:
        start, ideal = assemble(part), _Ideal(part, scene)
        status = start.status | ideal.status(False)
        t0 = time.process_time()
        out = simulate_outputs(part, timed, sim, start.q, start.v, ideal.start(False), status,
                               diagnostics=True, histories=False)  # fmt: skip
        return out, time.process_time() - t0

    run(model.select(0, 2))
    out, cpu = run(model)
    joint = model.joint_names.index("B")
    values = {
        "slider_error": np.asarray(out["slider_error"], dtype=np.float64),
        "peak_contact_force": np.asarray(out["peak_contact_force"][:, joint], dtype=np.float64),
        "pin_force_after_startup": np.asarray(out["pin_force_after_startup"], dtype=np.float64),
        "status": np.asarray(out["status"]),
    }
    for key in ("steps", "rejected_steps", "evaluations"):
        values[key] = np.asarray(out[key])
    return values, cpu


def verdicts(scene: Any, model: Any, values: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    """Per requirement: the samples that meet it, failures, P(fail), its one-sided bounds
    and the verdict, as ``mcchain verdict`` reads them (fixed count, independent draws)."""
    from mcchain.decision.requirements import check_requirements, defined_samples, requirement_met
    from mcchain.decision.stats import one_sided_bounds, verdict

    defined = defined_samples(values["status"])
    rows = []
    for requirement, sel in zip(scene.requirement, check_requirements(scene, model), strict=True):
        met = requirement_met(values[sel.output], requirement, defined) > 0
        failures = int(np.count_nonzero(~met))
        lower, upper = one_sided_bounds(failures, met.size, requirement.confidence)
        rows.append({
            "name": requirement.name, "met": met, "failures": failures,
            "p": failures / met.size, "lower": lower, "upper": upper,
            "verdict": verdict(lower, upper, requirement.target),
        })  # fmt: skip
    return rows


def flags(bits: Any) -> str:
    """The status words of ``bits`` (``none`` without a bit)."""
    from mcchain.status import Status

    return " ".join(f.meaning for f in Status if int(bits) & f.value) or "none"


def error_stats(x: np.ndarray, ref: np.ndarray, relative: bool) -> str:
    """median / p90 / max of |x − ref| (over |ref| when ``relative``) where both are finite,
    and how many samples are finite in one only."""
    both = np.isfinite(x) & np.isfinite(ref)
    err = np.abs(x[both] - ref[both])
    if relative:
        err = err / np.abs(ref[both])
    odd = int(np.count_nonzero(np.isfinite(x) != np.isfinite(ref)))
    text = f"{np.median(err):.2g} / {np.percentile(err, 90):.2g} / {np.max(err):.2g}"
    return text + (f" ({odd} NaN in one only)" if odd else "")


def tables(scene: Any, model: Any, results: dict[str, Any], reference: str) -> list[str]:
    ref_values = results[reference][0]
    ref_rows = verdicts(scene, model, ref_values)
    lines = [
        f"### Per-sample errors against `{reference}` (median / p90 / max over the samples)",
        "",
        "| variant | rtol, atol | steps a sample | rejected | evaluations a sample | CPU (s) | "
        "slider_error (m) | peak_contact_force (relative) | pin_force_after_startup "
        "(relative) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (values, cpu) in results.items():
        sim = variant_scene(scene, name).simulate
        steps, rejected = values["steps"].sum(), values["rejected_steps"].sum()
        share = f"{rejected / (steps + rejected) * 100:.1f} %" if rejected >= 0 else "–"
        lines.append(
            f"| `{name}` | {sim.rtol:g}, {sim.atol:g} | {values['steps'].mean():.0f} | {share} | "
            f"{values['evaluations'].mean():.0f} | {cpu:.2f} | "
            + " | ".join(
                "(reference)"
                if name == reference
                else error_stats(values[o], ref_values[o], o != "slider_error")
                for o in OUTPUTS
            )
            + " |"
        )
    for name, (values, _) in results.items():
        differ = np.flatnonzero(values["status"] != ref_values["status"])
        if len(differ):
            lines.append(
                f"- `{name}`: status differs from the reference's on sample(s) "
                + ", ".join(f"{s} ({flags(values['status'][s])} against "
                            f"{flags(ref_values['status'][s])})" for s in differ)
            )  # fmt: skip
    lines += [
        "",
        f"### What the verdict says ({model.nsample} samples; P(fail) [lower, upper] one-sided "
        "at the requirement's confidence; flips: samples whose pass/fail differs from "
        f"`{reference}`'s, as passes there -> fails here / fails there -> passes here)",
        "",
        "| variant | " + " | ".join(r["name"] for r in ref_rows) + " |",
        "|---|" + "---|" * len(ref_rows),
    ]
    for name, (values, _) in results.items():
        cells = []
        for row, ref in zip(verdicts(scene, model, values), ref_rows, strict=True):
            to_fail = np.flatnonzero(ref["met"] & ~row["met"])
            to_pass = np.flatnonzero(~ref["met"] & row["met"])
            flips = f"flips {len(to_fail)}/{len(to_pass)}"
            if 0 < len(to_fail) + len(to_pass) <= 6:
                flips += " (samples " + ", ".join(map(str, [*to_fail, *to_pass])) + ")"
            cells.append(
                f"{row['failures']} fail, {row['p']:.4f} [{row['lower']:.4f}, "
                f"{row['upper']:.4f}] {row['verdict']}; {flips}"
            )
        lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--variants", default="landing,free,landing-1e-10,free-1e-11,free-1e-12,radau-1e-10",
        help=f"comma-separated, of {', '.join(VARIANTS)}",
    )  # fmt: skip
    parser.add_argument(
        "--references", default="free-1e-12,free-1e-11",
        help="comma-separated variants to compare every variant with, one table each",
    )  # fmt: skip
    parser.add_argument("--out", default="accuracy.md", help="file name in the results folder")
    args = parser.parse_args()
    names, references = args.variants.split(","), args.references.split(",")
    for name in names:
        if name not in VARIANTS:
            parser.error(f"--variants: {name!r} is none of {', '.join(VARIANTS)}")
    for name in references:
        if name not in names:
            parser.error(f"--references: {name!r} is not one of --variants")
    command = "python benchmarks/accuracy_verdict.py " + " ".join(sys.argv[1:])
    numba.set_num_threads(args.threads)
    scene, model = light_scene(args.samples)
    load = os.getloadavg()[0]
    results = {}
    for name in names:
        results[name] = solve(scene, model, name)
        values, cpu = results[name]
        print(f"{name}: {values['steps'].mean():.0f} steps, {cpu:.2f} s", flush=True)
    lines = [f"{args.threads} threads, load {load:.1f} at the start", ""]
    for reference in references:
        lines += [*tables(scene, model, results, reference), ""]
    write_result(command, lines, args.out)


if __name__ == "__main__":
    main()
