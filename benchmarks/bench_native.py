"""The generated lanes compiled two ways: straight to LLVM (``mcchain.codegen.native``, the
default) against numba's ``@njit`` of the same text (``MCCHAIN_LANE_COMPILER=numba``).

For each scene, with each compiler, side by side:

* **compile**: a first run of the topology (a fresh generated-code cache; numba's cache
  holds every other kernel, warmed by a run before), ``warmup`` of its ``run.json``;
* **lanes**: a warm run of ``--samples`` instances on one thread, ``kernel`` of its
  ``run.json`` (the best of ``--rounds``, the two compilers alternating, so both see the
  same machine load), in ns per instance-step;
* **values**: how far apart the two ensembles are: the largest difference of any variable,
  relative to that variable's largest magnitude (0: the same bits; NaN must fall at the same
  places).

    python benchmarks/bench_native.py [--quick] [--rounds 3] [--samples 256]

``--quick`` leaves out the 32-bar chain (numba compiles its lanes for about a minute).
Writes ``benchmarks/results/native/native.md`` and ``native.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "benchmarks" / "results" / "native"
sys.path.insert(0, str(REPO))

from mcchain.testing.factory import chain_scene_text  # noqa: E402

COMPILERS = ("numba", "native")


def _scenes(folder: Path, quick: bool) -> dict[str, tuple[Path, int]]:
    """Scene files by row name, with their sample count (0: ``--samples``)."""
    configs = REPO / "configs"
    pendulum = (configs / "double-pendulum.toml").read_text()
    radau = folder / "double-pendulum-radau.toml"
    radau.write_text(
        pendulum.replace('"double-pendulum"', '"dp-radau"').replace('"rk4"', '"radau"')
    )
    fourbar = (configs / "fourbar-clearance.toml").read_text()
    link = folder / "fourbar-link.toml"
    link.write_text(
        fourbar.replace('model = "auto"', 'model = "link"')
        .replace('method = "rk45"', 'method = "rk4-projection"')
        .replace('"fourbar-clearance"', '"fourbar-link"')
    )
    rows = {
        "double pendulum (rk4)": (configs / "double-pendulum.toml", 0),
        "double pendulum (radau: accel)": (radau, 16),  # scipy's loop per instance
        "four-bar, link (rk4-projection)": (link, 0),
        "four-bar, contact law (rk45)": (configs / "fourbar-clearance.toml", 0),
    }
    if not quick:
        chain = folder / "chain32.toml"
        chain.write_text(
            chain_scene_text(
                32, (), seed=1, equilibrium=False, modes=False,
                simulate={"t_end": 0.05, "dt": 1e-4, "output_dt": 1e-2, "method": "rk4"},
            ).replace("[simulate]", '[simulate]\nkernels = "lanes"')
        )  # fmt: skip
        rows["32-bar chain (rk4)"] = (chain, 0)
    return rows


def _run(scene: Path, env: dict[str, str], out: Path, samples: int, threads: int = 1) -> dict:
    """``run.json`` of one ``mcchain run`` in a fresh process, and its ensemble's path."""
    out.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "mcchain.cli", "run", str(scene), "--out", str(out)]
    cmd += ["--quiet", "--samples", str(samples), "--threads", str(threads)]
    before = set(out.iterdir())
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr[-2000:]}")
    (folder,) = set(out.iterdir()) - before
    record = json.loads((folder / "run.json").read_text())
    record["folder"] = str(folder)
    return record


def _largest_difference(a: Path, b: Path) -> tuple[float, str]:
    """The largest difference between two ensembles' variables, relative to the variable's
    largest magnitude, and that variable's name (inf: NaN at different places, or other
    values differ)."""
    import xarray as xr

    worst, where = 0.0, ""
    with xr.open_dataset(a / "ensemble.nc") as x, xr.open_dataset(b / "ensemble.nc") as y:
        for name in x.data_vars:
            u, v = x[name].values, y[name].values
            if u.dtype.kind != "f":
                gap = 0.0 if np.array_equal(u, v) else np.inf
            elif not np.array_equal(np.isnan(u), np.isnan(v)):
                gap = np.inf
            else:
                u, v = np.nan_to_num(u, nan=0.0), np.nan_to_num(v, nan=0.0)
                scale = np.abs(u).max(initial=0.0)
                gap = float(np.abs(u - v).max(initial=0.0) / scale) if scale > 0 else 0.0
            if gap > worst:
                worst, where = gap, str(name)
    return worst, where


