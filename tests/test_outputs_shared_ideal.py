"""``relative_to = "ideal"`` with one ideal mechanism for every sample: when no sampled
parameter reaches the ideal mechanism (decided from its model: the parameters its kernels
read and its start state), rk45 integrates it once per chunk at a tight tolerance and reads
it from a table (:func:`mcchain.solvers.ideal.tabulated_plan`), instead of integrating an
ideal copy beside every sample. The mechanism's own integration is unchanged (every other
variable bit for bit); the relative output moves by the copy's own integration error."""

from __future__ import annotations

import numpy as np
import pytest

import mcchain.solvers.ideal as ideal_module
from mcchain.codes import OUTPUT_POSITION
from mcchain.kernels.outputs import REFERENCE_HEAD, REFERENCE_WIDTH, reference_signal
from mcchain.scene import compile_model, load_scene_text
from mcchain.solvers import solve_chunk
from mcchain.solvers.ideal import ideal_model, shared_ideal
from mcchain.solvers.start import start_state
from mcchain.solvers.statics import assemble
from mcchain.testing.scenes import config_text, with_lines

TABLE_AGAINST_COPY = 1e-12
"""m: the tabulated ideal slider against the copy's (integrated at the mechanism's steps,
rtol 1e-7): found 1.3e-14 on the shipped scene's 64 first samples."""


def _scene(vary: str, count: int = 6):
    """The shipped requirement scene, 4 ms, ``count`` samples, its second sampled parameter
    ``vary`` (a line of ``[sample.vary]``), no histories stored."""
    text = config_text("slider-crank-requirement.toml")
    lines = {"t_end": "t_end = 0.004", "count": f"count = {count}"}
    lines["window"] = "window = [0.002, 0.004]"
    lines['"joint.B.contact.restitution"'] = vary
    text = with_lines(text, lines).replace("[sample]", '[storage]\nhistories = "none"\n\n[sample]')
    return load_scene_text(text)


PIN_ONLY = '"joint.B.contact.restitution" = { uniform = [0.7, 0.95] }'
ROD_MASS = '"body.rod.mass" = { uniform = [0.2, 0.22] }'


def _ideal_start(scene):
    model = compile_model(scene)
    ideal = ideal_model(model)
    start = assemble(ideal)
    return start_state(ideal, scene.simulate, start.q, start.v, start.status)


@pytest.mark.parametrize(("vary", "shared"), [(PIN_ONLY, True), (ROD_MASS, False)])
def test_shared_ideal__decided_from_the_ideal_model(vary, shared):
    """The pin's clearance and restitution do not reach the ideal slider-crank (the pin made
    ideal); the rod's mass does."""
    scene = _scene(vary)
    ideal = ideal_model(compile_model(scene))
    q, v, status = _ideal_start(scene)
    assert shared_ideal(ideal, q, v, status) is shared


def _copy_path(monkeypatch, model, scene):
    with monkeypatch.context() as patch:
        patch.setattr(ideal_module, "shared_ideal", lambda *args: False)
        return solve_chunk(model, scene)


def test_tabulated_ideal__the_copy_s_values_and_every_other_variable_bit_for_bit(monkeypatch):
    scene = _scene(PIN_ONLY)
    model = compile_model(scene)
    table, copy = solve_chunk(model, scene), _copy_path(monkeypatch, model, scene)
    assert set(table) == set(copy)
    for name, value in copy.items():
        if name != "slider_error":
            assert np.asarray(table[name]).tobytes() == np.asarray(value).tobytes(), name
    assert np.isfinite(copy["slider_error"]).all()
    assert np.max(np.abs(table["slider_error"] - copy["slider_error"])) <= TABLE_AGAINST_COPY


def test_tabulated_ideal__not_taken_where_a_sampled_parameter_reaches_it(monkeypatch):
    scene = _scene(ROD_MASS)
    model = compile_model(scene)
    run, copy = solve_chunk(model, scene), _copy_path(monkeypatch, model, scene)
    for name, value in copy.items():
        assert np.asarray(run[name]).tobytes() == np.asarray(value).tobytes(), name


