"""Light runs (issue 37, items 4 and 6): what ``[storage] histories`` stores, and the
warm end-to-end time of a slider-crank verdict, before and after, side by side.

1. **storage**: ``configs/slider-crank-requirement.toml`` at ``--store-samples`` (1,024)
   samples with ``histories = "all"``, ``"none"`` and ``"failed"`` (a ``[storage]`` table
   added to a copy of the file), in alternating order: the size of ``ensemble.nc``, the
   merge's seconds and bytes, and a check that every per-sample variable is bitwise the
   same in the three files (and that ``"failed"`` keeps exactly the samples that fail a
   requirement or carry a status flag).
2. **verdict**: ``mcchain run`` of the same scene at ``--verdict-samples`` (4,096), warm
   (each tree runs once first, unmeasured, so its kernels are cached), timed from the
   command's start to its exit: ``before`` is the tree of ``--before`` (a commit, exported
   with ``git archive``) running the shipped file; ``after all`` this tree with the same
   file; ``after none`` this tree with ``histories = "none"``. The variants alternate in
   each repeat; ratios are of medians; the load average is printed beside each run (the
   machine is shared).

    python benchmarks/bench_light.py                             # both parts
    python benchmarks/bench_light.py --parts verdict --repeats 5

Results (table and JSON, with the command) go to ``benchmarks/results/light/``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "configs" / "slider-crank-requirement.toml"
RESULTS = REPO / "benchmarks" / "results" / "light"
MODES = ("all", "none", "failed")


def scene_with(histories: str, folder: Path) -> Path:
    """A copy of the shipped scene with ``[storage] histories`` set (before ``[sample]``)."""
    text = SCENE.read_text(encoding="utf-8")
    head, sep, tail = text.partition("\n[sample]")
    assert sep, "the scene has a [sample] table"
    path = folder / f"slider-crank-{histories}.toml"
    path.write_text(f'{head}\n[storage]\nhistories = "{histories}"\n{sep}{tail}', "utf-8")
    return path


def mcchain_run(
    tree: Path, scene: Path, samples: int, run_dir: Path, extra: Sequence[str] = ()
) -> dict:
    """``mcchain run`` of ``tree`` as a user starts it (``extra``: more arguments); wall
    seconds, the child's user CPU seconds and run.json."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    command = [sys.executable, "-m", "mcchain.cli", "run", str(scene)]
    command += ["--samples", str(samples), "--run-dir", str(run_dir), *extra]
    load = os.getloadavg()[0]
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
    t0 = time.perf_counter()
    proc = subprocess.run(command, env=env, capture_output=True, text=True, cwd=tree)
    wall = time.perf_counter() - t0
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime - cpu0
    if proc.returncode not in (0, 1, 4):  # a verdict's exit codes are 0, 1 and 4... (run: 0)
        raise RuntimeError(f"{command}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    record = json.loads((run_dir / "run.json").read_text())
    return {
        "wall": wall,
        "cpu": cpu,
        "load": load,
        "timings": record["timings"],
        "merge": record.get("merge", {}),
        "bytes": (run_dir / "ensemble.nc").stat().st_size,
        "verdict": [line for line in proc.stdout.splitlines() if line.startswith("requirement")],
        "stdout": proc.stdout,
    }


def per_sample_bits(path: Path) -> dict[str, bytes]:
    """Bytes of every variable without a time axis (the per-sample ones and coordinates)."""
    import netCDF4

    out = {}
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        for name, var in nc.variables.items():
            if "time" in var.dimensions or "history_sample" in var.dimensions:
                continue
            values = np.asarray(var[:])
            out[name] = values.tobytes() if values.dtype.kind != "O" else repr(values).encode()
    return out


def check_modes(folders: dict[str, Path]) -> str:
    """Per-sample variables bitwise equal across the modes; the failed subset exact."""
    bits = {mode: per_sample_bits(folder / "ensemble.nc") for mode, folder in folders.items()}
    base = bits["all"]
    for mode in ("none", "failed"):
        if bits[mode] != base:
            differ = sorted(
                k for k in base.keys() | bits[mode].keys() if base.get(k) != bits[mode].get(k)
            )
            raise AssertionError(f"{mode}: per-sample variables differ from all: {differ}")
    import netCDF4

    with netCDF4.Dataset(folders["all"] / "ensemble.nc") as nc:
        status = np.asarray(nc["status"][:])
        met = np.asarray(nc["requirement_met"][:])
    with netCDF4.Dataset(folders["failed"] / "ensemble.nc") as nc:
        kept = np.asarray(nc["history_sample"][:])
    expected = np.flatnonzero((status != 0) | (met == 0).any(axis=1))
    assert np.array_equal(kept, expected), "failed: not the failing samples"
    return (
        f"per-sample variables ({len(base)}) bitwise identical in all three; "
        f'"failed" kept {kept.size} of {status.size} samples, exactly those that fail a '
        "requirement or carry a status flag"
    )


def storage_part(args: argparse.Namespace, work: Path) -> list[dict]:
    rows = []
    scenes = {mode: scene_with(mode, work) for mode in MODES}
    mcchain_run(REPO, scenes["none"], 64, work / "warm-store")  # kernels cached
    for r in range(args.repeats):
        order = MODES if r % 2 == 0 else MODES[::-1]
        folders = {}
        for mode in order:
            folder = work / f"store-{mode}-{r}"
            result = mcchain_run(REPO, scenes[mode], args.store_samples, folder)
            rows.append({"mode": mode, "repeat": r, **result})
            folders[mode] = folder
            print(
                f"  storage {mode:6s} repeat {r}: {result['bytes'] / 1e6:8.2f} MB, merge "
                f"{result['merge']['seconds']:.3f} s, load {result['load']:.2f}",
                flush=True,
            )
        if r == 0:
            rows.append({"check": check_modes(folders)})
        for folder in folders.values():
            shutil.rmtree(folder)
    return rows


def export_tree(commit: str, work: Path) -> Path:
    tree = work / f"tree-{commit[:10]}"
    tree.mkdir()
    archive = subprocess.run(
        ["git", "archive", commit], cwd=REPO, capture_output=True, check=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def verdict_part(args: argparse.Namespace, work: Path) -> list[dict]:
    before = export_tree(args.before, work)
    variants = {
        "before": (before, SCENE),
        "after all": (REPO, SCENE),
        "after none": (REPO, scene_with("none", work)),
    }
    for name, (tree, scene) in variants.items():  # warm: compile or load every kernel once
        mcchain_run(tree, scene, 64, work / f"warm-{name.replace(' ', '-')}")
    rows = []
    names = list(variants)
    for r in range(args.repeats):
        order = names[r % len(names) :] + names[: r % len(names)]
        for name in order:
            tree, scene = variants[name]
            folder = work / f"verdict-{name.replace(' ', '-')}-{r}"
            result = mcchain_run(tree, scene, args.verdict_samples, folder)
            rows.append({"variant": name, "repeat": r, **result})
            t = result["timings"]
            print(
                f"  verdict {name:10s} repeat {r}: {result['wall']:6.2f} s (compute "
                f"{t['compute']:.2f}, merge {t['merge']:.2f}, prepare {t['prepare']:.2f}), "
                f"{result['bytes'] / 1e6:.1f} MB, load {result['load']:.2f}",
                flush=True,
            )
            shutil.rmtree(folder)
    verdicts = {tuple(row["verdict"]) for row in rows}
    assert len(verdicts) == 1, "the variants printed different verdicts"
    return rows


def _loads(rows: list[dict]) -> str:
    return ", ".join(f"{r['load']:.1f}" for r in rows)


def _median(rows: list[dict], key, **where) -> float:
    values = [key(r) for r in rows if all(r.get(k) == v for k, v in where.items())]
    return statistics.median(values) if values else float("nan")


def table(storage: list[dict], verdict: list[dict], args: argparse.Namespace) -> str:
    lines = []
    if storage:
        lines += [
            f"### storage: {SCENE.name}, {args.store_samples} samples (median of the repeats)",
            "",
            "| histories | ensemble.nc (MB) | merge (s) | merge input (MB) | wall (s) | load |",
            "|---|---|---|---|---|---|",
        ]
        for mode in MODES:
            rows = [r for r in storage if r.get("mode") == mode]
            lines.append(
                f"| {mode} | {statistics.median(r['bytes'] for r in rows) / 1e6:.3f} | "
                f"{statistics.median(r['merge']['seconds'] for r in rows):.3f} | "
                f"{statistics.median(r['merge']['bytes_in'] for r in rows) / 1e6:.1f} | "
                f"{statistics.median(r['wall'] for r in rows):.2f} | "
                f"{_loads(rows)} |"
            )
        lines += ["", *(r["check"] for r in storage if "check" in r), ""]
    if verdict:
        lines += [
            f"### verdict: {SCENE.name}, {args.verdict_samples} samples, `mcchain run` end to "
            "end, warm (median of the repeats; each run's 1-minute load average)",
            "",
            "| variant | wall (s) | prepare | warmup | compute | merge | outside run.json "
            "total | ensemble.nc (MB) | loads |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for name in ("before", "after all", "after none"):
            rows = [r for r in verdict if r["variant"] == name]
            med = {
                k: statistics.median(r["timings"][k] for r in rows)
                for k in ("prepare", "warmup", "compute", "merge")
            }
            outside = statistics.median(r["wall"] - r["timings"]["total"] for r in rows)
            lines.append(
                f"| {name} | {statistics.median(r['wall'] for r in rows):.2f} | "
                f"{med['prepare']:.2f} | {med['warmup']:.2f} | {med['compute']:.2f} | "
                f"{med['merge']:.2f} | {outside:.2f} | "
                f"{statistics.median(r['bytes'] for r in rows) / 1e6:.1f} | "
                f"{_loads(rows)} |"
            )
        wall = {
            n: _median(verdict, lambda r: r["wall"], variant=n)
            for n in ("before", "after all", "after none")
        }
        lines += [
            "",
            f"ratios of medians: before / after none = {wall['before'] / wall['after none']:.2f}; "
            f"before / after all = {wall['before'] / wall['after all']:.2f}",
            "",
        ]
        # per repeat (same minute of the machine): the ratio of each pair
        pairs = []
        for r in sorted({row["repeat"] for row in verdict}):
            w = {row["variant"]: row["wall"] for row in verdict if row["repeat"] == r}
            pairs.append(f"{w['before'] / w['after none']:.2f}")
        lines.append(f"before / after none, repeat by repeat: {', '.join(pairs)}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="storage,verdict")
    parser.add_argument("--store-samples", type=int, default=1024)
    parser.add_argument("--verdict-samples", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--before", default="9dd0c92", help="commit of the 'before' tree")
    args = parser.parse_args()
    parts = set(args.parts.split(","))
    RESULTS.mkdir(parents=True, exist_ok=True)
    command = "python benchmarks/bench_light.py " + " ".join(sys.argv[1:])
    with tempfile.TemporaryDirectory(prefix="bench-light-") as tmp:
        work = Path(tmp)
        storage = storage_part(args, work) if "storage" in parts else []
        verdict = verdict_part(args, work) if "verdict" in parts else []
    text = table(storage, verdict, args)
    cores = os.cpu_count()
    when = time.strftime("%Y-%m-%d %H:%M")
    header = f"`{command}` ({cores} cores, {when}, before = {args.before})\n\n"
    print(header + text)
    stem = "_".join(sorted(parts))
    (RESULTS / f"{stem}.md").write_text(header + text + "\n", "utf-8")
    (RESULTS / f"{stem}.json").write_text(
        json.dumps({"command": command, "storage": storage, "verdict": verdict}, indent=1), "utf-8"
    )


if __name__ == "__main__":
    main()
