"""The lanes' ``[[output]]``s: the scalar per-lane code that
:func:`mcchain.codegen.generate.generate_source` puts into the templates' ``@@outputs_*``
blocks, and the reduction functions it copies into the generated module.

At every accepted state (the fixed step: each step's start, with the first stage's q̈ and
λ; the adaptive step: each accepted state, with the last stage's) each output's signal and
rate are computed from the lane's rows — a body's quantity by
:func:`mcchain.kernels.outputs.body_signal` inlined (with the lane's own sine and cosine),
a joint's from the emitter's outputs (its force, normal force) or its Φ̇ (a penetration's
rate), a driver's from λ — and fed to the same reduction the loop kernels run
(:mod:`mcchain.kernels.outputs`, copied). A scene without outputs gets empty blocks: its
text, and so its kernels, are those of a build without this module.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

from mcchain.codegen.emitter import Emitter
from mcchain.codegen.layout import OUTPUT_SAMPLE_COLUMNS, Layout
from mcchain.codegen.schedule import INDEPENDENT_MARK
from mcchain.codegen.sincos import sincos_code
from mcchain.codegen.topology import Topology
from mcchain.codes import (
    OUTPUT_ANGULAR_VELOCITY,
    OUTPUT_CONTACT_FORCE,
    OUTPUT_JOINT_FORCE,
    OUTPUT_PENETRATION,
    OUTPUT_TABULATED_REFERENCE,
    OUTPUT_WIDTH,
)

OUTPUT_KERNELS = "mcchain.kernels.outputs"
"""The module whose functions define the outputs for the loop kernels and the lanes."""
OUTPUT_BLOCKS = ("outputs_setup", "outputs_c", "outputs_feed", "outputs_finish")
Signature = tuple[tuple[int, ...], ...]
"""The outputs' structure (:attr:`mcchain.solvers.outputs.OutputPlan.signature`): per
output kind, component, item, the ideal copy's item, reduce, with rate."""


def output_blocks(topo: Topology, lay: Layout, outputs: Signature) -> dict[str, str]:
    """The per-lane code of the outputs ``outputs`` (empty blocks without)."""
    if not outputs:
        return dict.fromkeys(OUTPUT_BLOCKS, "")
    at = lay.at
    base = [f"{(lay.rows['ot'] + OUTPUT_WIDTH * k) * lay.lmax} + l" for k in range(len(outputs))]
    # Lane l takes sample sl (setup) and has finished it (finish; ``dead``: its failure).
    setup = [f"outputs_start(W, {b}, {lay.lmax})" for b in base]
    finish = [
        f"cnt = {at('otk', 4)}",
        *(f"t{x} = {at('otk', i)}" for i, x in enumerate("abcd")),
        "row = sl % ot_in.shape[0]",
    ]
    for k, (_kind, _component, _item, _ref, reduce, rate) in enumerate(outputs):
        window = f"ot_in[row, {k}, 2], ot_in[row, {k}, 3], ot_in[row, {k}, 4]"
        finish += [
            f"output_last(W, {base[k]}, {lay.lmax}, cnt, ta, tb, tc, td, {float(rate)!r}, "
            f"{window}, {reduce})",
            f"out_ot[sl, {k}] = np.nan if dead else output_value(W, {base[k]}, "
            f"{lay.lmax}, {reduce})",
        ]
    # Fed lane by lane: the fixed step every lane at each step's start; the adaptive step
    # each running lane at its accepted state (its sample in row smp).
    blocks = {"outputs_setup": "\n".join(setup), "outputs_finish": "\n".join(finish)}
    if "smp" in lay.rows:  # the adaptive kernel's layout
        columns = range(OUTPUT_SAMPLE_COLUMNS)
        blocks["outputs_setup"] += "\n" + "\n".join([
            "row = sl % ot_in.shape[0]",
            *(f"{at('otd', OUTPUT_SAMPLE_COLUMNS * k + c)} = ot_in[row, {k}, {c}]"
              for k in range(len(outputs)) for c in columns),
        ])  # fmt: skip
        blocks["outputs_feed"] = _lanes_feed(topo, lay, outputs, base)
        blocks["outputs_c"] = ""
    else:
        # (the step's start: its first stage's accelerations in rows kv0)
        fixed = _feed(topo, lay, outputs, base, "ts", "kv0", "lamc", "s0 + l")
        blocks["outputs_c"] = "for l in range(nl):\n" + _indented(fixed, 4)
        blocks["outputs_feed"] = ""
    return blocks


