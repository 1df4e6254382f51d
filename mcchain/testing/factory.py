"""One seeded factory of test scenes (TOML text), shared by the tests and benchmarks.

Builders return the text of a scene file, so tests exercise the real loader:

* :func:`chain_scene_text` — a random open chain of ``nbody`` homogeneous bars hanging from
  the origin, with chosen clearance joints and optional springs, loads, driver, sampling and
  analysis sections. Initial positions satisfy every joint to rounding (clearance joints:
  the journal sits at ``clearance`` along its eccentricity, which points along the journal
  bar, the direction the chain's weight pulls it).
* :func:`paper_bar_text`, :func:`clearance_bar_text`, :func:`tip_load_bar_text` — the
  seed bar's check scenes (ideal pin, clearance pin, horizontal tip load), whose analytic
  answers are in :mod:`mcchain.testing.closed_forms`.
* :func:`toml_text` — the small TOML writer behind them (scene dicts -> text).

Same arguments, same text: every random choice comes from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mcchain.model import JOINT_IDEAL
from mcchain.testing.closed_forms import G, bar_inertia


# -- TOML writer ---------------------------------------------------------------------------
def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list | tuple | np.ndarray):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else json.dumps(k)


def toml_text(doc: Mapping[str, Any], header: str = "") -> str:
    """A scene dict as TOML: dict values are tables (nested dicts become sub-tables, e.g.
    ``sample.vary``), lists of dicts are arrays of tables, everything else a key."""
    lines = [f"# {line}" for line in header.splitlines()]

    def table(name: str, body: Mapping[str, Any], array: bool = False) -> None:
        lines.append("")
        lines.append(f"[[{name}]]" if array else f"[{name}]")
        subtables = []
        for k, v in body.items():
            if isinstance(v, Mapping) and k in ("vary",):
                subtables.append((k, v))
            else:
                lines.append(f"{_key(k)} = {_value(v)}")
        for k, v in subtables:
            table(f"{name}.{k}", v)

    for name, body in doc.items():
        if isinstance(body, Mapping):
            table(name, body)
        elif isinstance(body, list) and all(isinstance(x, Mapping) for x in body):
            for item in body:
                table(name, item, array=True)
        else:
            lines.insert(len(header.splitlines()), f"{_key(name)} = {_value(body)}")
    return "\n".join(lines).lstrip("\n") + "\n"


def write_scene(directory: str | Path, text: str, name: str = "scene.toml") -> Path:
    """Write ``text`` to ``directory/name`` and return the path (for CLI/runs tests)."""
    path = Path(directory) / name
    path.write_text(text)
    return path


# -- geometry -----------------------------------------------------------------------------
def rotation(th: float) -> np.ndarray:
    """The 2×2 rotation A(θ)."""
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def _centre(point: np.ndarray, th: float, local: np.ndarray) -> np.ndarray:
    """Centre r of a body with angle th whose local point ``local`` is at ``point``."""
    return point - rotation(th) @ local


def constraint_residual(model: Any, s: int = 0) -> float:
    """max |Φ| of sample ``s`` of a compiled model at its q0 (ideal joints: |d|, clearance
    joints: ||d| - c|, drivers: |θ - θ0|), in plain NumPy: checks that a scene starts
    assembled."""

    def pick(name: str) -> np.ndarray:
        arr = getattr(model, name)
        return arr[s % arr.shape[0]]

    q = pick("q0")

    def world(b: int, p: np.ndarray) -> np.ndarray:
        if b < 0:
            return p
        return q[3 * b : 3 * b + 2] + rotation(q[3 * b + 2]) @ p

    out: list[float] = []
    for k in range(model.njoint):
        d = world(model.joint_body_b[k], pick("joint_point_b")[k]) - world(
            model.joint_body_a[k], pick("joint_point_a")[k]
        )
        if model.joint_kind[k] == JOINT_IDEAL:
            out += [abs(float(x)) for x in d]
        else:
            out.append(abs(math.hypot(*d) - pick("joint_clearance")[k]))
    for j in range(model.ndriver):
        out.append(abs(q[3 * model.driver_body[j] + 2] - pick("driver_angle0")[j]))
    return max(out, default=0.0)


# -- random chains -------------------------------------------------------------------------
def chain_scene_dict(
    nbody: int,
    clearance_joints: Iterable[int] = (),
    seed: int = 0,
    *,
    springs: int = 0,
    forces: int = 0,
    driver: bool = False,
    sample: int | None = None,
    design: str = "random",
    vary: Mapping[str, Mapping[str, list[float]]] | None = None,
    equilibrium: bool = True,
    modes: bool = True,
    simulate: Mapping[str, Any] | None = None,
    spread: float = 0.5,
    name: str = "chain",
    prismatic_joints: Iterable[int] = (),
) -> dict[str, Any]:
    """The dict behind :func:`chain_scene_text` (same arguments)."""
    if nbody < 1:
        raise ValueError("nbody must be >= 1")
    rng = np.random.default_rng(seed)
    clearance_set = set(clearance_joints)
    prismatic_set = set(prismatic_joints)
    if not clearance_set <= set(range(nbody)):
        raise ValueError(f"clearance_joints must be in 0..{nbody - 1}")
    lengths = rng.uniform(0.2, 1.0, nbody)
    masses = rng.uniform(0.5, 3.0, nbody)
    angles = -math.pi / 2 + rng.uniform(-spread, spread, nbody)

    bodies, joints = [], []
    point = np.zeros(2)  # bearing centre of the next joint, global
    for k in range(nbody):
        half = lengths[k] / 2
        th = float(angles[k])
        journal = point.copy()
        joint: dict[str, Any] = {
            "name": f"J{k}",
            "bodies": ["ground" if k == 0 else f"b{k - 1}", f"b{k}"],
            "points": [
                [0.0, 0.0] if k == 0 else [float(lengths[k - 1] / 2), 0.0],
                [-float(half), 0.0],
            ],
        }
        if k in prismatic_set:  # a slider along a random axis (not unit: compiled to unit)
            turn = float(rng.uniform(-math.pi, math.pi))
            joint["type"] = "prismatic"
            joint["axis"] = [2.0 * math.cos(turn), 2.0 * math.sin(turn)]
        elif k in clearance_set:
            c = float(rng.uniform(1e-4, 1e-3))
            journal = point + c * np.array([math.cos(th), math.sin(th)])
            joint["clearance"] = c
            joint["eccentricity"] = th
        r = _centre(journal, th, np.array([-half, 0.0]))
        bodies.append(
            {
                "name": f"b{k}",
                "mass": float(masses[k]),
                "inertia": bar_inertia(float(masses[k]), float(lengths[k])),
                "position": [float(r[0]), float(r[1])],
                "angle": th,
            }
        )
        joints.append(joint)
        point = r + rotation(th) @ np.array([half, 0.0])

    doc: dict[str, Any] = {
        "scene": {"name": name, "gravity": [0.0, -G]},
        "body": bodies,
        "joint": joints,
    }
    if driver:
        doc["driver"] = [{"body": "b0", "omega": float(rng.uniform(5.0, 20.0))}]
    if forces:
        items = []
        for f in range(forces):
            k = int(rng.integers(nbody))
            item: dict[str, Any] = {
                "name": f"F{f}",
                "body": f"b{k}",
                "point": [float(lengths[k] / 2), 0.0],
            }
            kind = int(rng.integers(3))  # 0: force, 1: torque, 2: both
            if kind in (0, 2):
                item["value"] = [float(x) for x in rng.uniform(-5.0, 5.0, 2)]
            if kind in (1, 2):
                item["torque"] = float(rng.uniform(-1.0, 1.0))
            items.append(item)
        doc["force"] = items
    if springs:
        items = []
        for s in range(springs):
            k = int(rng.integers(nbody))
            anchor = [float(x) for x in rng.uniform(-0.5, 0.5, 2)]
            item = {
                "name": f"S{s}",
                "bodies": ["ground", f"b{k}"],
                "points": [anchor, [float(lengths[k] / 2), 0.0]],
                "stiffness": float(rng.uniform(100.0, 1000.0)),
            }
            if rng.random() < 0.5:  # else the default: unstressed at t = 0
                item["rest_length"] = float(rng.uniform(0.05, 0.5))
            if rng.random() < 0.5:
                item["damping"] = float(rng.uniform(0.0, 2.0))
            items.append(item)
        doc["spring"] = items
    if sample is not None:
        if vary is None:
            vary = {f"body.b{k}.mass": {"normal": [float(masses[k]), 0.01]} for k in range(nbody)}
            for k in sorted(clearance_set):
                vary[f"joint.J{k}.clearance"] = {"uniform": [1e-4, 1e-3]}
        doc["sample"] = {"count": sample, "seed": seed, "design": design, "vary": dict(vary)}
    if equilibrium:
        doc["equilibrium"] = {}
    if modes:
        doc["modes"] = {}
    if simulate is not None:
        doc["simulate"] = dict(simulate)
    return doc


def chain_scene_text(
    nbody: int,
    clearance_joints: Iterable[int] = (),
    seed: int = 0,
    *,
    springs: int = 0,
    forces: int = 0,
    driver: bool = False,
    sample: int | None = None,
    design: str = "random",
    vary: Mapping[str, Mapping[str, list[float]]] | None = None,
    equilibrium: bool = True,
    modes: bool = True,
    simulate: Mapping[str, Any] | None = None,
    spread: float = 0.5,
    name: str = "chain",
    prismatic_joints: Iterable[int] = (),
) -> str:
    """A random open chain of ``nbody`` bars hanging from the origin, as TOML text.

    Args:
        nbody: number of bars ``b0 .. b{n-1}``; joint ``J{k}`` joins b{k-1} (ground for k=0)
            to b{k}.
        clearance_joints: indices k of the joints ``J{k}`` with clearance (uniform in
            [1e-4, 1e-3] m, eccentricity along the journal bar); the others are ideal.
        seed: seeds every random choice (lengths 0.2-1 m, masses 0.5-3 kg, angles within
            ``spread`` rad of hanging) and the ``[sample]`` seed.
        springs: number of ground springs ``S{i}`` to random bars' distal ends (rest length
            explicit or default, damping sometimes).
        forces: number of loads ``F{i}`` (a force, a torque or both) at bars' distal ends.
        driver: drive b0 at a random ω in [5, 20] rad/s.
        sample: ``[sample] count``; None: no ``[sample]``.
        design: ``[sample] design``.
        vary: ``[sample.vary]``; default: every mass normal (σ = 0.01 kg) and every
            clearance uniform [1e-4, 1e-3] m.
        equilibrium, modes: add ``[equilibrium]`` / ``[modes]``.
        simulate: keys of a ``[simulate]`` section (e.g. ``{"t_end": 0.1, "dt": 1e-4}``).
        spread: half-width of the random angles around hanging, rad.
        name: ``[scene] name``.
        prismatic_joints: indices k of the joints ``J{k}`` that are prismatic instead
            (a random, non-unit axis; the relative angle as written).
    """
    doc = chain_scene_dict(
        nbody,
        clearance_joints,
        seed,
        springs=springs,
        forces=forces,
        driver=driver,
        sample=sample,
        design=design,
        vary=vary,
        equilibrium=equilibrium,
        modes=modes,
        simulate=simulate,
        spread=spread,
        name=name,
        prismatic_joints=prismatic_joints,
    )
    header = f"factory chain: nbody={nbody} clearance={sorted(set(clearance_joints))} seed={seed}"
    return toml_text(doc, header=header)


# -- the seed bar ----------------------------------------------------------------------
def bar_scene_dict(
    *,
    mass: float = 2.0,
    length: float = 1.0,
    clearance: float = 0.0,
    eccentricity: float = -math.pi / 2,
    tip_force: float | None = None,
    sample: Mapping[str, Any] | None = None,
    equilibrium: bool = True,
    modes: bool = True,
    simulate: Mapping[str, Any] | None = None,
    name: str = "bar",
) -> dict[str, Any]:
    """The paper's Fig. 1 bar (length 2l = ``length``) hanging from a pin at the origin.

    With ``clearance`` > 0 the journal starts at ``clearance`` along ``eccentricity`` from the
    bearing centre, and the bar hangs straight down from it; ``tip_force`` adds a horizontal
    force ``P`` (N) named ``P`` at the free end; ``sample`` is a ``[sample]`` table.
    """
    half = length / 2
    th = -math.pi / 2
    journal = np.zeros(2)
    joint: dict[str, Any] = {
        "name": "O",
        "bodies": ["ground", "bar"],
        "points": [[0.0, 0.0], [-half, 0.0]],
    }
    if clearance > 0:
        journal = clearance * np.array([math.cos(eccentricity), math.sin(eccentricity)])
        joint["clearance"] = clearance
        joint["eccentricity"] = eccentricity
    r = _centre(journal, th, np.array([-half, 0.0]))
    doc: dict[str, Any] = {
        "scene": {"name": name, "gravity": [0.0, -G]},
        "body": [
            {
                "name": "bar",
                "mass": mass,
                "inertia": bar_inertia(mass, length),
                "position": [float(r[0]), float(r[1])],
                "angle": th,
            }
        ],
        "joint": [joint],
    }
    if tip_force is not None:
        doc["force"] = [
            {"name": "P", "body": "bar", "point": [half, 0.0], "value": [tip_force, 0.0]}
        ]
    if sample is not None:
        doc["sample"] = dict(sample)
    if equilibrium:
        doc["equilibrium"] = {}
    if modes:
        doc["modes"] = {}
    if simulate is not None:
        doc["simulate"] = dict(simulate)
    return doc


def paper_bar_text(*, mass: float = 2.0, length: float = 1.0, **kw: Any) -> str:
    """The paper's bar with an ideal pin (the first check: p² = m g l / (J + m l²))."""
    return toml_text(bar_scene_dict(mass=mass, length=length, name="paper-bar", **kw))


def clearance_bar_text(
    clearance: float = 1e-3, eccentricity: float = -math.pi / 2, **kw: Any
) -> str:
    """The paper's bar with a radial clearance at the pin (the clearance quartic)."""
    kw.setdefault("name", "clearance-bar")
    return toml_text(bar_scene_dict(clearance=clearance, eccentricity=eccentricity, **kw))


def tip_load_bar_text(P: float = 5.0, clearance: float = 1e-3, **kw: Any) -> str:
    """The clearance bar with a horizontal force P at its free end (tan φ = 2P/(m g))."""
    kw.setdefault("name", "clearance-bar-tip-load")
    return toml_text(bar_scene_dict(clearance=clearance, tip_force=P, **kw))
