"""Cross-reference checks of a scene: what the models alone cannot see.

Duplicate or reserved names, references to unknown bodies, sampled and perturbation paths,
distribution supports against the parameter's domain, counts against the design, ``output_dt``
against ``dt``, clearances against the size of the mechanism (a clearance written in mm).
Each failure is one :class:`~mcchain.errors.SceneError` line ``key.path: reason``.
"""

from __future__ import annotations

import itertools
import math

from mcchain.errors import SceneError
from mcchain.parameters import PARAMETERS
from mcchain.scene.fields import GROUND_NAME
from mcchain.scene.mechanism import Driver, Force, Joint
from mcchain.scene.models import FIXED_STEP_METHODS, LOOP_METHODS, Scene
from mcchain.scene.outputs import check_outputs
from mcchain.scene.paths import (
    PARAM_SHAPES,
    PERTURB_KEYS,
    item_path,
    parse_path,
    quote_key,
)
from mcchain.scene.study import Distribution, saltelli_count_error


def _item(scene: Scene, kind: str, index: int) -> str:
    entry = getattr(scene, kind)[index]
    if kind == "driver":
        return item_path(kind, index, entry.name)
    if getattr(entry, "_auto_name", False):
        return f"{kind}[{index}]"
    return item_path(kind, index, entry.name)