def _indented(text: str, indent: int) -> str:
    return "\n".join(" " * indent + line if line else "" for line in text.splitlines())


def _feed(
    topo: Topology,
    lay: Layout,
    outputs: Signature,
    base: list[str],
    t: str,
    acc: str,
    lam: str,
    sample: str,
) -> str:
    """Feed every output at the lane's state (rows q, v; accelerations in rows ``acc``,
    multipliers in rows ``lam``) at time ``t``, unless ``t`` is not after the last fed;
    ``sample``: the lane's sample (its row of ``ot_in``)."""
    at = lay.at
    lines = _signals(topo, lay, outputs, t, acc, lam, f"row = ({sample}) % ot_in.shape[0]",
                     lambda k, c: f"ot_in[row, {k}, {c}]", _reference_call)  # fmt: skip
    feeds = []
    for k, (_kind, _component, _item, _ref, reduce, rate) in enumerate(outputs):
        window = f"ot_in[row, {k}, 2], ot_in[row, {k}, 3], ot_in[row, {k}, 4], {reduce}"
        if rate:
            feeds.append(
                f"hermite_feed(W, {base[k]}, {lay.lmax}, cnt, td, tf, of{k}, or{k}, {window})"
            )
        else:
            feeds.append(
                f"cubic_feed(W, {base[k]}, {lay.lmax}, cnt, tb, tc, td, tf, of{k}, {window})"
            )
    body = [
        f"cnt = {at('otk', 4)}",
        f"if cnt == 0.0 or {t} > {at('otk', 3)}:",
        *(f"    t{x} = {at('otk', i + 1)}" for i, x in enumerate("bcd")),
        *("    " + line for line in lines),
        *("    " + line for line in feeds),
        f"    {at('otk', 0)} = tb",
        f"    {at('otk', 1)} = tc",
        f"    {at('otk', 2)} = td",
        f"    {at('otk', 3)} = tf",
        f"    {at('otk', 4)} = min(cnt + 1.0, 4.0)",
    ]
    return "\n".join(body)


