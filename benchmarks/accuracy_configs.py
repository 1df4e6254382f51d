"""Two source trees against a tight reference on shipped configs: for a change of bits whose
effect an impact sequence amplifies (the contact law's δ^1.5 rounded once instead of libm's
``pow``), is either tree the more accurate one?

Each config runs ``--samples`` samples (``mcchain run``) from ``before`` and ``after`` as
written, and from ``after`` with ``rtol``/``atol`` tightened (``--reference``: rtol; atol
1000 times smaller) as the reference. Per per-sample variable, the largest and median
difference from the reference relative to the reference's value (``impact_count``: the
samples whose count differs), for both trees.

    python benchmarks/accuracy_configs.py BEFORE_TREE AFTER_TREE [--only fourbar-clearance]
        [--samples 8] [--reference 1e-11] [--out DIR]

Runs already in ``--out`` are reused (``compare_ensembles.py``'s layout: ``DIR/before``,
``DIR/after``). Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from compare_ensembles import run_tree

from mcchain.ensemble.per_sample import open_per_sample

VARIABLES = ("peak_contact_force", "max_penetration", "peak_joint_force", "free_flight_time")


def _tight(tree: Path, config: str, out: Path, rtol: float, samples: int) -> Path:
    """The ensemble of ``config`` run from ``tree`` at rtol ``rtol``, atol rtol/1000."""
    run = out / "reference" / Path(config).stem
    if (run / "ensemble.nc").exists():
        return run / "ensemble.nc"
    text = (tree / config).read_text()
    text = re.sub(r"^(rtol|atol) = .*\n", "", text, flags=re.MULTILINE)
    text = re.sub(r'^(method = "rk45".*)$', rf"\1\nrtol = {rtol!r}\natol = {rtol / 1000!r}", text,
                  count=1, flags=re.MULTILINE)  # fmt: skip
    run.parent.mkdir(parents=True, exist_ok=True)
    scene = run.parent / f"{Path(config).stem}.toml"
    scene.write_text(text)
    env = dict(os.environ, PYTHONPATH=str(tree), MCCHAIN_CACHE_DIR=str(out / "after" / "cache"))
    command = [sys.executable, "-m", "mcchain.cli", "run", str(scene), "--quiet",
               "--samples", str(samples), "--run-dir", str(run)]  # fmt: skip
    subprocess.run(command, env=env, check=True, cwd=tree, stdout=subprocess.DEVNULL)
    return run / "ensemble.nc"


def _errors(path: Path, reference: Path) -> list[str]:
    ds, ref = open_per_sample(path), open_per_sample(reference)
    cells = []
    for name in VARIABLES:
        if name not in ds.data_vars:  # a scene without contact-law joints has no contact figures
            cells.append("–")
            continue
        x, r = np.asarray(ds[name].values, float), np.asarray(ref[name].values, float)
        keep = np.isfinite(r) & (np.abs(r) > 0)
        rel = np.abs(x[keep] / r[keep] - 1.0)
        cells.append(f"{np.median(rel):.1e} / {np.max(rel):.1e}" if rel.size else "–")
    if "impact_count" not in ds.data_vars:
        return [*cells, "–"]
    counts = np.asarray(ds["impact_count"].values) != np.asarray(ref["impact_count"].values)
    cells.append(str(int(np.any(counts.reshape(counts.shape[0], -1), axis=1).sum())))
    return cells


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--only", nargs="*", default=["fourbar-clearance", "fourbar-contact-sweep"])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--reference", type=float, default=1e-11, help="the reference's rtol")
    parser.add_argument("--out", type=Path, default=Path("/tmp/compare-ensembles"))
    args = parser.parse_args()
    print(
        "| config | tree | "
        + " | ".join(f"{v} (relative; median / max)" for v in VARIABLES)
        + " | samples whose impact counts differ |"
    )
    print("|---" * (len(VARIABLES) + 3) + "|")
    for stem in args.only:
        config = f"configs/{stem}.toml"
        reference = _tight(args.after, config, args.out, args.reference, args.samples)
        for side, tree in (("before", args.before), ("after", args.after)):
            path = run_tree(tree, config, args.out / side, args.samples)
            print(f"| {stem} | {side} | " + " | ".join(_errors(path, reference)) + " |", flush=True)


if __name__ == "__main__":
    main()
