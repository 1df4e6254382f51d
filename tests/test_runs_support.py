"""Fakes for the runs/ensemble tests: a scene, a model and a deterministic solver.

The fake solver returns arrays in the registry's dims computed from each sample's
parameters only (like the real one, bit-identical whatever the chunking), with NaN and
status bits on some samples. A fake scene file is a small TOML::

    [scene]
    name = "fake"
    [sample]
    count = 100
    seed = 3
    [simulate]        # optional: time histories with `steps` output times
    steps = 20
    [storage]         # optional
    compression = "zstd"

The real pipeline is tested in test_runs_pipeline.py; these fakes keep the storage layer's
tests independent of the solvers.

To interrupt a run at a known point without racing it, :func:`start_paused_child` runs it in
a child process whose solver stops (blocks in ``signal.pause``) at the first chunk that
starts once ``after_parts`` part files exist, and tells the parent so through a pipe; the
parent then kills or interrupts it. No clock is involved: the parent waits on the pipe.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tomllib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mcchain.ensemble.registry import STEPS_TAKEN
from mcchain.model import JOINT_CLEARANCE, JOINT_IDEAL, Model, constraint_rows
from mcchain.status import CONTACT_LOST, EQUILIBRIUM_NOT_CONVERGED

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent


@dataclass
class FakeStorage:
    history_dtype: str = "float32"
    compression: str = "zlib"
    complevel: int = 1
    chunk_size: int = 16


@dataclass
class FakeSection:
    name: str = "fake"
    count: int = 1
    seed: int | None = None
    steps: int = 0


@dataclass
class FakeScene:
    text: str
    scene: FakeSection
    sample: FakeSection
    storage: FakeStorage
    fake: FakeSection
    simulate: Any = None
    extra: dict[str, Any] = field(default_factory=dict)

    def model_dump(self, mode: str = "json") -> dict[str, Any]:
        data = {k: v for k, v in asdict(self).items() if k != "text"}
        return json.loads(json.dumps(data))

    def model_copy(self, update: dict[str, Any]) -> FakeScene:
        """As pydantic's (the warm-up shortens ``simulate``: runner.executors.warm_scene)."""
        return replace(self, **update)


@dataclass
class FakeSimulate:
    t_end: float
    dt: float
    steps: int

    def model_copy(self, update: dict[str, Any]) -> FakeSimulate:
        return replace(self, **update)


def fake_model(nsample: int, seed: int = 0, nbody: int = 2) -> Model:
    """A chain of ``nbody`` bars (joint 0 ideal, the others clearance), one driver."""
    kinds = np.array([JOINT_IDEAL] + [JOINT_CLEARANCE] * (nbody - 1), dtype=np.int64)
    joint_row, driver_row = constraint_rows(kinds, 1)
    index = np.arange(nsample, dtype=np.float64)
    params = np.stack([1e-4 * (1.0 + np.sin(index + seed)), 2.0 + 0.1 * np.cos(index)], axis=1)

    def zeros(*shape: int) -> np.ndarray:
        return np.zeros((1, *shape))

    return Model(
        body_names=tuple(f"bar{i}" for i in range(nbody)),
        joint_names=tuple(f"J{i}" for i in range(nbody)),
        driver_names=("bar0",),
        force_names=(),
        spring_names=(),
        param_paths=("joint.J1.clearance", "body.bar0.mass"),
        parameters=params,
        nsample=nsample,
        joint_body_a=np.arange(-1, nbody - 1, dtype=np.int64),
        joint_body_b=np.arange(nbody, dtype=np.int64),
        joint_kind=kinds,
        joint_row=joint_row,
        driver_body=np.zeros(1, dtype=np.int64),
        driver_row=driver_row,
        force_body=np.zeros(0, dtype=np.int64),
        spring_body_a=np.zeros(0, dtype=np.int64),
        spring_body_b=np.zeros(0, dtype=np.int64),
        gravity=np.array([[0.0, -9.81]]),
        body_mass=np.concatenate([params[:, 1:2], np.ones((nsample, nbody - 1))], axis=1),
        body_inertia=np.full((1, nbody), 0.1),
        joint_point_a=zeros(nbody, 2),
        joint_point_b=zeros(nbody, 2),
        joint_clearance=np.concatenate([np.zeros((nsample, 1)), params[:, :1]], axis=1)
        if nbody > 1
        else zeros(1),
        joint_eccentricity=np.full((1, nbody), np.nan),
        driver_angle0=zeros(1),
        driver_omega=np.full((1, 1), 20.0),
        force_point=zeros(0, 2),
        force_value=zeros(0, 2),
        force_torque=zeros(0),
        spring_point_a=zeros(0, 2),
        spring_point_b=zeros(0, 2),
        spring_stiffness=zeros(0),
        spring_rest_length=zeros(0),
        spring_damping=zeros(0),
        q0=zeros(3 * nbody),
        v0=zeros(3 * nbody),
        meta={"seed": seed},
    )