def _lanes_feed(topo: Topology, lay: Layout, outputs: Signature, base: list[str]) -> str:
    """The adaptive kernel's feed of every running lane at its accepted state (rows q, v,
    kv0, lam; its time tl), where it is after the last state fed (a rejected step's is met
    again). Four loops over the lanes: the new-state flag (``run`` is an array of its own)
    and the tabulated references (a table lookup that branches); every lane's signals and
    its plain steps (:mod:`mcchain.kernels.output_steps`, inlined) at once, branch-free,
    its state written through the flag; the full feed (:func:`mcchain.kernels.outputs.
    hermite_feed`, ``cubic_feed``) lane by lane for the steps left (a new extreme, a window
    edge, the first steps of a cubic); the clocks. The same numbers as one feed a lane."""
    from mcchain.kernels.outputs import FA, FB, FC, FD, HI, LO, RD, SPAN

    at = lay.at
    lmax = lay.lmax
    n = len(outputs)
    first = [
        "for l in range(nl):",
        f"    cnt = {at('otk', 4)}",
        f"    {at('ofs')} = 1.0 if run[l] and (cnt == 0.0 or {at('tl')} > {at('otk', 3)}) else 0.0",
    ]
    # the reference's values the signal reads (a component: its x or y and rate), by row
    names = ("rfx", "rfy", "rrx", "rry")
    components = [component for _kind, component, *_rest in outputs]
    read = [[0, 1, 2, 3] if c == 2 else ([1, 3] if c == 1 else [0, 2]) for c in components]
    for k, (_kind, _component, _item, ref, _reduce, _rate) in enumerate(outputs):
        if ref == OUTPUT_TABULATED_REFERENCE:
            first.append(f"    rfx{k}, rfy{k}, rrx{k}, rry{k} = reference_signal(ot_in, {k}, "
                         f"{at('tl')})")  # fmt: skip
            first += [f"    {at('ofr', 4 * k + i)} = {names[i]}{k}" for i in read[k]]

    def data(k: int, c: int) -> str:
        return at("otd", OUTPUT_SAMPLE_COLUMNS * k + c)

    def reference(k: int) -> str:
        return "\n".join(f"{names[i]}{k} = {at('ofr', 4 * k + i)}" for i in read[k])

    em = Emitter(topo)
    em.emit(f"fresh = {at('ofs')} > 0.0", f"cnt = {at('otk', 4)}",
            *(f"t{x} = {at('otk', i + 1)}" for i, x in enumerate("bcd")))  # fmt: skip
    em.emit(*_signals(topo, lay, outputs, at("tl"), "kv0", "lam", "", data, reference))
    steps = "mcchain.kernels.output_steps"
    for k, (_kind, _component, _item, _ref, reduce, rate) in enumerate(outputs):
        ot = lay.rows["ot"] + OUTPUT_WIDTH * k

        def w(offset: int, ot: int = ot) -> str:
            return f"W[{(ot + offset) * lmax} + l]"

        window = [data(k, 2), data(k, 3), str(reduce), w(HI), w(LO)]
        if rate:
            em.emit(f"f0_{k} = {w(FD)}", f"r0_{k} = {w(RD)}")
            arguments = ["cnt", "td", f"f0_{k}", f"r0_{k}", "tf", f"of{k}", f"or{k}", *window]
            settled, reduced, hi, lo = em.kernel(steps, "hermite_settles", arguments, f"_s{k}")
            span = "(tf - td)"
        else:
            em.emit(f"fb{k} = {w(FB)}", f"fc{k} = {w(FC)}", f"fd{k} = {w(FD)}")
            arguments = ["cnt", "tb", "tc", "td", "tf", f"fb{k}", f"fc{k}", f"fd{k}", f"of{k}",
                         *window]  # fmt: skip
            settled, reduced, hi, lo = em.kernel(steps, "cubic_settles", arguments, f"_s{k}")
            span = "(td - tc)"
        em.emit(
            f"ok{k} = {settled}",
            f"red{k} = fresh and ({reduced})",
            f"{w(SPAN)} = {w(SPAN)} + {span} if red{k} else {w(SPAN)}",
            f"{w(HI)} = {hi} if red{k} else {w(HI)}",
            f"{w(LO)} = {lo} if red{k} else {w(LO)}",
            f"shift{k} = fresh and ok{k}",
        )
        if rate:
            em.emit(f"{w(FD)} = of{k} if shift{k} else f0_{k}",
                    f"{w(RD)} = or{k} if shift{k} else r0_{k}")  # fmt: skip
        else:
            em.emit(f"{w(FA)} = fb{k} if shift{k} else {w(FA)}",
                    f"{w(FB)} = fc{k} if shift{k} else fb{k}",
                    f"{w(FC)} = fd{k} if shift{k} else fc{k}",
                    f"{w(FD)} = of{k} if shift{k} else fd{k}")  # fmt: skip
        em.emit(
            f"{at('ofl', k)} = 1.0 if fresh and not ok{k} else 0.0",
            f"{at('ofv', 2 * k)} = of{k}",
            f"{at('ofv', 2 * k + 1)} = or{k}",
        )
    plain = [f"for l in range(nl):  {INDEPENDENT_MARK}", em.take(4)]
    left = [
        "for l in range(nl):",
        f"    if {' + '.join(at('ofl', k) for k in range(n))} > 0.0:",
        f"        cnt = {at('otk', 4)}",
        *(f"        t{x} = {at('otk', i + 1)}" for i, x in enumerate("bcd")),
        f"        tf = {at('tl')}",
    ]
    for k, (_kind, _component, _item, _ref, reduce, rate) in enumerate(outputs):
        bounds = f"{data(k, 2)}, {data(k, 3)}, {data(k, 4)}, {reduce}"
        value = at("ofv", 2 * k)
        call = (
            f"hermite_feed(W, {base[k]}, {lmax}, cnt, td, tf, {value}, {at('ofv', 2 * k + 1)}, "
            f"{bounds})"
            if rate
            else f"cubic_feed(W, {base[k]}, {lmax}, cnt, tb, tc, td, tf, {value}, {bounds})"
        )
        left += [f"        if {at('ofl', k)} > 0.0:", f"            {call}"]
    fed = at("ofs") + " > 0.0"
    clock = [
        f"for l in range(nl):  {INDEPENDENT_MARK}",
        *(f"    {at('otk', i)} = {at('otk', i + 1)} if {fed} else {at('otk', i)}"
          for i in range(3)),
        f"    {at('otk', 3)} = {at('tl')} if {fed} else {at('otk', 3)}",
        f"    {at('otk', 4)} = min({at('otk', 4)} + 1.0, 4.0) if {fed} else {at('otk', 4)}",
    ]  # fmt: skip
    return "\n".join([*first, *plain, *left, *clock])


