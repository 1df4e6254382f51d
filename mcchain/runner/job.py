"""The job of a run: the scene, its compiled model and the resolved settings.

:func:`prepare_job` loads, compiles and checks a scene and writes nothing; the
:class:`Job` it returns is everything a run computes from, independent of how (chunk size,
threads, scheduler) it is executed. :func:`resolved_settings` is what ``ensemble.nc``
stores of the settings, and :meth:`Job.attributes` its global attributes.

This module imports only the standard library at import time; the scene module and the
statics checks are imported by :func:`default_loader`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mcchain import __version__
from mcchain.errors import RunError, check_positive

if TYPE_CHECKING:
    from mcchain.model import Model
    from mcchain.runner.resources import DiskEstimate

Loader = Callable[[Path, "int | None", "int | None"], tuple[Any, "Model"]]
"""``loader(scene_path, samples, seed) -> (scene, model)``; raises ``SceneError``."""


@dataclass
class Job:
    """Everything a run computes from, independent of how it is executed.

    Attributes:
        scene: the validated scene (``mcchain.scene.Scene``).
        model: the compiled model of all samples.
        scene_text: the scene file's text (copied to ``scene.toml``, stored in attributes).
        scene_name: ``[scene] name``.
        nsample: number of samples.
        seed: sampling seed (``None`` without ``[sample]``).
        chunk_size: samples per chunk (execution only: never changes the data).
        history_dtype, compression, complevel: ``[storage]`` settings.
        histories: ``[storage] histories``: which time histories are stored
            (:mod:`mcchain.ensemble.histories`).
        disk: what the run writes (:class:`mcchain.runner.resources.DiskEstimate`; ``None`` for a
            scene that is not a real one, the tests' fakes).
        settings: resolved settings stored in ``ensemble.nc`` (no execution details).
        warnings: lines about the scene as written, e.g. a written position that assembly
            moved (:func:`mcchain.solvers.statics.initial_state_warnings`).
        notes: lines about choices made for the user, e.g. the loop kernels that
            ``[simulate] kernels = "auto"`` took (:func:`resolve_kernels`).
        kernels: the path that integrates the time histories (``[simulate] kernels``,
            resolved), None without ``[simulate]``.
    """

    scene: Any
    model: Model
    scene_text: str
    scene_name: str
    nsample: int
    seed: int | None
    chunk_size: int
    history_dtype: str
    compression: str
    complevel: int
    disk: DiskEstimate | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    kernels: str | None = None
    histories: str = "all"

    def resized(self, nsample: int) -> Job:
        """The same job with ``nsample`` samples (a run that ``--extend`` or ``until`` grew):
        the model is kept (it must hold at least ``nsample`` samples), the settings follow."""
        if nsample > self.model.nsample:
            raise ValueError(f"nsample: the model holds {self.model.nsample}, asked {nsample}")
        settings = {**self.settings, **resolved_settings(self.scene, nsample, self.seed)}
        return replace(self, nsample=int(nsample), settings=settings)

    def with_solved_histories(self) -> Job:
        """The same job whose solver computes every time history even where ``[storage]
        histories = "none"`` stores none (``histories`` is kept: the store drops them): a
        ``--rerun`` stream shows the histories of its samples. Without ``"none"``: itself."""
        storage = getattr(self.scene, "storage", None)
        if getattr(storage, "histories", "all") != "none":
            return self
        assert storage is not None
        solved = storage.model_copy(update={"histories": "all"})
        return replace(self, scene=self.scene.model_copy(update={"storage": solved}))

    def attributes(self, versions: Mapping[str, str]) -> dict[str, Any]:
        """Global attributes of ``ensemble.nc`` (and of every part file)."""
        return {
            "Conventions": "CF-1.10",
            "title": f"mcchain ensemble of scene {self.scene_name}",
            "source": f"mcchain {__version__}",
            "scene_name": self.scene_name,
            "scene": self.scene_text,
            "settings": json.dumps(self.settings, sort_keys=True),
            "seed": "none" if self.seed is None else int(self.seed),
            "sample_count": int(self.nsample),
            "mcchain_version": __version__,
            "versions": json.dumps(dict(versions), sort_keys=True),
        }


def default_loader(path: Path, samples: int | None, seed: int | None) -> tuple[Any, Model]:
    """Load, compile and check a scene with the real scene module and statics checks."""
    from mcchain.scene import compile_model, load_scene
    from mcchain.solvers.statics import check_scene, initial_state_warnings, written_state

    scene = load_scene(path)
    model = compile_model(scene, nsample=samples, seed=seed, count_name="--samples")
    check_scene(model)
    if scene.output:
        from mcchain.solvers.outputs import check_ideal

        check_ideal(scene, model)
    if scene.requirement:
        from mcchain.decision.requirements import check_requirements

        check_requirements(scene, model)
    model.meta["warnings"] = initial_state_warnings(*written_state(scene))
    return scene, model


def _section(scene: Any, name: str) -> Any:
    return getattr(scene, name, None)


def _dump(obj: Any) -> Any:
    if hasattr(obj, "model_dump"):
        return obj.model_dump(mode="json")
    return obj


def resolved_settings(scene: Any, nsample: int, seed: int | None) -> dict[str, Any]:
    """The scene with every default filled in, the sample count and the seed.

    Execution details (chunk size, threads, scheduler) are left out on purpose: they never
    change the data and must not change the file.
    """
    data = _dump(scene)
    data = dict(data) if isinstance(data, Mapping) else {}
    data.pop("text", None)
    storage = data.get("storage")
    if isinstance(storage, Mapping):
        data["storage"] = {k: v for k, v in storage.items() if k != "chunk_size"}
    return {"scene": data, "samples": int(nsample), "seed": seed}


def _warnings(model: Model) -> list[str]:
    lines = model.meta.get("warnings") or []
    assert isinstance(lines, list)
    return [str(line) for line in lines]


def prepare_job(
    scene_path: str | Path,
    *,
    samples: int | None = None,
    seed: int | None = None,
    chunk_size: int | None = None,
    loader: Loader | None = None,
) -> Job:
    """Load, compile and check a scene; nothing is written.

    Raises:
        SceneError: a bad scene (one line naming the key).
        RunError: a bad argument.
    """
    check_positive("--samples", samples)
    check_positive("--chunk-size", chunk_size)
    if seed is not None and (not isinstance(seed, int) or seed < 0):
        raise RunError(f"--seed: must be an integer >= 0, got {seed!r}")
    path = Path(scene_path)
    scene, model = (loader or default_loader)(path, samples, seed)
    scene, kernels_note = resolve_kernels(scene, model, int(model.nsample))
    from mcchain.decision.tolerance import requirement_tolerance

    scene, tolerance_note = requirement_tolerance(scene)
    from mcchain.scene.models import Storage

    # A scene without ``[storage]`` (a fake) gets the schema's defaults.
    storage = _section(scene, "storage") or Storage()
    chunk = chunk_size or storage.chunk_size
    check_positive("storage.chunk_size", chunk)
    effective_seed: Any = model.meta.get("seed", seed)
    if effective_seed is None:
        effective_seed = getattr(_section(scene, "sample"), "seed", None)
    effective_seed = None if effective_seed is None else int(effective_seed)
    text = getattr(scene, "text", None)
    if text is None:
        text = path.read_text(encoding="utf-8")
    name = getattr(_section(scene, "scene"), "name", None) or path.stem
    nsample = int(model.nsample)
    settings = resolved_settings(scene, nsample, effective_seed)
    warnings = _warnings(model)
    notes = [note for note in (kernels_note, tolerance_note) if note is not None]
    kernels = scene_kernels(scene)
    from mcchain.runner.resources import estimate_disk

    return Job(
        scene=scene,
        model=model,
        scene_text=text,
        scene_name=str(name),
        nsample=nsample,
        seed=effective_seed,
        chunk_size=int(chunk),
        history_dtype=str(storage.history_dtype),
        compression=str(storage.compression),
        complevel=int(storage.complevel),
        disk=estimate_disk(scene, model, nsample, int(chunk)),
        settings=settings,
        warnings=warnings,
        notes=notes,
        kernels=kernels,
        histories=str(getattr(storage, "histories", "all")),
    )


def scene_kernels(scene: Any) -> str | None:
    """The path that integrates the scene's time histories (``[simulate] kernels``), or None
    without ``[simulate]``."""
    sim = _section(scene, "simulate")
    return None if sim is None else str(getattr(sim, "kernels", "lanes"))


def resolve_kernels(scene: Any, model: Model, nsample: int) -> tuple[Any, str | None]:
    """The scene with ``[simulate] kernels = "auto"`` resolved for a run of ``nsample``
    instances of ``model``'s topology (:func:`mcchain.solvers.kernel_choice.choose_kernels`),
    and a line for the user when that takes the loop kernels. A run resolves it once, for
    all its samples, so every chunk, its resume and a Dask run integrate on the same path;
    the resolved value is what ``ensemble.nc`` stores. Other scenes come back as given."""
    sim = _section(scene, "simulate")
    if getattr(sim, "kernels", None) != "auto":
        return scene, None
    from mcchain.solvers.kernel_choice import choose_kernels

    choice = choose_kernels(sim, int(model.ndof), nsample)
    simulate = sim.model_copy(update={"kernels": choice.kernels})
    return scene.model_copy(update={"simulate": simulate}), choice.note()