def check_scene(scene: Scene) -> None:
    """Cross-reference checks the models cannot make; raise :class:`SceneError`.

    Duplicate or reserved names, references to unknown bodies, bodies joined to themselves,
    bodies not connected to the ground, drivers/forces on ground, duplicate drivers, sampled
    and perturbation paths, the distributions' supports against the parameter's domain, a
    ``"saltelli"`` count against the number of varied paths, ``output_dt`` against ``dt``,
    each clearance (written or sampled) against :data:`CLEARANCE_SHARE` of the joint's
    neighbouring dimension (:func:`_check_clearance_scale`). Kinematics are not checked.
    """
    bodies = scene.body_names
    known = {GROUND_NAME, *bodies}
    listing = ", ".join([GROUND_NAME, *bodies])

    def unique(kind: str, names: list[str]) -> None:
        seen: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in seen:
                entry = getattr(scene, kind)[i]
                auto = " (a default name: give the item a `name`)" if entry._auto_name else ""
                raise SceneError(
                    f"{kind}[{i}].name: duplicate {kind} name {name!r} "
                    f"(also {kind}[{seen[name]}]){auto}"
                )
            seen[name] = i

    for i, name in enumerate(bodies):
        if name == GROUND_NAME:
            raise SceneError(f"body[{i}].name: {GROUND_NAME!r} is reserved for the fixed body")
    seen_body: dict[str, int] = {}
    for i, name in enumerate(bodies):
        if name in seen_body:
            raise SceneError(
                f"body[{i}].name: duplicate body name {name!r} (also body[{seen_body[name]}])"
            )
        seen_body[name] = i

    for kind in ("joint", "spring"):
        items = getattr(scene, kind)
        for i, item in enumerate(items):
            where = _item(scene, kind, i)
            for k, ref in enumerate(item.bodies):
                if ref not in known:
                    raise SceneError(
                        f"{where}.bodies[{k}]: unknown body {ref!r} (known: {listing})"
                    )
            if item.bodies[0] == item.bodies[1]:
                raise SceneError(f"{where}.bodies: joins body {item.bodies[0]!r} to itself")
        unique(kind, [str(item.name) for item in items])

    _check_connected(scene)

    drivers: dict[str, int] = {}
    for i, driver in enumerate(scene.driver):
        if (driver.body is None) == (driver.joint is None):
            raise SceneError(
                f"driver[{i}]: give `body` (a body's angle) or `joint` (a prismatic joint's "
                "displacement), " + ("not both" if driver.body is not None else "one of them")
            )
        where = _item(scene, "driver", i)
        if driver.slides:
            _check_slider_driver(scene, where, driver)
            if driver.name in drivers:
                raise SceneError(
                    f"driver[{i}].joint: joint {driver.joint!r} already driven by "
                    f"driver[{drivers[driver.name]}]"
                )
            drivers[driver.name] = i
            continue
        for key in ("displacement0", "speed"):
            if getattr(driver, key) is not None:
                raise SceneError(
                    f"{where}.{key}: only a driver of a prismatic joint (`joint = ...`) has one"
                )
        if driver.body == GROUND_NAME:
            raise SceneError(f"{where}.body: cannot drive the fixed body 'ground'")
        if driver.body not in known:
            raise SceneError(f"{where}.body: unknown body {driver.body!r} (known: {listing})")
        if driver.body in drivers:
            raise SceneError(
                f"driver[{i}].body: body {driver.body!r} already driven by "
                f"driver[{drivers[driver.body]}]"
            )
        drivers[driver.body] = i

    sampled_paths = set(_canonical_paths(scene))
    for i, driver in enumerate(scene.driver):
        _check_driver_law(_item(scene, "driver", i), driver, sampled_paths)

    for i, force in enumerate(scene.force):
        where = _item(scene, "force", i)
        _check_load_law(where, force, sampled_paths)
        if force.body == GROUND_NAME:
            raise SceneError(f"{where}.body: a load on the fixed body 'ground' does nothing")
        if force.body not in known:
            raise SceneError(f"{where}.body: unknown body {force.body!r} (known: {listing})")
    unique("force", scene.force_names)
    seen_requirement: dict[str, int] = {}
    for i, requirement in enumerate(scene.requirement):
        if requirement.name in seen_requirement:
            raise SceneError(
                f"requirement[{i}].name: duplicate requirement name {requirement.name!r} "
                f"(also requirement[{seen_requirement[requirement.name]}])"
            )
        seen_requirement[requirement.name] = i

    targets: dict[str, str] = {}  # canonical sampled path -> the path as written
    if scene.sample is not None:
        for path, dist in scene.sample.vary.items():
            where = f"sample.vary.{quote_key(path)}"
            try:
                ref = parse_path(scene, path, PARAM_SHAPES)
            except ValueError as exc:
                raise SceneError(f"{where}: {exc}") from None
            canonical = ref.canonical()
            if canonical in targets:
                same = quote_key(targets[canonical])
                raise SceneError(f"{where}: the same parameter as {same!s}")
            targets[canonical] = path
            domain = PARAMETERS[ref.kind, ref.key].domain
            bounds = dist.bounds()
            for bound in bounds or ():
                if domain is not None and not domain.contains(bound):
                    raise SceneError(
                        f"{where}.{dist.kind}: can give {bound!r}, but {ref.key} must be "
                        f"{domain.text}"
                    )
        if scene.sample.design == "saltelli":
            reason = saltelli_count_error(len(scene.sample.vary), scene.sample.count)
            if reason is not None:
                raise SceneError(f"sample.count: {reason}")

    sampled = set(targets) if scene.sample is not None else set()
    for i, body in enumerate(scene.body):
        if body.scale_inertia and f"body.{body.name}.inertia" in sampled:
            raise SceneError(
                f"{_item(scene, 'body', i)}.scale_inertia: the inertia is sampled as well "
                f"(sample.vary.{quote_key(targets[f'body.{body.name}.inertia'])}); scale it "
                "with the mass or sample it, not both"
            )
    for i, joint in enumerate(scene.joint):
        where = _item(scene, "joint", i)
        _check_joint_type(where, joint, sampled)
        clearance_joint = joint.clearance > 0 or f"joint.{joint.name}.clearance" in sampled
        if joint.eccentricity is not None and not clearance_joint:
            raise SceneError(
                f"{where}.eccentricity: only a clearance joint has one "
                "(its clearance is 0 and not sampled)"
            )
        _check_contact(scene, where, joint, clearance_joint, sampled)
        path = f"joint.{joint.name}.clearance"
        written = targets.get(path)
        sampled_as = scene.sample.vary[written] if written and scene.sample else None
        _check_clearance_scale(scene, i, where, sampled_as, written)

    check_outputs(scene)
    along = scene.modes.along if scene.modes is not None else None
    if along is not None and along.driver not in {d.body for d in scene.driver if not d.slides}:
        driven = ", ".join(d.name for d in scene.driver if not d.slides) or "none"
        raise SceneError(
            f"modes.along.driver: no driver turns body {along.driver!r} (drivers: {driven})"
        )
    if along is not None and any(d.slides for d in scene.driver):
        raise SceneError(
            "modes.along: follows one crank turn with every other driver held; a slider driver ("
            + ", ".join(f"driver.{d.name}" for d in scene.driver if d.slides)
            + ") has no turn to hold (leave [modes] along out, or drive the slider's crank)"
        )
    if along is not None and any(d.law != "constant" for d in scene.driver):
        raise SceneError(
            'modes.along: follows drivers of law "constant" only (one turn at speed ω); '
            + ", ".join(f"driver.{d.name}" for d in scene.driver if d.law != "constant")
            + ' is "harmonic"'
        )

    if scene.simulate is not None and scene.simulate.kernels == "loop":
        sim = scene.simulate
        if sim.method not in LOOP_METHODS:
            raise SceneError(
                f'simulate.kernels: "loop" integrates with {", ".join(LOOP_METHODS)}, not '
                f'{sim.method!r} (use kernels = "lanes")'
            )

    if scene.simulate is not None:
        sim = scene.simulate
        tabled = [("driver", i, d.times) for i, d in enumerate(scene.driver) if d.law == "table"]
        tabled += [("force", i, f.times) for i, f in enumerate(scene.force) if f.law == "table"]
        for kind, i, times in tabled:
            if times is not None and times[-1] < sim.t_end:
                raise SceneError(
                    f"{_item(scene, kind, i)}.times: the table ends at {times[-1]!r} s, before "
                    f"simulate.t_end = {sim.t_end!r} s (extend it to cover the run)"
                )
        for key in ("dt", "output_dt"):
            value = getattr(sim, key)
            if value is not None and value > sim.t_end:
                raise SceneError(f"simulate.{key}: must be <= t_end ({sim.t_end!r}), got {value!r}")
        for path in sim.perturb:
            try:
                parse_path(scene, path, {"body": PERTURB_KEYS})
            except ValueError as exc:
                raise SceneError(f"simulate.perturb.{quote_key(path)}: {exc}") from None
        if sim.output_dt is not None:
            if sim.output_dt < sim.dt:
                raise SceneError(
                    f"simulate.output_dt: must be >= dt ({sim.dt!r}), got {sim.output_dt!r}"
                )
            ratio = sim.output_dt / sim.dt
            if sim.method in FIXED_STEP_METHODS and abs(ratio - round(ratio)) > 1e-9 * ratio:
                raise SceneError(
                    f"simulate.output_dt: must be a whole multiple of dt ({sim.dt!r}) for "
                    f"method {sim.method!r}, got {sim.output_dt!r}"
                )