def load_fake_scene(path: Path | str) -> FakeScene:
    text = Path(path).read_text(encoding="utf-8")
    data = tomllib.loads(text)
    sample = data.get("sample", {})
    sim = data.get("simulate")
    steps = int(sim["steps"]) if sim else 0
    return FakeScene(
        text=text,
        scene=FakeSection(name=data["scene"]["name"]),
        sample=FakeSection(count=int(sample.get("count", 1)), seed=sample.get("seed")),
        storage=FakeStorage(**data.get("storage", {})),
        fake=FakeSection(),
        simulate=FakeSimulate(t_end=1e-3 * steps, dt=1e-4, steps=steps) if sim else None,
    )


def fake_loader(path: Path, samples: int | None, seed: int | None) -> tuple[FakeScene, Model]:
    scene = load_fake_scene(path)
    n = samples or scene.sample.count
    s = seed if seed is not None else (scene.sample.seed or 0)
    return scene, fake_model(n, seed=s)


def fake_solve(model: Model, scene: Any) -> dict[str, np.ndarray]:
    """Deterministic per-sample outputs of every registry variable the fake scene asks for."""
    p = model.parameters
    n, nbody, njoint = model.nsample, model.nbody, model.njoint
    c, m = p[:, 0], p[:, 1]
    status = np.zeros(n, dtype=np.uint32)
    key = np.round(c * 1e8).astype(np.int64)
    status[key % 7 == 3] |= EQUILIBRIUM_NOT_CONVERGED
    status[key % 5 == 1] |= CONTACT_LOST
    failed = (status & EQUILIBRIUM_NOT_CONVERGED) != 0
    q_eq = (
        np.sin(c[:, None, None] * 1e4 + np.arange(3 * nbody).reshape(1, nbody, 3))
        * m[:, None, None]
    )
    q_eq[failed] = np.nan
    force = np.cos(m[:, None, None] + np.arange(2 * njoint).reshape(1, njoint, 2)) * 9.81
    force[failed] = np.nan
    omega = np.sqrt(m[:, None] * np.array([1.0, 7.0]))
    omega[failed] = np.nan
    out: dict[str, np.ndarray] = {
        "status": status,
        "q_eq": q_eq,
        "joint_force_eq": force,
        "iterations": np.where(failed, 50, 3 + (key % 3)).astype(np.int64),
        "stable": ~failed,
        "omega": omega,
    }
    sim = getattr(scene, "simulate", None)
    if sim is not None and sim.steps:
        t = np.arange(sim.steps) * 1e-3
        phase = t[None, :, None, None] * (10.0 + m[:, None, None, None])
        shape = (1, 1, nbody, 3)
        q = np.sin(phase + np.arange(3 * nbody).reshape(shape))
        out.update(
            time=t,
            q=q,
            v=np.cos(phase + np.arange(3 * nbody).reshape(shape)),
            joint_force=np.broadcast_to(force[:, None], (n, sim.steps, njoint, 2))
            * q[:, :, :1, :2],
            contact_force=q[:, :, :, 0] * 3.0,
            driver_torque=q[:, :, :1, 2],
            constraint_error=np.abs(q[:, :, 0, 0]) * 1e-9,
            energy=q[:, :, 0, 1] ** 2,
            diverged_time=np.where(failed, 0.5, np.nan),
            singular_time=np.full(n, np.nan),
            contact_lost_time=np.where((status & CONTACT_LOST) != 0, t[-1] / 2, np.nan),
        )
        # the steps each sample "took", as the real solver counts them for run.json
        out[STEPS_TAKEN] = np.full(n, round(sim.t_end / sim.dt), dtype=np.int64)
    return out