def measure(rows: dict[str, tuple[Path, int]], work: Path, samples: int, rounds: int) -> dict:
    base = dict(os.environ)
    base.pop("MCCHAIN_INTERPRET_COLD", None)
    base.update(MCCHAIN_COMPILE_AHEAD="0", NUMBA_CACHE_DIR=str(work / "numba"))
    results: dict[str, dict] = {}
    for name, (scene, count) in rows.items():
        row: dict = {}
        # every kernel but the lanes in numba's cache (the scene's statics, checks, loop)
        warm = dict(base, MCCHAIN_CACHE_DIR=str(work / "warmup"))
        _run(scene, warm, work / "runs", 4)
        for compiler in COMPILERS:
            env = dict(base, MCCHAIN_LANE_COMPILER=compiler)
            env["MCCHAIN_CACHE_DIR"] = tempfile.mkdtemp(prefix=f"cold-{compiler}-", dir=work)
            cold = _run(scene, env, work / "runs", 4)
            row[f"compile {compiler}"] = cold["sessions"][-1]["timings"]["warmup"]
            row[f"env {compiler}"] = env
            print(f"  {name}, {compiler}: compile {row[f'compile {compiler}']:.2f} s", flush=True)
        best = {c: np.inf for c in COMPILERS}
        folders = {}
        for _ in range(rounds):
            for compiler in COMPILERS:
                record = _run(scene, row[f"env {compiler}"], work / "runs", count or samples)
                session = record["sessions"][-1]
                steps = session["samples_computed"] * record["throughput"]["steps_per_sample"]
                best[compiler] = min(best[compiler], session["timings"]["kernel"] / steps * 1e9)
                folders[compiler] = Path(record["folder"])
        for compiler in COMPILERS:
            row[f"lanes {compiler}"] = best[compiler]
            del row[f"env {compiler}"]
        row["difference"] = _largest_difference(folders["numba"], folders["native"])
        print(f"  {name}: lanes {best}, difference {row['difference']}", flush=True)
        results[name] = row
    return results


def _table(results: dict, samples: int, rounds: int) -> str:
    lines = [
        "# Lane kernels: numba's `@njit` against `mcchain.codegen.native`, side by side",
        "",
        f"`python benchmarks/bench_native.py --samples {samples} --rounds {rounds}`, 2 cores. "
        "Compile: the first run of the topology, numba's cache warm for every other kernel. "
        f"Lanes: {samples} instances (radau: 16) on one thread, best of {rounds} alternating "
        "runs, ns per nominal instance-step (t_end / dt; rk45 adapts its steps, radau calls "
        "the accelerations from scipy). Difference: the largest of any variable between the "
        "two ensembles, relative to that variable's largest magnitude (0: the same bits, NaN "
        "at the same places).",
        "",
        "| scene | compile numba, s | compile native, s | × | lanes numba, ns | "
        "lanes native, ns | native / numba | difference |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, r in results.items():
        lines.append(
            f"| {name} | {r['compile numba']:.2f} | {r['compile native']:.2f} | "
            f"{r['compile numba'] / r['compile native']:.1f}× | {r['lanes numba']:.0f} | "
            f"{r['lanes native']:.0f} | {r['lanes native'] / r['lanes numba']:.2f} | "
            f"{_difference_text(*r['difference'])} |"
        )
    return "\n".join(lines) + "\n"


def _difference_text(gap: float, name: str) -> str:
    return "0 (same bits)" if gap == 0 else f"{gap:.1e} ({name})"


def _chart(results: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    y = np.arange(len(names))
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 0.6 * len(names) + 1.8), sharey=True)
    for k, compiler in enumerate(COMPILERS):
        left.barh(y + 0.2 - 0.4 * k, [results[n][f"compile {compiler}"] for n in names], 0.4,
                  label=compiler)  # fmt: skip
        right.barh(y + 0.2 - 0.4 * k, [results[n][f"lanes {compiler}"] for n in names], 0.4,
                   label=compiler)  # fmt: skip
    left.set_yticks(y, names)
    left.invert_yaxis()
    left.set_xlabel("first run of the topology: lane compile, s")
    right.set_xlabel("lanes, ns per instance-step (one thread)")
    left.legend(loc="upper right")
    fig.suptitle("Lane kernels: numba @njit against mcchain.codegen.native (same text)")
    fig.tight_layout()
    fig.savefig(OUT / "native.png", dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-native-") as tmp:
        work = Path(tmp)
        results = measure(_scenes(work, args.quick), work, args.samples, args.rounds)
    table = _table(results, args.samples, args.rounds)
    print(table)
    (OUT / "native.md").write_text(table)
    _chart(results)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