HARMONIC_KEYS = ("amplitude", "frequency", "phase")
"""The keys only a harmonic driver has."""


def _canonical_paths(scene: Scene) -> list[str]:
    """The canonical form of every sampled path that parses (the others are named later)."""
    if scene.sample is None:
        return []
    found = []
    for path in scene.sample.vary:
        try:
            found.append(parse_path(scene, path, PARAM_SHAPES).canonical())
        except ValueError:
            continue
    return found


def _check_slider_driver(scene: Scene, where: str, driver: Driver) -> None:
    """A slider driver names a prismatic joint and uses ``displacement0``/``speed``."""
    if driver.joint not in scene.joint_names:
        known = ", ".join(scene.joint_names) or "none"
        raise SceneError(f"{where}.joint: unknown joint {driver.joint!r} (known: {known})")
    joint = scene.joint[scene.joint_names.index(str(driver.joint))]
    if joint.type != "prismatic":
        raise SceneError(
            f"{where}.joint: joint {driver.joint!r} is {joint.type}; a driver moves a prismatic "
            "joint along its axis (drive a body's angle with `body = ...`)"
        )
    for key in ("omega", "angle0"):
        if getattr(driver, key) is not None:
            other = {"omega": "speed", "angle0": "displacement0"}[key]
            raise SceneError(f"{where}.{key}: a slider driver takes `{other}` (m), not `{key}`")


