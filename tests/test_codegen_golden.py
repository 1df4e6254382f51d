"""codegen: the generated lane-kernel text, pinned by SHA-256 for three topologies and
each variant of the module (the functions one method calls).

A move or rename inside the generator must leave these hashes alone; a change of the generated
text updates them in the same commit and says so. A module with contact-law joints carries a
digest of ``mcchain/kernels/contact.py`` (numba's cache key): an edit there changes its hash.
The work-row length is pinned to 4 (AVX2) so the hashes do not depend on the CPU that runs the
test.
"""

from __future__ import annotations

import ast
import hashlib
import re
from pathlib import Path

import pytest

from mcchain.codegen.generate import VARIANTS, generate_source
from mcchain.codegen.schedule import INDEPENDENT_MARK
from mcchain.codegen.topology import Topology
from mcchain.scene import compile_model, load_scene, load_scene_text
from mcchain.testing.factory import chain_scene_text

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
LMAX_PINNED = 4  # one AVX2 register of doubles; the text depends on the row length

GOLDEN = {
    "double-pendulum-clearance": {
        "accel": "4ad99df1961cea05c65fe9ec5babf7f0f64b99deba91ed4c4c50d25378c28193",
        "rk4": "9f156c65ffc3ab0946b9bd9270ed4d8ebadc4da5c200442f18e1c99201441771",
        "rk4-projection": "98a6783df78cd2847cbb08838bba7377bf5aafec7e9997253d3006384d925e32",
        "rk45": "58de507d27c547c6f81c62a647291a6966bfc546bb950923a29c743a25b5c10a",
    },
    "fourbar-clearance": {
        "accel": "ea24d2a29ea8272d76dd4172106ca88d596b1af8de51adbbeb3acd31218a0ccd",
        "rk4": "f374ac03fbe044704a38d30590eeab26d89523b1ab296b33186972f7e01768f5",
        "rk4-projection": "564dbd11f08a825da2ffac9150f899a0933ff8d780bcfc59715a3df8f493e215",
        "rk45": "7cfdf883dc1b5ede191b4b78d10d295c3e1545c8b87211f0da3ea4e5d888dc44",
    },
    "fourbar-clearance-auto": {
        "accel": "9e998cbf8cab1466aebb82c786e72ab9cf119cb6744a33e46b5e8ca5541bcebb",
        "rk4": "6b3150d77bcb8c9ab1e1637f5b6247d842259e5571b7863b9331c04806c77d5a",
        "rk4-projection": "ae0c084b1b9528f2318faee48f6352d2c0e0ad337e0aa71e74131f2b5e5f2ea1",
        "rk45": "a13ac221a384c4c06ae91c30aefc8c1a43e4352609f8536cc1e7c669d1b2da33",
    },
    "chain4-mixed-spring": {
        "accel": "105998c4aa9ba3f47261e2b8863082059c91f9411f0f49b2357f76e72a25c167",
        "rk4": "038b7d7ccb1b29f28eaeb3827b8017b23496bafaf73a4758dba08bb78e616168",
        "rk4-projection": "bb44252d9160f3653a2f48d7038bbb3f413eb2e2b78c727abd0659bedae95ace",
        "rk45": "faaa738f95b3d7639fb95a2de21954ea41ad531ebb0df59ef66784023c016cc7",
    },
}


def _topology(name: str) -> Topology:
    if name == "chain4-mixed-spring":
        text = chain_scene_text(4, {1, 3}, 11, springs=1, forces=1, equilibrium=False, modes=False)
        return Topology.from_model(compile_model(load_scene_text(text, name=name)))
    if name == "fourbar-clearance":  # the link model at B (the paper's)
        text = (CONFIGS / "fourbar-clearance.toml").read_text()
        text = text.replace('model = "auto"', 'model = "link"').replace("rk45", "rk4")
        return Topology.from_model(compile_model(load_scene_text(text, name=name)))
    if name == "fourbar-clearance-auto":  # the shipped config: B under the contact law
        return Topology.from_model(compile_model(load_scene(CONFIGS / "fourbar-clearance.toml")))
    return Topology.from_model(compile_model(load_scene(CONFIGS / f"{name}.toml")))


