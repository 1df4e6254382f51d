"""Run every shipped config from two source trees and compare their ``ensemble.nc``.

For a change meant to keep the numbers (a refactor): each config is run with
``mcchain run --samples N`` from each tree (its own numba and lane caches), and every
variable of the two ensembles is compared; a difference is reported as its largest size
relative to the variable's largest value, absolute, and in ulps of that largest value.

    python benchmarks/compare_ensembles.py BEFORE_TREE AFTER_TREE [--samples 8] [--out DIR]

The trees are checkouts (e.g. ``git worktree add --detach``); prints a Markdown table. A
finished run in ``--out`` is reused (delete ``DIR/after`` after changing the after tree).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import xarray as xr


def run_tree(tree: Path, config: str, out: Path, samples: int) -> Path:
    """``mcchain run`` of ``config`` from ``tree`` into ``out``; the ensemble's path."""
    env = dict(os.environ, PYTHONPATH=str(tree), MCCHAIN_CACHE_DIR=str(out / "cache"))
    run = out / Path(config).stem
    if (run / "ensemble.nc").exists():  # a finished run of this tree: reused
        return run / "ensemble.nc"
    shutil.rmtree(run, ignore_errors=True)
    command = [sys.executable, "-m", "mcchain.cli", "run", str(tree / config), "--quiet",
               "--samples", str(samples), "--run-dir", str(run)]  # fmt: skip
    subprocess.run(command, env=env, check=True, cwd=tree, stdout=subprocess.DEVNULL)
    return run / "ensemble.nc"


def compare(before: Path, after: Path) -> str:
    """'identical' or, per differing variable, its largest difference."""
    a, b = xr.open_dataset(before), xr.open_dataset(after)
    notes = []
    for name in sorted(set(a.variables) | set(b.variables)):
        if name not in a.variables or name not in b.variables:
            notes.append(f"{name}: only in one")
            continue
        x, y = a[name].values, b[name].values
        if x.dtype.kind not in "fc":
            if not np.array_equal(x, y):
                notes.append(f"{name}: differs")
            continue
        if np.array_equal(x, y, equal_nan=True):
            continue
        both = np.isfinite(x) & np.isfinite(y)
        if not np.array_equal(np.isnan(x), np.isnan(y)):
            notes.append(f"{name}: NaN pattern differs")
        scale = float(np.nanmax(np.abs(x))) if np.isfinite(x).any() else 1.0
        diff = float(np.max(np.abs(x[both] - y[both]))) if both.any() else 0.0
        ulps = diff / float(np.spacing(scale)) if scale > 0.0 else 0.0
        notes.append(f"{name} {diff / (scale or 1.0):.1e} ({diff:.1e}; {ulps:.0f} ulp of max)")
    a.close()
    b.close()
    return "identical" if not notes else "; ".join(notes)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--out", type=Path, default=Path("/tmp/compare-ensembles"))
    parser.add_argument("--only", nargs="*", default=None, help="config stems to run")
    args = parser.parse_args()
    configs = sorted(p.name for p in (args.after / "configs").glob("*.toml"))
    if args.only:
        configs = [c for c in configs if Path(c).stem in args.only]
    print("| config | after against before |\n|---|---|")
    for config in configs:
        paths = [run_tree(tree, f"configs/{config}", args.out / side, args.samples)
                 for side, tree in (("before", args.before), ("after", args.after))]  # fmt: skip
        print(f"| {Path(config).stem} | {compare(*paths)} |", flush=True)


if __name__ == "__main__":
    main()
