"""Scene loading: defaults, and one exact one-line message per kind of bad input."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from mcchain.errors import SceneError
from mcchain.scene import load_scene, load_scene_text, scene_from_dict
from mcchain.testing.factory import chain_scene_text, clearance_bar_text

BASE = """
[scene]
name = "t"

[[body]]
name = "bar"
mass = 2.0
inertia = 0.1667
position = [0.0, -0.5]
angle = -1.5707963267948966

[[joint]]
name = "O"
bodies = ["ground", "bar"]
points = [[0.0, 0.0], [-0.5, 0.0]]
"""


def _with(old: str, new: str) -> str:
    assert old in BASE
    return BASE.replace(old, new, 1)


def _spring(extra: str = "", name: str = 'name = "s"\n', bodies: str = '"ground", "bar"') -> str:
    return (
        f"\n[[spring]]\n{name}bodies = [{bodies}]\npoints = [[0, 0], [0.5, 0]]\n"
        f"stiffness = 10.0\n{extra}"
    )


def _vary(path: str, dist: str) -> str:
    return BASE + f'\n[sample.vary]\n"{path}" = {dist}\n'


# (id, scene text, key path, reason substring)
BAD = [
    ("toml", "[[body]\nname = 1", "<string>", "malformed TOML: Expected ']]'"),
    ("toml-line-col", BASE + "x = = 1\n", "<string>", "(at line 16, column"),
    ("toml-duplicate-key", _with("mass = 2.0", "mass = 2.0\nmass = 3.0"), "<string>", "line"),
    (
        "unknown-key",
        _with("mass = 2.0", "mass = 2.0\ncolour = 1"),
        "body.bar.colour",
        "unknown key",
    ),
    ("unknown-section", BASE + "[solver]\n", "solver", "unknown section"),
    ("unknown-scene-key", _with('name = "t"', 'name = "t"\ng = 1'), "scene.g", "unknown key"),
    ("missing-mass", _with("mass = 2.0\n", ""), "body.bar.mass", "missing required key"),
    (
        "eccentricity-on-ideal-joint",
        BASE + "eccentricity = 0.5\n",
        "joint.O.eccentricity",
        "only a clearance joint has one (its clearance is 0 and not sampled)",
    ),
    (
        "dt-past-t_end",
        BASE + "[simulate]\nt_end = 0.1\ndt = 0.2\n",
        "simulate.dt",
        "must be <= t_end (0.1), got 0.2",
    ),
    (
        "output_dt-past-t_end",
        BASE + "[simulate]\nt_end = 0.1\ndt = 0.01\noutput_dt = 0.5\n",
        "simulate.output_dt",
        "must be <= t_end (0.1), got 0.5",
    ),
    (
        "typo-not-missing",
        _with("mass = 2.0", "masss = 2.0"),
        "body.bar.masss",
        "unknown key (did you mean `mass`? expected one of: name, mass,",
    ),
    ("missing-body", '[scene]\nname = "x"\n', "body", "missing required key"),
    ("no-bodies", "body = []\n", "body", "expected at least 1 item, got 0"),
    ("body-not-array", _with("[[body]]", "[body]"), "body", "expected an array of tables [[body]]"),
    (
        "missing-joint-points",
        _with("points = [[0.0, 0.0], [-0.5, 0.0]]\n", ""),
        "joint.O.points",
        "missing required key",
    ),
    ("string-number", _with("mass = 2.0", 'mass = "2"'), "body.bar.mass", "expected a number"),
    (
        "bool-number",
        _with("mass = 2.0", "mass = true"),
        "body.bar.mass",
        "expected a number, got true",
    ),
    ("zero-mass", _with("mass = 2.0", "mass = 0.0"), "body.bar.mass", "must be > 0.0, got 0.0"),
    ("negative-mass", _with("mass = 2.0", "mass = -2"), "body.bar.mass", "must be > 0.0, got -2"),
    ("inf-mass", _with("mass = 2.0", "mass = inf"), "body.bar.mass", "must be a finite number"),
    ("nan-inertia", _with("inertia = 0.1667", "inertia = nan"), "body.bar.inertia", "finite"),
    ("zero-inertia", _with("inertia = 0.1667", "inertia = 0"), "body.bar.inertia", "must be > 0"),
    ("nan-position", _with("[0.0, -0.5]", "[nan, -0.5]"), "body.bar.position[0]", "finite"),
    (
        "inf-gravity",
        _with('name = "t"', 'name = "t"\ngravity = [0, -inf]'),
        "scene.gravity[1]",
        "finite",
    ),
    ("inf-point", _with("[-0.5, 0.0]]", "[-inf, 0.0]]"), "joint.O.points[1][0]", "finite"),
    (
        "vector-long",
        _with("[0.0, -0.5]", "[0.0, -0.5, 1.0]"),
        "body.bar.position",
        "expected 2 items, got 3",
    ),
    (
        "vector-short",
        _with("[-0.5, 0.0]]", "[-0.5]]"),
        "joint.O.points[1]",
        "expected 2 items, got 1",
    ),
    ("int-expected", BASE + "[sample]\ncount = 10.0\n", "sample.count", "expected an integer"),
    ("bad-literal", BASE + '[sample]\ndesign = "grid"\n', "sample.design", "must be one of"),
    (
        "saltelli-count",
        BASE
        + '[sample]\ncount = 1001\ndesign = "saltelli"\n[sample.vary]\n'
        + '"body.bar.mass" = { uniform = [1, 3] }\n"body.bar.inertia" = { uniform = [0.1, 0.2] }\n',
        "sample.count",
        'must be a multiple of 4 (= number of varied paths + 2) for design "saltelli", got 1001',
    ),
    ("bad-name", _with('name = "bar"', 'name = "my bar"'), "body[0].name", "invalid name"),
    ("dotted-name", _with('name = "bar"', 'name = "a.b"'), "body[0].name", "invalid name"),
    ("ground-body", _with('name = "bar"', 'name = "ground"'), "body[0].name", "reserved"),
    (
        "duplicate-body",
        BASE + '[[body]]\nname = "bar"\nmass = 1\ninertia = 1\n',
        "body[1].name",
        "duplicate body name 'bar' (also body[0])",
    ),
    (
        "joint-unknown-body",
        _with('"ground", "bar"', '"ground", "barr"'),
        "joint.O.bodies[1]",
        "unknown body 'barr' (known: ground, bar)",
    ),
    (
        "joint-self",
        _with('"ground", "bar"', '"bar", "bar"'),
        "joint.O.bodies",
        "joins body 'bar' to itself",
    ),
    (
        "joint-ground-ground",
        _with('"ground", "bar"', '"ground", "ground"'),
        "joint.O.bodies",
        "joins body 'ground' to itself",
    ),
    (
        "duplicate-joint",
        BASE + '[[joint]]\nname = "O"\nbodies = ["ground", "bar"]\npoints = [[0, 0], [0, 0]]\n',
        "joint[1].name",
        "duplicate joint name 'O'",
    ),
    (
        "duplicate-default-joint-name",
        _with('name = "O"\n', "")
        + '[[joint]]\nbodies = ["ground", "bar"]\npoints = [[0, 0], [0, 0]]\n',
        "joint[1].name",
        "duplicate joint name 'ground-bar' (also joint[0]) (a default name",
    ),
    (
        "unnamed-item-by-index",
        _with('name = "O"\n', "") + "clearance = 'a'\n",
        "joint[0].clearance",
        "expected a number",
    ),
    (
        "negative-clearance",
        BASE + "clearance = -1e-3\n",
        "joint.O.clearance",
        "must be >= 0.0, got -0.001",
    ),
    (
        "driver-unknown-body",
        BASE + '[[driver]]\nbody = "crank"\nomega = 1\n',
        "driver.crank.body",
        "unknown body 'crank'",
    ),
    (
        "driver-ground",
        BASE + '[[driver]]\nbody = "ground"\nomega = 1\n',
        "driver.ground.body",
        "cannot drive the fixed body",
    ),
    (
        "driver-missing-omega",
        BASE + '[[driver]]\nbody = "bar"\n',
        "driver.bar.omega",
        'required for law "constant"',
    ),
    (
        "driver-duplicate",
        BASE + '[[driver]]\nbody = "bar"\nomega = 1\n[[driver]]\nbody = "bar"\nomega = 2\n',
        "driver[1].body",
        "already driven by driver[0]",
    ),
    (
        "force-empty",
        BASE + '[[force]]\nname = "tip"\nbody = "bar"\n',
        "force.tip",
        "a force needs `value = [Fx, Fy]`, `torque = T`, or both",
    ),
    (
        "force-unknown-body",
        BASE + '[[force]]\nname = "tip"\nbody = "bax"\ntorque = 1\n',
        "force.tip.body",
        "unknown body 'bax'",
    ),
    (
        "force-on-ground",
        BASE + '[[force]]\nname = "tip"\nbody = "ground"\ntorque = 1\n',
        "force.tip.body",
        "fixed body",
    ),
    (
        "duplicate-force",
        BASE + '[[force]]\nname = "P"\nbody = "bar"\ntorque = 1\n' * 2,
        "force[1].name",
        "duplicate force name 'P'",
    ),
    (
        "spring-unknown-body",
        BASE + _spring(bodies='"ground", "x"'),
        "spring.s.bodies[1]",
        "unknown body 'x'",
    ),
    ("spring-self", BASE + _spring(bodies='"bar", "bar"'), "spring.s.bodies", "to itself"),
    ("spring-negative", BASE + _spring("damping = -1.0\n"), "spring.s.damping", "must be >= 0.0"),
    (
        "duplicate-spring",
        BASE + _spring() + _spring(),
        "spring[1].name",
        "duplicate spring name 's'",
    ),
    (
        "uniform-inverted",
        _vary("body.bar.mass", "{ uniform = [3, 1] }"),
        'sample.vary."body.bar.mass".uniform',
        "low > high (3.0 > 1.0)",
    ),
    (
        "normal-negative-std",
        _vary("body.bar.mass", "{ normal = [3, -1] }"),
        'sample.vary."body.bar.mass".normal',
        "standard deviation must be >= 0, got -1.0",
    ),
    (
        "lognormal-negative-sigma",
        _vary("body.bar.mass", "{ lognormal = [0, -1] }"),
        'sample.vary."body.bar.mass".lognormal',
        "standard deviation must be >= 0",
    ),
    (
        "choice-empty",
        _vary("body.bar.mass", "{ choice = [] }"),
        'sample.vary."body.bar.mass".choice',
        "expected at least 1 item, got 0",
    ),
    (
        "truncnormal-inverted",
        _vary("body.bar.mass", "{ truncnormal = [2, 0.1, 3, 1] }"),
        'sample.vary."body.bar.mass".truncnormal',
        "bounds inverted or empty: low 3.0 >= high 1.0",
    ),
    (
        "truncnormal-outside",
        _vary("body.bar.mass", "{ truncnormal = [5, 0.1, 1, 3] }"),
        'sample.vary."body.bar.mass".truncnormal',
        "mean 5.0 outside the bounds [1.0, 3.0]",
    ),
    (
        "truncnormal-zero-std",
        _vary("body.bar.mass", "{ truncnormal = [2, 0, 1, 3] }"),
        'sample.vary."body.bar.mass".truncnormal',
        "standard deviation must be > 0",
    ),
    (
        "truncnormal-arity",
        _vary("body.bar.mass", "{ truncnormal = [2, 0.1, 1] }"),
        'sample.vary."body.bar.mass".truncnormal',
        "expected 4 items, got 3",
    ),
    (
        "distribution-unknown",
        _vary("body.bar.mass", "{ gamma = [1, 2] }"),
        'sample.vary."body.bar.mass".gamma',
        "unknown distribution (expected one of: uniform,",
    ),
    (
        "distribution-two-keys",
        _vary("body.bar.mass", "{ normal = [2, 0.1], uniform = [1, 2] }"),
        'sample.vary."body.bar.mass"',
        "exactly one of",
    ),
    (
        "distribution-no-key",
        _vary("body.bar.mass", "{ }"),
        'sample.vary."body.bar.mass"',
        "got none",
    ),
    (
        "distribution-not-table",
        _vary("body.bar.mass", "2.0"),
        'sample.vary."body.bar.mass"',
        "expected a distribution table",
    ),
    (
        "distribution-nan",
        _vary("body.bar.mass", "{ uniform = [1, nan] }"),
        'sample.vary."body.bar.mass".uniform[1]',
        "finite",
    ),
    (
        "path-unknown-body",
        _vary("body.barr.mass", "{ uniform = [1, 2] }"),
        'sample.vary."body.barr.mass"',
        "unknown body 'barr' (known: bar)",
    ),
    (
        "path-unknown-joint",
        _vary("joint.X.clearance", "{ uniform = [1e-4, 2e-4] }"),
        'sample.vary."joint.X.clearance"',
        "unknown joint 'X' (known: O)",
    ),
    (
        "path-unknown-force",
        _vary("force.tip.torque", "{ uniform = [1, 2] }"),
        'sample.vary."force.tip.torque"',
        "unknown force 'tip' (known: none)",
    ),
    (
        "path-unknown-spring",
        _vary("spring.s.stiffness", "{ uniform = [1, 2] }"),
        'sample.vary."spring.s.stiffness"',
        "unknown spring 's'",
    ),
    (
        "path-unknown-driver",
        _vary("driver.bar.omega", "{ uniform = [1, 2] }"),
        'sample.vary."driver.bar.omega"',
        "unknown driver (named by its body) 'bar'",
    ),
    (
        "path-unknown-key",
        _vary("body.bar.colour", "{ uniform = [1, 2] }"),
        'sample.vary."body.bar.colour"',
        "unknown key 'colour' of a body",
    ),
    (
        "path-unknown-kind",
        _vary("bogus.O.x", "{ uniform = [1, 2] }"),
        'sample.vary."bogus.O.x"',
        "unknown kind 'bogus'",
    ),
    (
        "path-index-range",
        _vary("body.bar.position[2]", "{ uniform = [1, 2] }"),
        'sample.vary."body.bar.position[2]"',
        "index 2 out of range 0..1",
    ),
    (
        "path-nested-index-range",
        _vary("joint.O.points[1][2]", "{ uniform = [1, 2] }"),
        'sample.vary."joint.O.points[1][2]"',
        "index 2 out of range 0..1",
    ),
    (
        "path-missing-index",
        _vary("body.bar.position", "{ uniform = [1, 2] }"),
        'sample.vary."body.bar.position"',
        "needs 1 index",
    ),
    (
        "path-scalar-indexed",
        _vary("body.bar.mass[0]", "{ uniform = [1, 2] }"),
        'sample.vary."body.bar.mass[0]"',
        "takes no index",
    ),
    (
        "path-bad-index",
        _vary("body.bar.position[x]", "{ uniform = [1, 2] }"),
        'sample.vary."body.bar.position[x]"',
        "bad index",
    ),
    (
        "path-scene-key",
        _vary("scene.name", "{ uniform = [1, 2] }"),
        'sample.vary."scene.name"',
        "unknown key 'name' of a scene",
    ),
    (
        "path-duplicate-target",
        BASE + '\n[sample.vary]\n"body.bar.angle" = { uniform = [1, 2] }\n'
        "body.bar.angle = { uniform = [1, 2] }\n",
        "sample.vary",
        "path 'body.bar.angle' given twice",
    ),
    (
        "domain-uniform",
        _vary("body.bar.mass", "{ uniform = [-1, 2] }"),
        'sample.vary."body.bar.mass".uniform',
        "can give -1.0, but mass must be > 0.0",
    ),
    (
        "domain-clearance-choice",
        _vary("joint.O.clearance", "{ choice = [0.0, 1e-4] }"),
        'sample.vary."joint.O.clearance".choice',
        "clearance must be > 0.0",
    ),
    ("sample-count", BASE + "[sample]\ncount = 0\n", "sample.count", "must be >= 1, got 0"),
    ("sample-seed", BASE + "[sample]\nseed = -1\n", "sample.seed", "must be >= 0"),
    (
        "simulate-missing",
        BASE + "[simulate]\ndt = 1e-3\n",
        "simulate.t_end",
        "missing required key",
    ),
    (
        "simulate-method",
        BASE + '[simulate]\nt_end = 1\ndt = 1e-3\nmethod = "euler"\n',
        "simulate.method",
        "must be one of 'rk4', 'rk4-projection'",
    ),
    (
        "simulate-output-multiple",
        BASE + "[simulate]\nt_end = 1\ndt = 1e-3\noutput_dt = 1.5e-3\n",
        "simulate.output_dt",
        "whole multiple of dt",
    ),
    (
        "simulate-output-small",
        BASE + "[simulate]\nt_end = 1\ndt = 1e-3\noutput_dt = 1e-4\n",
        "simulate.output_dt",
        "must be >= dt",
    ),
    (
        "simulate-rho",
        BASE + "[simulate]\nt_end = 1\ndt = 1e-3\nrho_inf = 2\n",
        "simulate.rho_inf",
        "must be <= 1",
    ),
    (
        "perturb-key",
        BASE + '[simulate]\nt_end = 1\ndt = 1e-3\nperturb = { "body.bar.mass" = 1 }\n',
        'simulate.perturb."body.bar.mass"',
        "unknown key 'mass' of a body",
    ),
    (
        "perturb-body",
        BASE + '[simulate]\nt_end = 1\ndt = 1e-3\nperturb = { "body.x.angle" = 1 }\n',
        'simulate.perturb."body.x.angle"',
        "unknown body 'x'",
    ),
    (
        "storage-compression",
        BASE + '[storage]\ncompression = "lz4"\n',
        "storage.compression",
        "must be one of 'zlib', 'zstd' or 'none'",
    ),
    (
        "storage-zlib-level",
        BASE + '[storage]\ncompression = "zlib"\ncomplevel = 12\n',
        "storage",
        "complevel 12 > 9",
    ),
    (
        "equilibrium-tolerance",
        BASE + "[equilibrium]\ntolerance = 0\n",
        "equilibrium.tolerance",
        "must be > 0.0",
    ),
]


@pytest.mark.parametrize(("text", "path", "reason"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_load_scene_text__bad_input_names_key_and_reason(text: str, path: str, reason: str) -> None:
    with pytest.raises(SceneError) as info:
        load_scene_text(text)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: "), message
    assert reason in message, message


def test_load_scene__missing_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    with pytest.raises(SceneError, match=r"nope\.toml: no such file$"):
        load_scene(missing)


def test_load_scene__directory(tmp_path: Path) -> None:
    with pytest.raises(SceneError, match="is a directory"):
        load_scene(tmp_path)


def test_load_scene__not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "bin.toml"
    path.write_bytes(b"\xff\xfe[scene]")
    with pytest.raises(SceneError, match=r"bin\.toml: not UTF-8 text"):
        load_scene(path)


def test_load_scene__malformed_file_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(BASE + "mass = \n")
    with pytest.raises(SceneError, match=r"bad\.toml: malformed TOML: .*\(at line 16, column 8\)"):
        load_scene(path)


def test_load_scene__defaults() -> None:
    pin = '[[joint]]\nbodies = ["ground", "b"]\npoints = [[0, 0], [0, 0]]\n'  # held by a pin
    text = '[[body]]\nname = "b"\nmass = 1\ninertia = 2\n' + pin
    scene = load_scene_text(text)
    assert scene.name == "scene"
    assert scene.scene.gravity == [0.0, -9.81]
    body = scene.body[0]
    assert (body.mass, body.inertia) == (1.0, 2.0)
    assert isinstance(body.mass, float)
    assert body.position is None and body.angle is None  # placed on its joints when compiled
    assert body.velocity == [0.0, 0.0] and body.angular_velocity == 0.0
    assert scene.joint[0].clearance == 0.0 and scene.joint[0].name == "ground-b"
    assert scene.driver == [] and scene.force == [] and scene.spring == []
    assert scene.sample is None and scene.equilibrium is None and scene.modes is None
    assert scene.simulate is None
    assert scene.storage.history_dtype == "float32"
    assert scene.storage.compression == "zstd"
    assert scene.storage.complevel == 1
    assert scene.storage.chunk_size == 1024
    assert scene.text == text and scene.source == "<string>"


def test_load_scene__section_defaults() -> None:
    text = BASE + "[sample]\n[equilibrium]\n[modes]\n[simulate]\nt_end = 1\ndt = 0.01\n"
    scene = load_scene_text(text)
    assert scene.sample is not None and scene.equilibrium is not None
    assert scene.modes is not None and scene.simulate is not None
    assert (scene.sample.count, scene.sample.seed, scene.sample.design) == (1000, 0, "random")
    assert scene.sample.vary == {}
    assert (scene.equilibrium.tolerance, scene.equilibrium.max_iterations) == (1e-10, 50)
    assert scene.modes.shapes is True  # mode_shape is stored for every [modes] run
    sim = scene.simulate
    assert (sim.method, sim.start, sim.output_dt, sim.output_step) == ("rk4", "scene", None, 0.01)
    assert (sim.rtol, sim.atol, sim.rho_inf) == (1e-8, 1e-10, 0.8)
    assert (sim.baumgarte, sim.constraint_tolerance, sim.max_newton) == (None, 1e-6, 20)
    assert sim.perturb == {}


def test_load_scene__default_names() -> None:
    text = _with('name = "O"\n', "") + (
        '[[force]]\nbody = "bar"\ntorque = 1.5\n'
        '[[spring]]\nbodies = ["ground", "bar"]\npoints = [[0, 0], [0, 0]]\nstiffness = 1\n'
        '[[driver]]\nbody = "bar"\nomega = 2\n'
    )
    scene = load_scene_text(text)
    assert scene.joint_names == ["ground-bar"]
    assert scene.force_names == ["bar"]
    assert scene.spring_names == ["ground-bar"]
    assert scene.driver_names == ["bar"]
    force = scene.force[0]
    assert (force.value, force.torque, force.point) == (None, 1.5, [0.0, 0.0])
    assert scene.driver[0].angle0 is None


def test_load_scene__name_from_file_stem(tmp_path: Path) -> None:
    path = tmp_path / "my-bar.toml"
    path.write_text(BASE.replace('[scene]\nname = "t"\n', ""))
    scene = load_scene(path)
    assert scene.name == "my-bar"
    assert scene.source == str(path)
    assert scene.text == path.read_text()


def test_load_scene__modes_alone_is_allowed() -> None:
    scene = load_scene_text(BASE + "[modes]\nshapes = true\n")
    assert scene.equilibrium is None and scene.modes is not None and scene.modes.shapes


def test_load_scene__dotted_bare_vary_keys_are_paths() -> None:
    scene = load_scene_text(BASE + "[sample.vary]\nbody.bar.mass = { uniform = [1, 2] }\n")
    assert scene.param_paths == ["body.bar.mass"]


def test_load_scene__sampled_path_order_is_file_order() -> None:
    text = BASE + (
        "[sample.vary]\n"
        '"scene.gravity[1]" = { normal = [-9.81, 0.01] }\n'
        '"joint.O.points[1][0]" = { uniform = [-0.51, -0.49] }\n'
        '"body.bar.mass" = { lognormal = [0.69, 0.01] }\n'
    )
    scene = load_scene_text(text)
    assert scene.param_paths == ["scene.gravity[1]", "joint.O.points[1][0]", "body.bar.mass"]


def test_load_scene__ints_accepted_for_floats_not_the_reverse() -> None:
    scene = load_scene_text(_with("mass = 2.0", "mass = 2"))
    assert scene.body[0].mass == 2.0
    with pytest.raises(SceneError, match=r"^sample\.seed: expected an integer, got 1\.5$"):
        load_scene_text(BASE + "[sample]\nseed = 1.5\n")


def test_load_scene__eccentricity_kept_and_optional() -> None:
    scene = load_scene_text(clearance_bar_text())
    assert scene.joint[0].clearance == 1e-3
    assert scene.joint[0].eccentricity == pytest.approx(-math.pi / 2)


def test_scene_from_dict__same_as_text() -> None:
    import tomllib

    text = chain_scene_text(3, [1], seed=2, springs=1, forces=2, driver=True, sample=8)
    a = load_scene_text(text)
    b = scene_from_dict(tomllib.loads(text))
    assert a.model_dump() == b.model_dump()


def test_load_section__settings_without_a_scene_use_the_schema() -> None:
    from mcchain.errors import SceneError
    from mcchain.scene import Simulate, Storage
    from mcchain.scene.loading import load_section

    sim = load_section(Simulate, "simulate", {"t_end": 1.0, "dt": 1e-3})
    assert sim == Simulate(t_end=1.0, dt=1e-3)
    assert sim.output_step == 1e-3 and sim.gains == (10.0, 10.0)
    assert load_section(Simulate, "simulate", sim) is sim
    with pytest.raises(SceneError, match=r"^simulate\.t_end: must be > 0.0, got -1$"):
        load_section(Simulate, "simulate", {"t_end": -1, "dt": 1e-3})
    with pytest.raises(SceneError, match=r"^simulate\.dt: missing required key$"):
        load_section(Simulate, "simulate", {"t_end": 1.0})
    assert load_section(Storage, "storage", {}).compression == "zstd"