def _check_driver_law(where: str, driver: Driver, sampled: set[str]) -> None:
    """The keys a driver's ``law`` needs are given (or sampled), and no other law's keys."""

    def given(key: str) -> bool:
        return getattr(driver, key) is not None or f"driver.{driver.name}.{key}" in sampled

    values = "displacements" if driver.slides else "angles"
    table_keys = ("times", "angles", "displacements")
    if driver.law == "table":
        wrong = "angles" if driver.slides else "displacements"
        for key in ("omega", "angle0", "speed", "displacement0", *HARMONIC_KEYS, wrong):
            if given(key):
                raise SceneError(
                    f'{where}.{key}: a driver of law "table" takes `times` and `{values}` only '
                    "(its start and rate come from the table)"
                )
        _check_table(where, driver.times, getattr(driver, values), values)
        return
    for key in table_keys:
        if getattr(driver, key) is not None:
            raise SceneError(f'{where}.{key}: only a driver of law "table" has one')
    if driver.law == "constant":
        rate = "speed" if driver.slides else "omega"
        if not given(rate):
            law = "s0 + v t" if driver.slides else "θ0 + ω t"
            raise SceneError(f'{where}.{rate}: required for law "constant" ({law})')
        for key in HARMONIC_KEYS:
            if given(key):
                raise SceneError(
                    f'{where}.{key}: only a driver of law "harmonic" has one (this one is '
                    '"constant"; set law = "harmonic")'
                )
    else:
        for key in ("amplitude", "frequency"):
            if not given(key):
                raise SceneError(
                    f'{where}.{key}: required for law "harmonic" (θ0 + ω t + A (sin(2π f t + φ) '
                    "− sin φ))"
                )


def _check_table(
    where: str, times: list[float] | None, values: list[float] | None, name: str
) -> None:
    """``times`` and ``values`` of a table law: given, as long as each other, at least 2,
    times increasing and covering t = 0."""
    if times is None:
        raise SceneError(f'{where}.times: required for law "table"')
    if values is None:
        raise SceneError(f'{where}.{name}: required for law "table"')
    if len(times) < 2:
        raise SceneError(f"{where}.times: a table needs at least 2 points, got {len(times)}")
    if len(values) != len(times):
        raise SceneError(
            f"{where}.{name}: {len(values)} values for {len(times)} times (one value per time)"
        )
    steps = [b - a for a, b in itertools.pairwise(times)]
    if min(steps) <= 0.0:
        i = steps.index(min(steps))
        raise SceneError(
            f"{where}.times: must increase, but times[{i + 1}] = {times[i + 1]!r} follows "
            f"{times[i]!r}"
        )
    if times[0] > 0.0:
        raise SceneError(f"{where}.times: the table must cover t = 0, it starts at {times[0]!r}")


def _check_load_law(where: str, force: Force, sampled: set[str]) -> None:
    """A harmonic load has its frequency; a table load its times and factors; a constant one
    neither."""

    def given(key: str) -> bool:
        return getattr(force, key) is not None or f"force.{force.name}.{key}" in sampled

    if force.law == "table":
        for key in ("frequency", "phase"):
            if given(key):
                raise SceneError(
                    f'{where}.{key}: a load of law "table" takes `times` and `factors` only'
                )
        _check_table(where, force.times, force.factors, "factors")
        return
    for key in ("times", "factors"):
        if getattr(force, key) is not None:
            raise SceneError(f'{where}.{key}: only a load of law "table" has one')

    if force.law == "harmonic":
        if not given("frequency"):
            raise SceneError(
                f'{where}.frequency: required for law "harmonic" (value and torque times '
                "sin(2π f t + φ))"
            )
        return
    for key in ("frequency", "phase"):
        if given(key):
            raise SceneError(
                f'{where}.{key}: only a load of law "harmonic" has one (this one is "constant"; '
                'set law = "harmonic")'
            )


