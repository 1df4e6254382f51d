"""What a run will write on disk, checked before anything is written.

(What it holds in memory is checked when its model is compiled: :mod:`mcchain.scene.memory`.)

A run writes uncompressed part files and merges them into ``ensemble.nc``, which
holds the parts and the merged file at once: :func:`estimate_disk` counts that peak from
the scene and the model (:class:`DiskEstimate`), and :func:`check_disk` refuses a run, or
its resume, whose peak exceeds the free space of the run folder's file system, so that
``output_dt = dt = 1e-7`` on 1e5 samples is one line instead of a full disk.

Imported when a run is prepared (it imports numpy with the variable registry).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcchain.ensemble.histories import is_history
from mcchain.ensemble.registry import VARIABLES
from mcchain.errors import RunError

FILE_OVERHEAD_BYTES = 64 * 1024
"""netCDF/HDF5 bytes per file beside the data (headers, B-trees, name coordinates), not
counting the scene text its attributes hold twice (as written, and resolved): the part
files of the shipped scenes carry 28-60 kB with the text; counted as 64 kB + twice the
text per part file and for ``ensemble.nc``."""


def stored_sample_bytes(scene: Any, model: Any) -> int:
    """Bytes per sample of the variables a run of ``scene`` stores, uncompressed: what each
    part file holds per sample (``model`` gives the sizes of the dims: bodies, joints,
    drivers, modes, sampled paths; ``[simulate]`` the output times, from
    :func:`mcchain.solvers.grid.output_times`). Mirrors what
    :func:`mcchain.solvers.solve_chunk` returns and ``[storage] histories`` keeps of it:
    nothing of the histories with ``"none"``; all of them with ``"failed"``, an upper bound
    (every sample may fail). Tests compare it with real part files."""
    nmode = max(int(model.nmode), 0)
    along = getattr(scene.modes, "along", None) if scene.modes is not None else None
    sizes = {
        "sample": 1,
        "body": int(model.nbody),
        "dof": 3,
        "joint": int(model.njoint),
        "xy": 2,
        "mode": nmode,
        "param": len(model.param_paths),
        "driver": int(model.ndriver),
        "phase": 0 if along is None else int(along.points),
        "time": 0,
    }
    statics = scene.equilibrium is not None or scene.modes is not None
    stored = {"parameters", "status"}
    if statics:
        stored |= {"q_eq", "joint_force_eq", "iterations", "stable"}
        stored |= {"joint_moment_eq"} if model.has_prismatic else set()
    if scene.modes is not None:
        stored |= {"omega", "damped_omega", "damping_ratio"}
        stored |= {"mode_shape"} if scene.modes.shapes else set()
        stored |= {"omega_cycle"} if along is not None else set()
    sim = scene.simulate
    if sim is not None:
        from mcchain.solvers.grid import output_times

        sizes["time"] = len(output_times(sim).time)
        stored |= {
            spec.name
            for spec in VARIABLES.values()
            if spec.analysis == "simulate"
            and spec.name not in ("joint_moment", "driver_force", "peak_driver_force")
            and (model.has_contact or spec.name not in _CONTACT_OUTPUTS)
            and (spec.name != "solved_by" or getattr(sim, "retry_failed", False))
        }
        stored |= {"joint_moment"} if model.has_prismatic else set()
        stored |= {"driver_force", "peak_driver_force"} if model.has_slider_drivers else set()
    histories = getattr(scene.storage, "histories", "all")
    total = 8  # the int64 sample coordinate
    if histories == "failed" and sim is not None:
        total += 8  # the int64 history_sample coordinate, should the sample's be kept
    for name in stored:
        spec = VARIABLES[name]
        if histories == "none" and is_history(spec.dims):
            continue  # "failed" keeps a sample's histories when it fails: counted (a bound)
        count = 1
        for dim in spec.dims:
            count *= sizes[dim]
        total += count * spec.storage_dtype(scene.storage.history_dtype).itemsize
    return total


_CONTACT_OUTPUTS = frozenset(
    {
        "penetration",
        "contact_mode",
        "peak_contact_force",
        "impact_count",
        "max_penetration",
        "free_flight_time",
        "first_separation_time",
    }
)
"""The variables only a model with a contact law stores."""


@dataclass(frozen=True)
class DiskEstimate:
    """What a run writes, in bytes, before any chunk runs.

    Part files are uncompressed; the merge streams them into ``ensemble.nc`` and deletes
    them only once it is complete, so the run's peak on disk is every part file plus the
    merged file. The merged file is counted uncompressed too: an upper bound (compression
    gains depend on the data), so that a run refused is one that might not fit.
    """

    nsample: int
    chunk_size: int
    sample_bytes: int
    file_bytes: int

    def parts(self, samples: int | None = None) -> int:
        """Bytes of the part files holding ``samples`` samples (default all)."""
        n = self.nsample if samples is None else samples
        return n * self.sample_bytes + -(-n // self.chunk_size) * self.file_bytes

    @property
    def merged(self) -> int:
        """Bytes of ``ensemble.nc`` at most."""
        return self.nsample * self.sample_bytes + self.file_bytes

    def peak(self, samples: int | None = None) -> int:
        """Bytes still to be written, at the merge's peak, when ``samples`` samples are yet
        to be computed (default all): their part files and the merged file."""
        return self.parts(samples) + self.merged

    def line(self) -> str:
        """The line of ``mcchain validate``: the peak and its parts."""
        samples = f"{self.nsample} sample{'' if self.nsample == 1 else 's'}"
        return (
            f"disk: a run of {samples} writes up to {size_text(self.peak())} at "
            f"its merge (part files {size_text(self.parts())} + ensemble.nc up to "
            f"{size_text(self.merged)}; {size_text(self.sample_bytes)} per sample uncompressed)"
        )


def size_text(nbytes: float) -> str:
    """Bytes for a person: ``812 kB``, ``1.53 GB``, ``8.4 TB`` (decimal units, 3 digits)."""
    value = float(nbytes)
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if abs(value) < 1000 or unit == "TB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.3g} {unit}"
        value /= 1000
    raise AssertionError("unreachable")


def estimate_disk(scene: Any, model: Any, nsample: int, chunk_size: int) -> DiskEstimate | None:
    """The :class:`DiskEstimate` of a run of ``nsample`` samples in chunks of ``chunk_size``;
    None for a scene that is not a :class:`mcchain.scene.models.Scene` (the tests' fakes)."""
    from mcchain.scene.models import Scene

    if not isinstance(scene, Scene):
        return None
    text = len((scene.text or "").encode("utf-8"))
    return DiskEstimate(
        nsample=int(nsample),
        chunk_size=max(int(chunk_size), 1),
        sample_bytes=stored_sample_bytes(scene, model),
        file_bytes=FILE_OVERHEAD_BYTES + 2 * text,  # the scene text, as it is and resolved
    )


def free_space(path: Any) -> tuple[int, Path]:
    """Free bytes (for this user) of the file system that holds ``path``, or would hold it:
    the nearest folder of ``path`` that exists; and that folder."""
    folder = Path(path)
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return shutil.disk_usage(folder).free, folder


def check_disk(
    estimate: DiskEstimate | None, folder: Any, samples: int | None = None, retry: str = ""
) -> None:
    """Raise :class:`RunError` when the bytes a run still writes (its ``samples`` samples
    yet to compute, default all, and the merge) exceed the free space of ``folder``'s file
    system; ``folder`` is the run folder, or where it will be made. ``retry`` names what to
    do again once there is room (``"resume"``, ``"extend"``) for a run that exists."""
    if estimate is None:
        return
    need = estimate.peak(samples)
    free, where = free_space(folder)
    if need <= free:
        return
    n = estimate.nsample if samples is None else samples
    parts = f"part files of {n} samples {size_text(estimate.parts(samples))} + " if n else ""
    hint = (
        f"free space, then {retry}"
        if retry
        else "lower the count, store fewer times ([simulate] output_dt) or float32 histories, "
        "or write elsewhere (--out, --run-dir)"
    )
    raise RunError(
        f"disk: the run needs up to {size_text(need)} more at its merge ({parts}ensemble.nc "
        f"up to {size_text(estimate.merged)}), but {where} has {size_text(free)} free: {hint}"
    )
