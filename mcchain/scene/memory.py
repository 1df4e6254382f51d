"""What a run will hold in memory, checked when its model is compiled, before anything is
allocated.

A run holds in memory, all at once: the sampled parameters and every model array a sampled
parameter makes per-sample (for every sample: the model is compiled whole), and the results
of one chunk of samples (the others are on disk). :func:`check_memory` estimates both from
the scene alone and refuses a run that cannot fit, so that ``count = 1e10`` is one line
instead of a 75 GiB allocation error. (What it writes on disk is checked before the run
folder is made: :mod:`mcchain.runner.resources`.)
"""

from __future__ import annotations

import os
from typing import Any

from mcchain.errors import SceneError

GIB = 2**30
HEADROOM = 0.8
"""Share of the available memory a run may plan to use (Python, numba and the OS need the rest)."""


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (``MemAvailable`` on Linux, else the
    free physical pages), or None when the system does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _per_sample_model_bytes(scene: Any) -> int:
    """Bytes per sample of the compiled model: the parameter table, and each model array a
    sampled path makes per-sample (the whole array, for every sample)."""
    from mcchain.parameters import PARAMETERS
    from mcchain.scene.paths import PARAM_SHAPES, parameter_slot, parse_path

    paths = list(scene.param_paths)
    counts = {
        "scene": 1,
        "body": len(scene.body),
        "joint": len(scene.joint),
        "driver": len(scene.driver),
        "force": len(scene.force),
        "spring": len(scene.spring),
    }
    fields: dict[str, int] = {}
    for path in paths:
        ref = parse_path(scene, path, PARAM_SHAPES)
        row = PARAMETERS[ref.kind, ref.key]
        name, _ = parameter_slot(ref)
        size = 1
        for n in row.field_shape(counts[ref.kind]):
            size *= n
        fields[name] = size
    # the parameter table, and the uniform draws and values of the design (float64 each)
    return 8 * (3 * len(paths) + sum(fields.values()))


def _per_sample_result_bytes(scene: Any) -> int:
    """Bytes per sample of one chunk's results (histories dominate)."""
    nbody, njoint, ndriver = len(scene.body), len(scene.joint), len(scene.driver)
    ndof = 3 * nbody
    total = 8 * (4 * ndof + ndof * ndof)  # start states, equilibrium, modes and shapes
    sim = scene.simulate
    if sim is not None:
        ntime = int(sim.t_end / sim.output_step) + 2
        per_time = 2 * ndof + 3 * njoint + ndriver + 2 + 2 * njoint  # q, v, forces, contact
        width = 4 if scene.storage.history_dtype == "float32" else 8
        total += ntime * per_time * (width + 8)  # float64 in the kernels, then the stored copy
    return total


def check_memory(scene: Any, nsample: int, count_name: str, chunk_size: int | None = None) -> None:
    """Raise :class:`SceneError` naming ``count_name`` when a run of ``nsample`` samples of
    ``scene`` would need more than :data:`HEADROOM` of the available memory."""
    available = available_memory()
    if available is None:
        return
    chunk = min(nsample, chunk_size or scene.storage.chunk_size)
    model = nsample * _per_sample_model_bytes(scene)
    results = chunk * _per_sample_result_bytes(scene)
    need = model + results
    if need <= HEADROOM * available:
        return
    raise SceneError(
        f"{count_name}: {nsample} samples need about {need / GIB:.3g} GiB (the sampled model "
        f"{model / GIB:.3g} GiB, one chunk of results {results / GIB:.3g} GiB), but this "
        f"machine has {available / GIB:.3g} GiB available: lower the count, or split the "
        "study into runs with different seeds"
    )