def _check_connected(scene: Scene) -> None:
    """Every body must hang on the ground through joints and springs: a body held by
    nothing falls, and its equilibrium fails with no hint of why."""
    held = {GROUND_NAME}
    links = [(j.bodies[0], j.bodies[1]) for j in scene.joint]
    links += [(s.bodies[0], s.bodies[1]) for s in scene.spring]
    grown = True
    while grown:
        grown = False
        for a, b in links:
            if (a in held) != (b in held):
                held.update((a, b))
                grown = True
    for i, name in enumerate(scene.body_names):
        if name not in held:
            raise SceneError(
                f"body[{i}]: {name!r} is not connected to the ground by any chain of joints "
                "or springs (a body held by nothing falls and has no equilibrium)"
            )


def _check_joint_type(where: str, joint: Joint, sampled: set[str]) -> None:
    """The keys of a prismatic joint (``axis``, ``relative_angle``) against its type."""
    if joint.type == "revolute":
        for key in ("axis", "relative_angle"):
            if getattr(joint, key) is not None:
                raise SceneError(
                    f'{where}.{key}: only a prismatic joint has one (type = "prismatic")'
                )
        return
    if joint.axis is None:
        raise SceneError(
            f"{where}.axis: a prismatic joint needs its sliding direction, e.g. [1.0, 0.0]"
        )
    if joint.axis[0] == 0.0 and joint.axis[1] == 0.0:
        raise SceneError(f"{where}.axis: must not be [0, 0] (it gives the sliding direction)")
    for key in ("clearance", "eccentricity", "model", "contact"):
        given = getattr(joint, key) not in (None, 0.0) or f"joint.{joint.name}.{key}" in sampled
        if given:
            raise SceneError(
                f"{where}.{key}: a prismatic joint is ideal (clearance is for revolute joints)"
            )


def _check_contact(
    scene: Scene, where: str, joint: Joint, clearance_joint: bool, sampled: set[str]
) -> None:
    """``model`` and ``[joint.contact]`` of one joint against its clearance and the sampled
    contact keys."""
    contact = joint.contact
    if contact is not None and not clearance_joint:
        raise SceneError(
            f"{where}.contact: only a clearance joint has a contact law (its clearance is 0 "
            "and not sampled)"
        )
    if joint.model in ("contact", "auto"):
        if not clearance_joint:
            raise SceneError(
                f"{where}.model: {joint.model!r} needs a clearance joint (clearance > 0 or sampled)"
            )
        if contact is None:
            raise SceneError(
                f"{where}.model: {joint.model!r} needs a [joint.contact] table (the law and "
                "its stiffness)"
            )
    start = contact.start if contact is not None else None
    if start is not None and joint.resolved_model == "link":
        raise SceneError(
            f'{where}.contact.start: model "link" has no contact law to start in (give '
            'model = "contact" or "auto", or remove start)'
        )
    if start == "pressed" and joint.resolved_model == "auto":
        raise SceneError(
            f'{where}.contact.start: model "auto" starts on the link, which carries the '
            'joint force from t = 0 (a pressed start\'s rigid limit): "pressed" is for model '
            '"contact"; give "seated" (the default) or "centred"'
        )
    prefix = f"joint.{joint.name}.contact."
    for path in sorted(p for p in sampled if p.startswith(prefix)):
        key = path[len(prefix) :]
        if contact is None or joint.resolved_model == "link":
            raise SceneError(
                f"sample.vary.{quote_key(path)}: joint {joint.name!r} uses the link model, "
                "which has no contact law (give it a [joint.contact] table and model "
                '"contact" or "auto")'
            )
        if key == "stiffness" and contact.stiffness is None:
            raise SceneError(
                f"sample.vary.{quote_key(path)}: the stiffness of joint {joint.name!r} comes "
                "from its radius and materials; give `stiffness` in [joint.contact] to sample it"
            )