def write_fake_scene(
    path: Path,
    name: str = "fake",
    count: int = 100,
    seed: int = 3,
    steps: int = 0,
    storage: dict[str, Any] | None = None,
) -> Path:
    lines = [f'[scene]\nname = "{name}"\n', f"[sample]\ncount = {count}\nseed = {seed}\n"]
    if steps:
        lines.append(f"[simulate]\nsteps = {steps}\n")
    if storage:
        body = "".join(f"{k} = {json.dumps(v)}\n" for k, v in storage.items())
        lines.append(f"[storage]\n{body}")
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


PAUSE_ENV = "MCCHAIN_TEST_PAUSE"
"""``PARTS_DIR:AFTER_PARTS:FD`` for a child started by :func:`start_paused_child`."""


def pausing(solve: Any, parts: Path, after_parts: int, notify_fd: int) -> Any:
    """``solve``, except that the first call made once ``after_parts`` part files exist in
    ``parts`` writes one byte to ``notify_fd`` and blocks until a signal ends the process
    (SIGKILL) or raises (SIGINT: KeyboardInterrupt, as Ctrl-C in a terminal)."""
    from mcchain.ensemble.io import list_parts

    def solve_or_pause(model: Any, scene: Any) -> Any:
        if len(list_parts(parts)) >= after_parts:
            os.write(notify_fd, b"p")
            while True:
                signal.pause()
        return solve(model, scene)

    return solve_or_pause


def start_paused_child(
    args: list[str],
    parts: Path,
    after_parts: int = 1,
    env: dict[str, str] | None = None,
    **popen: Any,
) -> subprocess.Popen[Any]:
    """Start ``python tests/test_runs_support.py ARGS`` (``run``/``cli``, see
    :func:`_child_main`) paused after ``after_parts`` part files; return once it is paused.

    The child then has between ``after_parts`` and ``after_parts + 2`` part files (the chunk
    being written when it paused and the one solved just before may still be on the writer
    thread), and never finishes by itself."""
    read_end, write_end = os.pipe()
    command = [sys.executable, str(TESTS / "test_runs_support.py"), *args]
    env = {**(os.environ if env is None else env), PAUSE_ENV: f"{parts}:{after_parts}:{write_end}"}
    child = subprocess.Popen(command, env=env, pass_fds=(write_end,), **popen)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as pipe:
        paused = pipe.read(1)  # b"" if the child exited without pausing
    if paused != b"p":
        _, err = child.communicate()
        raise AssertionError(f"the child ended before pausing (exit {child.returncode}): {err}")
    return child


def _pause_spec() -> tuple[Path, int, int] | None:
    spec = os.environ.get(PAUSE_ENV)
    if not spec:
        return None
    folder, after_parts, fd = spec.rsplit(":", 2)
    return Path(folder), int(after_parts), int(fd)


def _child_main(argv: list[str]) -> int:
    """``python tests/test_runs_support.py run|resume SCENE|RUN [OPTIONS_JSON]``: a run with
    the fakes; ``... cli ARGS...``: ``mcchain ARGS...`` with the real solver. Either pauses as
    :data:`PAUSE_ENV` says, when set."""
    import mcchain.solvers
    from mcchain import cli
    from mcchain.runner import plan

    pause = _pause_spec()
    command, *rest = argv
    if command == "cli":
        if pause is not None:
            mcchain.solvers.solve_chunk = pausing(mcchain.solvers.solve_chunk, *pause)
        return cli.main(rest)
    target, *options_json = rest
    options = json.loads(options_json[0]) if options_json else {}
    solve = fake_solve if pause is None else pausing(fake_solve, *pause)
    if command == "run":
        result = plan.start_run(target, loader=fake_loader, solve=solve, **options)
    else:
        result = plan.resume_run(target, loader=fake_loader, solve=solve, **options)
    print(result.folder, flush=True)
    return 0


def test_fake_solve__is_independent_of_chunking() -> None:
    model = fake_model(40, seed=1)
    scene = FakeScene(
        text="",
        scene=FakeSection(),
        sample=FakeSection(),
        storage=FakeStorage(),
        fake=FakeSection(),
        simulate=FakeSimulate(1e-2, 1e-4, 10),
    )
    whole = fake_solve(model, scene)
    parts = [fake_solve(model.select(a, b), scene) for a, b in ((0, 13), (13, 40))]
    for name, value in whole.items():
        if name == "time":
            continue
        np.testing.assert_array_equal(value, np.concatenate([p[name] for p in parts]))


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(_child_main(sys.argv[1:]))
