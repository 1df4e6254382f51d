"""What ``mcchain validate`` prints about a scene's model: its bodies, joints, drivers,
constraint rows and dof, and its initial state (written and assembled)."""

from __future__ import annotations

from typing import Any


def _fmt(value: Any) -> str:
    import numpy as np

    arr = np.asarray(value, dtype=float).reshape(-1)
    text = ", ".join(f"{v:.6g}" for v in arr)
    return text if arr.size == 1 else f"[{text}]"


def _units(units: str) -> str:
    """CF units as ``validate`` prints them: a ``-1`` power after a slash (``rad s-1`` ->
    ``rad/s``)."""
    words = [w for w in units.split() if w != "1"]  # dimensionless: no unit
    num = [w for w in words if not w.endswith("-1")]
    den = [w[:-2] for w in words if w.endswith("-1")]
    return " ".join(num) + "".join(f"/{w}" for w in den)


def describe_model(model: Any, scene_name: str, nominal: Any = None) -> list[str]:
    """The lines ``mcchain validate`` prints: bodies, joints, drivers, rows, dof.

    Values are those of ``nominal`` (the scene without ``[sample]``) when given, else of the
    first sample; each sampled path is listed with its range over ``model``'s samples.
    """
    import numpy as np

    from mcchain.contact import LAW_NAMES, LINK, MODEL_NAMES
    from mcchain.model import DRIVER_HARMONIC, DRIVER_TABLE, GROUND, JointKind
    from mcchain.parameters import PARAMETERS

    def body(index: int) -> str:
        return "ground" if index == GROUND else str(model.body_names[index])

    values = model if nominal is None else nominal

    def show(kind: str, item: int, *keys: str) -> str:
        """``key value units`` of each key of one item (the first sample's values)."""
        rows = [PARAMETERS[kind, key] for key in keys]
        return ", ".join(
            f"{row.key.split('.')[-1]} {_fmt(row.read(values, item))} {_units(row.units)}".rstrip()
            for row in rows
        )

    lines = [
        f"scene {scene_name}: {model.nbody} bodies, {model.njoint} joints, "
        f"{model.ndriver} drivers, {model.nsample} samples"
    ]
    lines.append("bodies:")
    for i, name in enumerate(model.body_names):
        lines.append(f"  {name}: {show('body', i, 'mass', 'inertia', 'position', 'angle')}")
    lines.append("joints:")
    for j, name in enumerate(model.joint_names):
        kind = JointKind(int(model.joint_kind[j]))
        row = int(model.joint_row[j])
        rows = f"row {row}" if kind.rows == 1 else f"rows {row}-{row + kind.rows - 1}"
        what = (
            show("joint", j, "clearance")
            if kind == JointKind.CLEARANCE
            else f"prismatic, {show('joint', j, 'axis', 'relative_angle')}"
            if kind == JointKind.PRISMATIC
            else "ideal"
        )
        law = ""
        if int(model.joint_model[j]) != LINK:  # the contact law of [simulate]
            law = (
                f", model {MODEL_NAMES[int(model.joint_model[j])]}: "
                f"{LAW_NAMES[int(model.joint_contact_law[j])]} law, "
                + show("joint", j, "contact.stiffness", "contact.exponent", "contact.restitution")
            )
        lines.append(
            f"  {name}: {body(int(model.joint_body_a[j]))} (bearing) - "
            f"{body(int(model.joint_body_b[j]))} (journal), {what}, {rows}{law}"
        )
    if model.ndriver:
        lines.append("drivers:")
        for k, name in enumerate(model.driver_names):
            slider = int(model.driver_joint[k]) >= 0
            driver_law = int(model.driver_law[k])
            start, rate = ("displacement0", "speed") if slider else ("angle0", "omega")
            what = f"joint {name} along its axis, " if slider else ""
            if driver_law == DRIVER_TABLE:
                n = int(model.driver_table_size[k])
                knots = model.driver_table_knots[k, :n]
                what += f"table of {n} points over [{knots[0]:g}, {knots[-1]:g}] s, "
                shown = show("driver", k, start) + " (from the table)"
            else:
                shown = show("driver", k, rate, start)
                if driver_law == DRIVER_HARMONIC:
                    swing = show("driver", k, "amplitude", "frequency", "phase")
                    shown += ", " + (swing.replace(" rad,", " m,", 1) if slider else swing)
            row = int(model.driver_row[k])
            lines.append(f"  {name}: {what}{shown}, row {row}")
    if model.param_paths:
        lines.append("sampled (range over the samples):")
        params = np.asarray(model.parameters, dtype=float)
        for k, path in enumerate(model.param_paths):
            lo, hi = np.nanmin(params[:, k]), np.nanmax(params[:, k])
            lines.append(f"  {path}: {_fmt(lo)} … {_fmt(hi)}")
    lines.append(f"coordinates: {model.ndof}")
    lines.append(f"constraint rows: {model.ncon}")
    lines.append(f"degrees of freedom: {model.nmode}")
    outputs = model.meta.get("outputs") or ()
    if outputs:  # the scene's [[output]]s: what each variable will hold
        lines.append("outputs:")
        lines += [f"  {o.name} ({_units(o.units)}): {o.long_name}" for o in outputs]
    return lines


