"""End to end with the real scene loader and solvers, through the command line.

``configs/clearance-bar.toml`` (equilibrium + modes) checks the stored values against the
clearance-bar quartic; ``configs/clearance-sweep.toml`` (the same bar, clearance and mass
sampled) makes every sample different, so a misplaced chunk could not go unnoticed when
runs are compared bit for bit.
"""

from __future__ import annotations

import filecmp
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_cli_commands import Ran
from test_runs_support import REPO, start_paused_child

from mcchain import open_run
from mcchain.ensemble.io import list_parts
from mcchain.ensemble.registry import validate_dataset
from mcchain.runner import runs
from mcchain.testing.closed_forms import G, clearance_bar_pulsations
from mcchain.testing.scenes import hanging_clearance_bar_text

pytestmark = pytest.mark.slow  # end to end through the CLI with real solvers, Dask and kills

CLEARANCE_BAR = REPO / "configs" / "clearance-bar.toml"
SWEEP = REPO / "configs" / "clearance-sweep.toml"

QUARTIC_RTOL = 1e-8
"""Stored eigenpulsations vs the closed form (the solver tests hold them to 1e-10)."""


def command(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "mcchain.cli", *map(str, args)]


def in_a_process(*args: str | Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``mcchain ARGS`` as a process of its own (``python -m mcchain.cli``): exit code 0.
    Where a claim needs no process of its own (an exit, a signal, a console), the tests
    run the command line in this process (conftest's ``mcchain``: :func:`mcchain.cli.main`),
    which saves the 1.5-2 s of CPU a process takes to import and load its kernels."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        command(*args), cwd=cwd, env=env, capture_output=True, text=True, timeout=900
    )
    assert proc.returncode == 0, proc.stderr
    return proc


def last_line(proc: subprocess.CompletedProcess[str] | Ran) -> Path:
    assert proc.returncode == 0, proc.stderr
    return Path(proc.stdout.splitlines()[-1])


def quartic_omega(mass: np.ndarray, clearance: np.ndarray) -> np.ndarray:
    """The clearance bar's two pulsations (1 m, J = 1/6 kg m² as in configs/)."""
    return clearance_bar_pulsations(mass, 1.0 / 6.0, 0.5, G, clearance)


def test_pipeline__run_clearance_bar_from_the_command_line(tmp_path: Path, mcchain) -> None:
    proc = mcchain("run", CLEARANCE_BAR, "--samples", "300", "--chunk-size", "64", cwd=tmp_path)
    folder = tmp_path / last_line(proc)
    # No progress bar when stderr is not a terminal: nothing but, on a cold cache, the
    # compile notice (mcchain.compiled.ready), whichever test ran first.
    notice = ("compiling the kernels of this scene", "kernels ready in ")
    assert [line for line in proc.stderr.splitlines() if not line.startswith(notice)] == []
    assert folder.parent == tmp_path / "runs" and folder.name.endswith("-clearance-bar")
    record = json.loads((folder / "run.json").read_text())
    assert record["status"] == "COMPLETED" and record["chunks"] == 5
    assert record["status_counts"]["ok"] == 300
    assert (folder / "scene.toml").read_bytes() == CLEARANCE_BAR.read_bytes()
    with open_run(str(folder)) as ds:
        validate_dataset(ds)
        assert set(ds.data_vars) >= {"q_eq", "joint_force_eq", "stable", "omega", "status"}
        assert "q" not in ds and "time" not in ds.dims  # no [simulate]: no histories
        expected = quartic_omega(np.array(2.0), np.array(1e-3))
        np.testing.assert_allclose(
            ds.omega.values, np.broadcast_to(expected, (300, 2)), rtol=QUARTIC_RTOL
        )
        assert bool(ds.stable.all())
        # The journal hangs straight below the pin: d along -y, |d| = c.
        np.testing.assert_allclose(ds.q_eq.sel(dof="theta").values, -np.pi / 2, atol=1e-9)
        assert ds.attrs["scene"] == CLEARANCE_BAR.read_text()
    listing = mcchain("runs", cwd=tmp_path)
    assert listing.returncode == 0
    assert folder.name in listing.stdout and "ok=300" in listing.stdout


def test_pipeline__the_console_exit_loses_nothing(tmp_path: Path) -> None:
    """The command line ends with ``os._exit`` after the exit handlers (the interpreter's
    teardown took 0.3-0.4 s): the log ends with the run's last line, stdout with the run
    folder, and bad input still exits 2 with its message."""
    proc = in_a_process("run", SWEEP, "--samples", "40", "--chunk-size", "16", cwd=tmp_path)
    folder = tmp_path / last_line(proc)
    assert (folder / "ensemble.nc").is_file()
    assert "run completed" in (folder / "run.log").read_text().splitlines()[-1]
    bad = subprocess.run(
        command("validate", tmp_path / "missing.toml"), cwd=tmp_path, capture_output=True,
        text=True, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=300,
    )  # fmt: skip
    assert bad.returncode == 2 and bad.stderr.startswith("mcchain: error:")
    assert "missing.toml: no such file" in bad.stderr and bad.stdout == ""


def test_pipeline__identical_files_in_process_any_chunks_threads_and_dask(
    tmp_path: Path, mcchain, dask_scheduler: str
) -> None:
    """``mcchain run`` (the command line, in this process) in one chunk, in small chunks
    on 2 threads, on a Dask cluster it starts (``--dask local``: two process workers) and
    on an existing scheduler reached by its tcp:// address (conftest's ``dask_scheduler``):
    the same file, byte for byte."""
    assert dask_scheduler.startswith("tcp://")
    variants = {
        "one-chunk": ["--chunk-size", "1000", "--threads", "1"],
        "small-chunks": ["--chunk-size", "96", "--threads", "2"],
        "dask-local": ["--chunk-size", "128", "--dask", "local", "--threads", "2"],
        "dask-tcp": ["--chunk-size", "200", "--dask", dask_scheduler],
    }
    files = {}
    for name, extra in variants.items():
        folder = tmp_path / name
        proc = mcchain("run", SWEEP, "--samples", "1000", "--run-dir", folder, *extra, cwd=tmp_path)
        assert last_line(proc) == folder
        files[name] = folder / "ensemble.nc"
    record = runs.read_record(tmp_path / "dask-local")
    assert record["scheduler"] == "dask local" and record["threads"] == 2
    assert len(record["workers"]) == 2
    assert all(w["numba_threads"] == 1 for w in record["workers"])
    assert len({w["pid"] for w in record["workers"]}) == 2
    assert runs.read_record(tmp_path / "small-chunks")["threads"] == 2
    tcp = runs.read_record(tmp_path / "dask-tcp")
    assert tcp["scheduler"].startswith("dask tcp://") and len(tcp["workers"]) == 2
    for name in ("small-chunks", "dask-local", "dask-tcp"):
        assert filecmp.cmp(files["one-chunk"], files[name], shallow=False), name
    with open_run(str(tmp_path / "one-chunk")) as ds:
        params = ds.parameters.values
        assert len(np.unique(params[:, 0])) == 1000  # every sample differs
        clearance, mass = params[:, 0], params[:, 1]
        np.testing.assert_allclose(
            ds.omega.values, quartic_omega(mass, clearance), rtol=QUARTIC_RTOL
        )


def test_pipeline__sigkill_then_resume_equals_an_uninterrupted_run(tmp_path: Path, mcchain) -> None:
    """A run killed (SIGKILL, a process of its own) after 3 parts: the parts it wrote are
    whole, ``mcchain runs`` calls it interrupted, the resume (the command line, here)
    completes it to the file of an uninterrupted run."""
    target = tmp_path / "killed"
    args: list[str | Path] = ["run", SWEEP, "--samples", "120", "--chunk-size", "4"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = start_paused_child(
        ["cli", *map(str, args), "--run-dir", str(target)],
        target / "parts",
        after_parts=3,
        env=env,
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    child.send_signal(signal.SIGKILL)
    child.wait()

    assert runs.read_record(target)["status"] == "RUNNING"
    listing = mcchain("runs", "--out", tmp_path, cwd=tmp_path).stdout
    assert "killed" in listing and "INTERRUPTED" in listing
    assert not (target / "ensemble.nc").exists()
    done = list_parts(target / "parts")
    assert 3 <= len(done) <= 5
    for part in done:  # every visible part is complete
        with xr.open_dataset(part.path) as ds:
            validate_dataset(ds)
            assert ds.sizes["sample"] == 4 and int(ds.sample[0]) == part.start
    with open_run(str(target)) as partial:
        finished = sorted(i for p in done for i in range(p.start, p.stop))
        assert list(partial.sample.values) == finished
        partial_values = partial.load()

    resumed = mcchain("run", "--resume", target, cwd=tmp_path)
    assert last_line(resumed) == target
    record = runs.read_record(target)
    assert record["status"] == "COMPLETED" and len(record["sessions"]) == 2
    assert record["sessions"][1]["chunks_computed"] == 30 - len(done)
    assert record["sessions"][1]["argv"][-2:] == ["--resume", str(target)]

    reference = tmp_path / "reference"
    assert last_line(mcchain(*args, "--run-dir", reference, "--chunk-size", "120", cwd=tmp_path))
    assert filecmp.cmp(target / "ensemble.nc", reference / "ensemble.nc", shallow=False)
    with open_run(str(target)) as a, open_run(str(reference)) as b:
        xr.testing.assert_identical(a.load(), b.load())
        xr.testing.assert_identical(partial_values, b.sel(sample=finished).load())


# Released at rest from a sampled angle (assembly seats the journal): every sample solves
# at the scene's step. A sampled angular velocity (the centre of mass left at rest) had the
# journal whirl round its 0.1-1 mm link at about v / c = 10³ rad/s: 99 % of the samples
# diverged and were solved again at dt / 10 or dt / 100 (twice the CPU of the whole test).
SWING = (
    hanging_clearance_bar_text("clearance-bar-swing")
    + """
[sample]
count = 100000
seed = 7
[sample.vary]
"joint.O.clearance" = { uniform = [1e-4, 1e-3] }
"body.bar.angle" = { uniform = [-1.9, -1.2] }

[simulate]
t_end = 0.1
dt = 5e-4
output_dt = 5e-4
method = "rk4"

[storage]
compression = "zstd"
"""
)

REAL_MEMORY_SCRIPT = """
import json, resource, sys
from pathlib import Path
import netCDF4, numpy, xarray, tqdm
from mcchain.runner import plan, runs
def peak():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
tmp, scene, chunk = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
medium, big = int(sys.argv[4]), int(sys.argv[5])
peaks = {"imports": peak()}
for name, n in (("warm", 2 * chunk), ("medium", medium), ("big", big)):
    result = plan.start_run(scene, samples=n, chunk_size=chunk, out=tmp / name, progress=False)
    peaks[name] = peak()
with runs.open_run(result.folder) as ds:
    sizes = {"time": ds.sizes["time"], "nbytes": int(ds.nbytes)}
ok = result.record["status_counts"]["ok"]
print(json.dumps({**peaks, **sizes, "ok": ok, "merge": result.record["merge"]}))
"""


@pytest.mark.slow
@pytest.mark.parametrize(
    ("medium", "big"),
    [
        # Two merge windows (2 x 8,192 samples: the merge's blocks and its 16 open parts
        # reached) then twice as many: the ensemble grows by 139 MiB, the peak may grow by
        # 10 MiB. 11 s of CPU in the subprocess.
        pytest.param(16_384, 32_768, id="32768"),
        # The same at 10⁵ samples (25 s of CPU): the ensemble (849 MiB) also dwarfs the
        # chunk bound itself.
        pytest.param(20_000, 100_000, id="1e5", marks=pytest.mark.long),
    ],
)
def test_memory__real_sample_run_with_histories_is_bounded_by_the_chunk(
    tmp_path: Path, medium: int, big: int
) -> None:
    """The swinging clearance bar (RK4, 200 steps, one stored each: the bytes are what the
    bound is about, not the steps; float32) run at 2 chunks, ``medium`` and ``big``
    samples in 500-sample chunks: the peak RSS (measured in a subprocess) grows with the
    chunk, not with the ensemble. The same bound with the fake solver was a second test;
    this one, with the real kernels, covers it."""
    scene = tmp_path / "swing.toml"
    scene.write_text(SWING)
    chunk = 500
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    args = [str(tmp_path), str(scene), str(chunk), str(medium), str(big)]
    proc = subprocess.run(
        [sys.executable, "-c", REAL_MEMORY_SCRIPT, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stderr
    m = json.loads(proc.stdout.strip().splitlines()[-1])
    assert m["ok"] == big  # every sample solved as written: 200 steps each
    ensemble_bytes = m["nbytes"]
    chunk_bytes = ensemble_bytes * chunk // big
    # Past the compile (the "warm" run): solver work arrays and float64 outputs of a chunk,
    # one chunk waiting for the writer, the merge's 16 MiB blocks and <= 16 open parts.
    bound = 28 * chunk_bytes + 96 * 2**20
    # From medium to big only what a sample keeps in memory (its row of the run's record
    # and the design, well under 128 bytes), beside allocator noise.
    growth = 8 * 2**20 + 128 * (big - medium)
    ensemble_growth = ensemble_bytes * (big - medium) // big
    print(
        f"peak above the warm run {(m['big'] - m['warm']) / 2**20:.0f} MiB "
        f"(bound {bound / 2**20:.0f} MiB), from medium to big "
        f"{(m['big'] - m['medium']) / 2**20:.1f} MiB (bound {growth / 2**20:.1f} MiB, the "
        f"ensemble {ensemble_growth / 2**20:.0f} MiB), ensemble {ensemble_bytes / 2**20:.0f} MiB, "
        f"compile etc. {(m['warm'] - m['imports']) / 2**20:.0f} MiB, "
        f"merge {m['merge']['mb_per_s']:.0f} MB/s"
    )
    # a run that held its ensemble would pass neither bound: it would grow by at least the
    # ensemble's growth from medium to big, and by the ensemble above the warm run
    assert growth < ensemble_growth / 10
    assert bound < ensemble_bytes / (3 if big >= 100_000 else 1)
    assert m["big"] - m["warm"] < bound
    assert m["big"] - m["medium"] < growth


def test_pipeline__ctrl_c_keeps_finished_chunks_and_resumes(tmp_path: Path, mcchain) -> None:
    """Ctrl-C (SIGINT to a process of its own) after 2 parts: exit 130, one line naming the
    folder and the command that completes it, the parts kept; ``mcchain runs`` and the
    resume (the command line, here) complete it."""
    target = tmp_path / "interrupted"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    samples = 40
    child = start_paused_child(
        [
            "cli",
            "run",
            str(SWEEP),
            "--samples",
            str(samples),
            "--chunk-size",
            "4",
            "--run-dir",
            str(target),
        ],
        target / "parts",
        after_parts=2,
        env=env,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # As in a terminal: a shell's background job (e.g. CI started with `&`) runs with
        # SIGINT ignored, and Python then never raises KeyboardInterrupt.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    child.send_signal(signal.SIGINT)
    _, stderr = child.communicate(timeout=120)
    assert child.returncode == 130, stderr
    assert stderr.strip().splitlines()[-1] == (
        f"mcchain: interrupted; run folder: {target} "
        f"(complete it with: mcchain run --resume {target})"
    )
    record = runs.read_record(target)
    assert record["status"] == "FAILED" and record["error"] == "interrupted"
    done = list_parts(target / "parts")
    assert done and not (target / "ensemble.nc").exists()
    assert "FAILED" in mcchain("runs", "--out", tmp_path, cwd=tmp_path).stdout
    assert last_line(mcchain("run", "--resume", target, cwd=tmp_path)) == target
    record = runs.read_record(target)
    assert record["status"] == "COMPLETED" and record["status_counts"]["samples"] == samples
