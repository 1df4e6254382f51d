"""Runs at scale: wall time, instance-steps/s, share of time outside the kernels.

Issue 4's benchmark: the driven four-bar with a clearance joint (``configs/fourbar-clearance
.toml``, two crank turns), 10⁵ samples by default, run in-process and on a Dask
``LocalCluster`` side by side on this machine; then the merge alone, re-run on the kept
part files with each codec (zlib, zstd, none). The two runs must give identical files.

    python benchmarks/bench_runs.py                      # 10⁵ samples (long)
    python benchmarks/bench_runs.py --samples 4096 --chunk-size 512
    python benchmarks/bench_runs.py --modes in-process   # skip Dask

``outside kernels`` is 1 − kernel / (workers × (compute + merge)): the share of the chunk
loop and the merge spent in I/O, merging and Python rather than in ``solve_chunk`` (compile
and cluster start-up are reported apart, as ``warmup``).
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mcchain.ensemble.io import list_parts, merge_parts  # noqa: E402
from mcchain.runner import plan, runs  # noqa: E402

FOURBAR = REPO / "configs" / "fourbar-clearance.toml"


def _run(scene: Path, folder: Path, args: argparse.Namespace, dask: str | None) -> dict:
    t0 = time.perf_counter()
    result = plan.start_run(
        scene,
        samples=args.samples,
        chunk_size=args.chunk_size,
        run_dir=folder,
        dask=dask,
        threads=args.threads,
        argv=["bench_runs", dask or "in-process"],
        keep_parts=True,
        progress=args.progress,
    )
    wall = time.perf_counter() - t0
    r = result.record
    t = r["timings"]
    return {
        "mode": f"dask {dask}" if dask else "in-process",
        "samples": r["samples"],
        "threads": r["threads"],
        "wall": wall,
        "warmup": t["warmup"],
        "compute": t["compute"],
        "kernel": t["kernel"],
        "write": t["write"],
        "merge": t["merge"],
        "samples_per_s": r["throughput"]["samples_per_s"],
        "instance_steps_per_s": r["throughput"]["instance_steps_per_s"],
        "outside_kernels": r["throughput"]["outside_kernel_share"],
        "file_mb": (folder / runs.ENSEMBLE).stat().st_size / 1e6,
        "folder": str(folder),
    }


def _merge_codecs(folder: Path, nsample: int) -> list[dict]:
    parts = list_parts(folder / runs.PARTS)
    rows = []
    for codec in ("none", "zstd", "zlib"):
        out = folder / f"bench-merge-{codec}.nc"
        stats = merge_parts(parts, out, compression=codec, complevel=1, nsample=nsample)
        rows.append(
            {
                "codec": codec,
                "mb_in": stats.bytes_in / 1e6,
                "mb_out": stats.bytes_out / 1e6,
                "seconds": stats.seconds,
                "mb_per_s": stats.throughput,
            }
        )
        out.unlink()
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", type=Path, default=FOURBAR)
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--chunk-size", type=int, default=1024)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--modes", default="in-process,local", help="in-process,local,tcp://...")
    parser.add_argument("--workdir", type=Path, default=None, help="default: a temporary folder")
    parser.add_argument("--json", type=Path, default=None, help="also write the results here")
    parser.add_argument("--progress", action="store_true")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        results = []
        for mode in args.modes.split(","):
            dask = None if mode == "in-process" else mode
            folder = Path(tmp) / mode.replace("/", "_").replace(":", "_")
            print(f"running {mode} ...", file=sys.stderr, flush=True)
            results.append(_run(args.scene, folder, args, dask))
        files = [Path(r["folder"]) / runs.ENSEMBLE for r in results]
        identical = all(filecmp.cmp(files[0], f, shallow=False) for f in files[1:])
        codecs = _merge_codecs(Path(results[0]["folder"]), results[0]["samples"])

    print(f"scene {args.scene.name}, {args.samples} samples, chunks of {args.chunk_size}")
    print(
        f"{'mode':<14} {'thr':>3} {'wall s':>8} {'warm s':>7} {'comp s':>8} {'kern s':>8} "
        f"{'write s':>8} {'merge s':>8} {'samples/s':>10} {'inst-steps/s':>13} "
        f"{'outside':>8} {'file MB':>8}"
    )
    for r in results:
        steps = r["instance_steps_per_s"]
        print(
            f"{r['mode']:<14} {r['threads']:>3} {r['wall']:>8.2f} {r['warmup']:>7.2f} "
            f"{r['compute']:>8.2f} {r['kernel']:>8.2f} {r['write']:>8.2f} {r['merge']:>8.2f} "
            f"{r['samples_per_s']:>10.1f} {(f'{steps:.3g}' if steps else '-'):>13} "
            f"{r['outside_kernels']:>8.1%} {r['file_mb']:>8.1f}"
        )
    print(f"files identical across modes: {identical}")
    print("merge alone (same parts):")
    for c in codecs:
        print(
            f"  {c['codec']:<5} {c['mb_in']:>9.1f} MB -> {c['mb_out']:>9.1f} MB "
            f"in {c['seconds']:>7.2f} s = {c['mb_per_s']:>7.1f} MB/s"
        )
    if args.json:
        args.json.write_text(
            json.dumps({"runs": results, "identical": identical, "merge": codecs}, indent=2)
        )
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