def _reference_call(k: int) -> str:
    """The tabulated reference of output ``k`` at the feed's time ``tf``, from the table."""
    return f"rfx{k}, rfy{k}, rrx{k}, rry{k} = reference_signal(ot_in, {k}, tf)"


def _signals(
    topo: Topology,
    lay: Layout,
    outputs: Signature,
    t: str,
    acc: str,
    lam: str,
    row: str,
    data: Callable[[int, int], str],
    reference: Callable[[int], str],
) -> list[str]:
    """The lines that set ``of<k>``, ``or<k>``: each output's signal and rate at the lane's
    state at time ``t`` (``tf``); ``row``: a line before the state's (or empty), ``data(k,
    c)``: column c of output k's data, ``reference(k)``: the line that sets its tabulated
    reference ``rfx<k>, rfy<k>, rrx<k>, rry<k>``."""
    at = lay.at
    em = Emitter(topo)
    cj = {k: j for j, k in enumerate(topo.contact_joints)}
    em.contact_source(lambda name, k: at(name, cj[k]))
    em.load_params(lambda k: at("P", k))
    em.emit(
        f"tf = {t}",
        *([row] if row else []),
        *(f"q{i} = {at('q', i)}" for i in range(topo.ndof)),
        *(f"v{i} = {at('v', i)}" for i in range(topo.ndof)),
        *(f"oa{i} = {at(acc, i)}" for i in range(topo.ndof)),
        *(f"lam{r} = {at(lam, r)}" for r in range(topo.ncon)),
    )
    kinds = {kind for kind, *_ in outputs}
    forces = bool(kinds & {OUTPUT_JOINT_FORCE, OUTPUT_CONTACT_FORCE, OUTPUT_PENETRATION})
    if forces:
        em.outputs(t="tf")  # joint forces jfx, jfy, normal forces cf (and their geometry)
        if OUTPUT_PENETRATION in kinds:
            em.constraint_values(t="tf", v="v")  # Φ̇ of a clearance row: δ̇
    angles: set[int] = set()
    for k, (kind, component, item, ref, _reduce, _rate) in enumerate(outputs):
        values: list[tuple[str, ...]] = []
        for tag, index in (("m", item), ("r", ref)):
            if index < 0:
                continue
            if kind <= OUTPUT_ANGULAR_VELOCITY and index not in angles:
                angles.add(index)
                if forces:  # the forces' geometry computed this body's sin/cos (sn, cs)
                    em.emit(f"osn{index} = sn{index}", f"ocs{index} = cs{index}")
                else:
                    em.emit(*sincos_code(f"q{3 * index + 2}", f"osn{index}", f"ocs{index}",
                                         f"o{index}"))  # fmt: skip
            point = [data(k, 0), data(k, 1)]
            values.append(_signal(em, topo, kind, component if ref == -1 or component < 2 else -2,
                                  index, k, f"{tag}{k}", point))  # fmt: skip
        if ref == OUTPUT_TABULATED_REFERENCE:  # the ideal mechanism's, the same for all
            em.emit(*reference(k).splitlines())
            pick = "y" if component == 1 else "x"
            tabulated = (f"rfx{k}", f"rfy{k}", f"rrx{k}", f"rry{k}")
            values.append(tabulated if component == 2 else (f"rf{pick}{k}", f"rr{pick}{k}"))
        if ref == -1:
            (f, r) = values[0]
        elif component < 2:
            f, r = f"({values[0][0]}) - ({values[1][0]})", f"({values[0][1]}) - ({values[1][1]})"
        else:  # the magnitude of the difference of the two vectors
            (fx1, fy1, rx1, ry1), (fx2, fy2, rx2, ry2) = values
            arguments = [f"({fx1}) - ({fx2})", f"({fy1}) - ({fy2})", f"({rx1}) - ({rx2})",
                         f"({ry1}) - ({ry2})", "2.0"]  # fmt: skip
            f, r = em.kernel(OUTPUT_KERNELS, "vector_component", arguments, f"_d{k}")
        em.emit(f"of{k} = {f}", f"or{k} = {r}")
    return em.take(0).splitlines()