def describe_initial_state(model: Any, assembled: Any) -> list[str]:
    """The lines ``mcchain validate`` prints about the assembled state at t = 0 (sample 0 of
    ``model``): each body's pose and velocity; each clearance joint's d, |d| − c, the model
    it starts its time history in and the force that model gives at t = 0. The state is the
    time history's start: assembled, then each contact-law journal the scene does not write
    placed where its ``[joint.contact] start`` says (:func:`mcchain.solvers.start.contact_start`).
    """
    import numpy as np

    from mcchain.contact import START_LINK, START_SEATED
    from mcchain.kernels.joints import joint_vectors
    from mcchain.model import JointKind
    from mcchain.solvers.start import contact_start, start_modes
    from mcchain.solvers.statics import start_multipliers

    if int(assembled.status[0]) != 0:
        return ["initial state: cannot be assembled"]
    one = model.select(0, 1)
    placed = contact_start(
        one, assembled.q[:1].copy(), assembled.v[:1].copy(), assembled.status[:1].copy()
    )
    if int(placed[2][0]) != 0:
        return ["initial state: the contact start cannot be closed around its journals"]
    q, v = placed[0][0], placed[1][0]
    lines = ["initial state at t = 0 (assembled):"]
    for b, name in enumerate(model.body_names):
        x, y, th = q[3 * b : 3 * b + 3]
        vx, vy, w = v[3 * b : 3 * b + 3]
        lines.append(
            f"  {name}: position [{_fmt(x)}, {_fmt(y)}] m, angle {_fmt(th)} rad, "
            f"velocity [{_fmt(vx)}, {_fmt(vy)}] m/s, angular velocity {_fmt(w)} rad/s"
        )
    clearance = np.flatnonzero(model.joint_kind == JointKind.CLEARANCE)
    if clearance.size:
        modes = start_modes(model, q[np.newaxis])[0]
        lam = start_multipliers(model, q, v)  # every clearance joint on the link
        law = (np.asarray(model.joint_model) != 0) & (modes != START_LINK)
        # model auto on the wall starts on the link only where the link pushes
        law |= (np.asarray(model.joint_model) != 0) & (lam[model.joint_row] <= 0.0)
        if law.any():
            lam = start_multipliers(model, q, v, law=law)
        km = model.kernel_model()
        for k in clearance:
            dx, dy = joint_vectors(km, 0, q, int(k))[4:]
            gap = float(np.hypot(dx, dy) - model.joint_clearance[0, k])
            force = float(lam[int(model.joint_row[k])])
            if not law[k]:
                start = "the link" + (" (model auto)" if model.joint_model[k] != 0 else "")
                state = "holds" if force > 0 else "lost at the start: the journal is pulled off"
                text = f"link force {_fmt(force)} N: contact {state}"
            else:
                where = (
                    "seated on the wall"
                    if modes[k] in (START_SEATED, START_LINK)
                    else "pressed in"
                    if gap > 0
                    else "free"
                )
                start = f"the contact law, {where}"
                text = f"contact force {_fmt(force)} N (K max(|d| - c, 0)^m, undamped)"
            lines.append(
                f"  {model.joint_names[k]}: |d| {_fmt(float(np.hypot(dx, dy)))} m at "
                f"{_fmt(float(np.arctan2(dy, dx)))} rad (eccentricity), |d| - c {_fmt(gap)} m; "
                f"starts on {start}: {text}"
            )
    return lines