CLEARANCE_SHARE = 0.05
"""Largest clearance accepted, as a share of the joint's shortest neighbouring dimension
(:func:`neighbouring_dimension`). Real clearances are thousandths of that dimension; a value
past this share is a clearance written in millimetres (``clearance = 0.5`` on a 1 m bar),
whose every sample would diverge or carry absurd contact forces."""

UPPER_SIGMAS = 4.0
"""A normal or lognormal clearance is checked at its mean + 4 standard deviations (of its
log, for lognormal): the 0.99997 quantile, past which one draw in 31,600 falls."""


def upper_value(dist: Distribution) -> tuple[float, str]:
    """The largest value a sampled clearance is checked at, and what it is: the upper bound
    (uniform, truncnormal, choice), or the mean + :data:`UPPER_SIGMAS` standard deviations
    (normal; of the log for lognormal)."""
    bounds = dist.bounds()
    if bounds is not None:
        return bounds[1], "its upper bound"
    centre, spread = dist.args
    top = centre + UPPER_SIGMAS * spread
    what = f"its mean + {UPPER_SIGMAS:g} standard deviations"
    if dist.kind == "lognormal":
        return math.exp(top), f"exp(mu + {UPPER_SIGMAS:g} sigma)"
    return top, what


def neighbouring_dimension(scene: Scene, index: int) -> tuple[float, str] | None:
    """The shortest distance (m) from joint ``index``'s point on either of its bodies to
    another joint's point on that body or to the body's centre of mass (the ground has
    none), and what it reaches; None when every such distance is 0 (a lone joint at the
    centre of mass)."""
    joint = scene.joint[index]
    best: tuple[float, str] | None = None
    for side, body in enumerate(joint.bodies):
        here = joint.points[side]
        others: list[tuple[list[float], str]] = []
        if body != GROUND_NAME:
            others.append(([0.0, 0.0], f"the centre of mass of body {body!r}"))
        for k, other in enumerate(scene.joint):
            if k == index:
                continue
            for other_side, other_body in enumerate(other.bodies):
                if other_body == body:
                    others.append((other.points[other_side], f"joint {other.name!r} on {body!r}"))
        for point, what in others:
            distance = math.hypot(point[0] - here[0], point[1] - here[1])
            if distance > 0 and (best is None or distance < best[0]):
                best = (distance, what)
    return best


def _check_clearance_scale(
    scene: Scene, index: int, where: str, dist: Distribution | None, path: str | None
) -> None:
    """Refuse a clearance (or a sampled clearance's :func:`upper_value`) larger than
    :data:`CLEARANCE_SHARE` of the joint's :func:`neighbouring_dimension`."""
    joint = scene.joint[index]
    if joint.type != "revolute":
        return
    nearest = neighbouring_dimension(scene, index)
    if nearest is None:
        return
    size, what = nearest
    limit = CLEARANCE_SHARE * size
    hint = (
        f"more than {CLEARANCE_SHARE:.0%} of the joint's shortest neighbouring dimension "
        f"({size:.6g} m, to {what}): clearances are in metres (at most {limit:.3g} m here)"
    )
    if joint.clearance > limit:
        raise SceneError(f"{where}.clearance: {joint.clearance!r} m is {hint}")
    if dist is not None and path is not None:
        top, which = upper_value(dist)
        if top > limit:
            raise SceneError(
                f"sample.vary.{quote_key(path)}.{dist.kind}: {which} {top:.6g} m is {hint}"
            )