def _signal(
    em: Emitter,
    topo: Topology,
    kind: int,
    component: int,
    index: int,
    k: int,
    tag: str,
    point: list[str],
) -> tuple[str, ...]:
    """The expressions of one item's quantity (and its rate): (f, r), or with ``component``
    −2 the vector's (fx, fy, rx, ry) (a difference's magnitude is taken after)."""
    if kind <= OUTPUT_ANGULAR_VELOCITY:
        i = 3 * index
        state = [f"q{i}", f"q{i + 1}", f"q{i + 2}", f"v{i}", f"v{i + 1}", f"v{i + 2}",
                 f"oa{i}", f"oa{i + 1}", f"oa{i + 2}"]  # fmt: skip
        trig = [f"ocs{index}", f"osn{index}"]
        if component == -2:
            x = em.kernel(OUTPUT_KERNELS, "body_signal", [str(kind), "0", *trig, *state, *point],
                          f"_x{tag}")  # fmt: skip
            y = em.kernel(OUTPUT_KERNELS, "body_signal", [str(kind), "1", *trig, *state, *point],
                          f"_y{tag}")  # fmt: skip
            return x[0], y[0], x[1], y[1]
        arguments = [str(kind), str(component), *trig, *state, *point]
        return tuple(em.kernel(OUTPUT_KERNELS, "body_signal", arguments, f"_{tag}"))
    if kind == OUTPUT_JOINT_FORCE:
        if component == -2:
            return f"jfx{index}", f"jfy{index}", "0.0", "0.0"
        arguments = [f"jfx{index}", f"jfy{index}", "0.0", "0.0", str(component)]
        value, _rate = em.kernel(OUTPUT_KERNELS, "vector_component", arguments, f"_{tag}")
        return value, "math.nan"
    if kind == OUTPUT_CONTACT_FORCE:
        return f"cf{index}", "math.nan"
    if kind == OUTPUT_PENETRATION:
        return f"rho{index} - p_cl{index}", f"phid{topo.joint_row[index]}"
    return f"-lam{topo.driver_row[index]}", "math.nan"


def output_functions(with_hermite: bool) -> str:
    """The source of the reduction functions of :mod:`mcchain.kernels.outputs` (and its
    constants) copied into the generated module (for the reason of
    :func:`mcchain.codegen.generate._contact_functions`); ``with_hermite``: also the
    Hermite interpolant, which the contact functions do not bring."""
    from mcchain.kernels import contact, output_steps, outputs

    names = ("FA", "FB", "FC", "FD", "RD", "HI", "LO", "S1", "S2", "CROSS", "SPAN",
             "REFERENCE_HEAD", "REFERENCE_WIDTH")  # fmt: skip
    constants = [f"{name} = {getattr(outputs, name)!r}" for name in names]
    constants += [f"{name} = {getattr(outputs, name)!r}" for name in
                  ("GL_X0", "GL_X1", "GL_W0", "GL_W1")]  # fmt: skip
    constants += [f"{name} = {getattr(output_steps, name)!r}" for name in
                  ("THIRD", "HULL_ROUNDING")]  # fmt: skip
    constants.append(f"OUTPUT_WIDTH = {OUTPUT_WIDTH!r}")
    parts = ["\n".join(constants)]
    kernels = [contact._hermite] if with_hermite else []
    kernels += [
        output_steps.hull_clear,
        output_steps.cubic_gates,
        output_steps.extremes_only,
        output_steps.step_inside,
        output_steps.cubic_slope,
        output_steps.hermite_settles,
        output_steps.middle_step_plain,
        output_steps.cubic_settles,
        outputs.outputs_start,
        outputs._crossing,
        outputs.hermite_window,
        outputs.hermite_feed,
        outputs.cubic_window,
        outputs.cubic_feed,
        outputs.output_last,
        outputs.output_value,
        outputs.reference_signal,
    ]
    for kernel in kernels:
        source = inspect.getsource(kernel.py_func)
        parts.append("@njit(**JIT)\n" + source[source.index("def ") :])
    return "\n\n".join(parts)


__all__ = ["OUTPUT_BLOCKS", "Signature", "output_blocks", "output_functions"]