def test_tabulated_ideal__the_same_bits_whatever_the_chunks():
    """Each chunk integrates the one ideal mechanism from the same start: a sample's output
    does not depend on the chunk it is solved in (nor on the first sample of its chunk)."""
    scene = _scene(PIN_ONLY)
    model = compile_model(scene)
    whole = solve_chunk(model, scene)
    parts = [solve_chunk(model.select(a, b), scene) for a, b in ((0, 1), (1, 4), (4, 6))]
    for name in ("slider_error", "pin_force_after_startup", "status"):
        joined = np.concatenate([p[name] for p in parts])
        assert joined.tobytes() == np.asarray(whole[name]).tobytes(), name


def test_reference_signal__exact_on_a_cubic_and_between_uneven_knots():
    """The cubic Hermite interpolant reproduces a cubic and its rate exactly (to rounding),
    on every interval, the last shorter one too, and at the knots themselves."""
    times = np.append(np.arange(0.0, 0.95, 0.1), 0.97)  # the last interval shorter

    def f(t):
        return 2.0 * t**3 - t**2 + 0.5 * t - 1.0

    def rate(t):
        return 6.0 * t**2 - 2.0 * t + 0.5

    data = np.zeros((1, 2, REFERENCE_HEAD + REFERENCE_WIDTH * len(times)))
    k = 1
    data[0, k, 5], data[0, k, 6] = len(times), 0.1
    knots = np.stack([times, f(times), -f(times), rate(times), -rate(times)], axis=1)
    data[0, k, REFERENCE_HEAD:] = knots.reshape(-1)
    for t in [0.0, 0.05, 0.1, 0.333, 0.899999, 0.9, 0.93, 0.97, *times]:
        x, y, rx, ry = reference_signal(data, k, t)
        assert x == pytest.approx(f(t), abs=1e-14) and y == pytest.approx(-f(t), abs=1e-14)
        assert rx == pytest.approx(rate(t), abs=1e-12) and ry == pytest.approx(-rate(t), abs=1e-12)


def test_tabulated_plan__only_for_outputs_whose_rate_is_in_the_state():
    """A relative output of a kind without its rate in the state (a velocity, a force)
    keeps the ideal copy: no table."""
    from mcchain.solvers.ideal import tabulated_plan
    from mcchain.solvers.output_plan import output_plan

    scene = _scene(PIN_ONLY)
    model = compile_model(scene)
    q, v, _status = _ideal_start(scene)
    plan = output_plan(scene.output, model, scene.simulate.t_end)
    ideal = ideal_model(model.select(0, 1))
    tabulated = tabulated_plan(ideal, q[:1], v[:1], scene.simulate, plan)
    assert tabulated is not None
    k = plan.names.index("slider_error")
    assert plan.spec[k, 0] == OUTPUT_POSITION and tabulated.spec[k, 3] == -2
    velocity = [o.model_copy(update={"of": "velocity"}) for o in scene.output]
    plan = output_plan(velocity, model, scene.simulate.t_end)
    assert tabulated_plan(ideal, q[:1], v[:1], scene.simulate, plan) is None


def _run(tmp_path, name: str, **options):
    from mcchain.runner import plan

    path = tmp_path / "scene.toml"
    if not path.exists():
        text = config_text("slider-crank-requirement.toml")
        lines = {"t_end": "t_end = 0.004", "count": "count = 6"}
        lines["window"] = "window = [0.002, 0.004]"
        path.write_text(with_lines(text, lines), encoding="utf-8")
    options = {"chunk_size": 6, "threads": 1, **options}
    return plan.start_run(path, run_dir=tmp_path / name, progress=False, **options).folder


def test_tabulated_ideal__runs_byte_identical_whatever_the_chunks_and_threads(tmp_path):
    import filecmp

    one = _run(tmp_path, "one")
    other = _run(tmp_path, "chunks", chunk_size=4, threads=2)
    assert filecmp.cmp(one / "ensemble.nc", other / "ensemble.nc", shallow=False)


@pytest.mark.slow
def test_tabulated_ideal__runs_byte_identical_on_dask(tmp_path):
    import filecmp

    one = _run(tmp_path, "one")
    other = _run(tmp_path, "dask", chunk_size=2, threads=2, dask="local")
    assert filecmp.cmp(one / "ensemble.nc", other / "ensemble.nc", shallow=False)
