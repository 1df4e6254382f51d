"""Is a change of bits within the tolerance? Two trees against one tight reference.

A change meant to keep the numbers can still move their last bits (a different fused
multiply-add, a term summed in another order); on a run with impacts those ulps grow into
visibly different per-sample values. Whether that is within the integrator's tolerance is
decided against a reference: each shipped config named is run with ``mcchain run --samples
N`` from the BEFORE and the AFTER tree as written, and from the AFTER tree with
``[simulate] rtol``/``atol`` tightened (``--reference-rtol``, atol 1e-3 of it); per
per-sample variable (sample axis only), the differences to the reference relative to its
largest |value|: median / p90 / max over the samples, before and after, and the samples of
each integer variable that differ from the reference's.

    python benchmarks/accuracy_bits.py BEFORE_TREE AFTER_TREE --only fourbar-clearance
        [--samples 64] [--reference-rtol 1e-11] [--out DIR]

Prints a Markdown table per config.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_ensembles import run_tree


def tightened(text: str, rtol: float) -> str:
    """The config ``text`` with ``[simulate] rtol``/``atol`` set to ``rtol``, ``rtol`` · 1e-3."""
    text = re.sub(r"(?m)^(rtol|atol)\s*=.*\n", "", text)
    return text.replace("[simulate]\n", f"[simulate]\nrtol = {rtol!r}\natol = {rtol * 1e-3!r}\n", 1)


def per_sample(path: Path) -> dict[str, np.ndarray]:
    """The per-sample variables of the ensemble (sample first, no time axis), one column
    per label of their other axis (``peak_contact_force[joint=B]``)."""
    out = {}
    with xr.open_dataset(path) as data:
        for name, var in data.data_vars.items():
            if not var.dims or var.dims[0] != "sample" or "time" in var.dims:
                continue
            if var.ndim == 1:
                out[name] = var.values
            elif var.ndim == 2:
                axis = var.dims[1]
                for i, label in enumerate(data[axis].values):
                    column = var.values[:, i]
                    if np.isfinite(column).any() if column.dtype.kind == "f" else True:
                        out[f"{name}[{axis}={label}]"] = column
    return out


def errors(values: np.ndarray, reference: np.ndarray) -> str:
    """Median / p90 / max of |values − reference| / max |reference| (finite in both)."""
    both = np.isfinite(values) & np.isfinite(reference)
    if not both.any():
        return "no finite pair"
    scale = float(np.max(np.abs(reference[both]))) or 1.0
    e = np.abs(values[both] - reference[both]) / scale
    return " / ".join(f"{x:.1e}" for x in (np.median(e), np.percentile(e, 90), e.max()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--only", nargs="+", required=True, help="config stems")
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--reference-rtol", type=float, default=1e-11)
    parser.add_argument("--out", type=Path, default=Path("/tmp/accuracy-bits"))
    args = parser.parse_args()
    for stem in args.only:
        config = f"configs/{stem}.toml"
        runs = {
            "before": run_tree(args.before.resolve(), config, args.out / "before", args.samples),
            "after": run_tree(args.after.resolve(), config, args.out / "after", args.samples),
        }
        # the reference: the after tree's run of the tightened config
        tight = args.out / "reference-configs" / f"{stem}.toml"
        tight.parent.mkdir(parents=True, exist_ok=True)
        written = (args.after / config).read_text(encoding="utf-8")
        tight.write_text(tightened(written, args.reference_rtol), encoding="utf-8")
        runs["reference"] = run_tree(
            args.after.resolve(), str(tight.resolve()), args.out / "reference", args.samples
        )
        values = {name: per_sample(path) for name, path in runs.items()}
        ref = values["reference"]
        print(f"\n### {stem}: {args.samples} samples, reference rtol {args.reference_rtol:g}\n")
        print("| variable | before against the reference | after against the reference |")
        print("|---|---|---|")
        for name in sorted(ref):
            cells = []
            for side in ("before", "after"):
                x, r = values[side][name], ref[name]
                if x.dtype.kind in "fc":
                    cells.append(errors(x, r))
                else:
                    cells.append(f"{int(np.sum(x != r))} samples differ")
            if "no finite pair" in cells[0] and "no finite pair" in cells[1]:
                continue
            if x.dtype.kind in "fc" or cells[0] != cells[1] or "0 samples" not in cells[0]:
                print(f"| {name} | {cells[0]} | {cells[1]} |")
        same = {n: np.array_equal(values["before"][n], values["after"][n], equal_nan=True)
                for n in ref}  # fmt: skip
        print(f"\nbefore and after bitwise equal: {', '.join(n for n, s in same.items() if s)}")


if __name__ == "__main__":
    main()