@pytest.mark.parametrize(
    ("name", "variant"), [(name, v) for name, hashes in GOLDEN.items() for v in hashes]
)
def test_generate_source__text_matches_the_golden_hash(name, variant):
    source = generate_source(_topology(name), variant, lmax=LMAX_PINNED)
    assert hashlib.sha256(source.encode()).hexdigest() == GOLDEN[name][variant]


def test_generate_source__every_variant_is_pinned():
    assert all(set(hashes) == set(VARIANTS) for hashes in GOLDEN.values())


PEAK_FUNCTIONS = ("cubic_peak", "peak_last")  # mcchain.kernels.peaks, copied
FUNCTIONS = {
    "accel": {"accel", "outputs"},
    "rk4": {"erk_run", "group_outputs_erk", *PEAK_FUNCTIONS},
    "rk4-projection": {
        "erk_project_run",
        "group_outputs_erkp",
        "group_project_erkp",
        *PEAK_FUNCTIONS,
    },
    "rk45": {
        "adaptive_run",
        "group_outputs_landed_dp",
        "group_first_stage_dp",
        "group_stage_dp",
        *PEAK_FUNCTIONS,
    },
}


@pytest.mark.parametrize("variant", list(FUNCTIONS))
def test_generate_source__a_variant_holds_only_the_functions_it_calls(variant):
    source = generate_source(_topology("fourbar-clearance"), variant, lmax=LMAX_PINNED)
    assert set(re.findall(r"^def (\w+)\(", source, re.MULTILINE)) == FUNCTIONS[variant]


PURE_CALLS = {"abs", "max", "min", "math.sqrt", "float", "int"}


def _lane_index_ok(array: str, index: ast.expr) -> bool:
    """Lane ``l``'s own element: ``W[c + l]`` with ``c`` a whole number of work rows,
    ``W[(row) * LMAX + l]``, or ``out[sl, ...]`` (``sl`` the lane's sample: ``s0 + l``, or
    the lane's ``smp`` row) with ``l`` nowhere else."""
    items = index.elts if isinstance(index, ast.Tuple) else [index]
    uses_l = [any(isinstance(n, ast.Name) and n.id == "l" for n in ast.walk(i)) for i in items]
    text = ast.unparse(items[0])
    if array == "W" and len(items) == 1:
        if m := re.fullmatch(r"(\d+) \+ l", text):
            return int(m.group(1)) % LMAX_PINNED == 0
        row = re.fullmatch(rf"\((.+)\) \* {LMAX_PINNED} \+ l", text)
        return row is not None and not re.search(r"\bl\b", row.group(1))
    return text == "sl" and not any(uses_l[1:])


@pytest.mark.parametrize(
    ("name", "variant"), [(name, v) for name, hashes in GOLDEN.items() for v in hashes]
)
def test_generate_source__independent_lane_loops_touch_only_their_lane(name, variant):
    """Each loop marked ``# lanes: independent`` (LLVM is told its iterations touch
    disjoint memory, ``mcchain.codegen.native``) reads and writes only lane ``l``'s
    elements and calls no function of the module; the scheduled stage bodies and the
    outputs are marked (``accel``, called per sample from Python, has none)."""
    source = generate_source(_topology(name), variant, lmax=LMAX_PINNED)
    lines = source.splitlines()
    marked = [
        node
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.For) and lines[node.lineno - 1].endswith(INDEPENDENT_MARK)
    ]
    assert len(marked) == source.count(INDEPENDENT_MARK)
    assert len(marked) >= (0 if variant == "accel" else 2)  # stage bodies and the outputs
    for loop in marked:
        assert ast.unparse(loop.target) == "l"
        samples = [ast.unparse(n.value) for n in ast.walk(loop) if isinstance(n, ast.Assign)
                   and ast.unparse(n.targets[0]) == "sl"]  # fmt: skip
        # the lane's sample: s0 + l (a lane group's lanes in order) or its smp row
        assert all(s == "s0 + l" or _lane_index_ok("W", ast.parse(s[4:-1], mode="eval").body.slice)
                   for s in samples), samples  # fmt: skip
        for node in ast.walk(loop):
            if isinstance(node, ast.Subscript):
                assert _lane_index_ok(ast.unparse(node.value), node.slice), ast.unparse(node)
            if isinstance(node, ast.Call) and ast.unparse(node.func) != "range":
                assert ast.unparse(node.func) in PURE_CALLS, ast.unparse(node)
