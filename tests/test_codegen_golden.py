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
        "accel": "769ae1636e4f9d307cea35946b4cf32754755a3563c4dc23556ebe4336498bc8",
        "rk4": "1377c010d32561d60de3560164b6156e5fe97150a4c2141e59e5508cf7d429ac",
        "rk4-projection": "b2f6470fa65fa0fa43669cf68336ec8a32dd84d0c6d1b5efa48b50a252f42ce2",
        "rk45": "f4cc0cceec6fd8b66cf4966b71d3453f06a2f00dcf8e57dfb5b949098396ee61",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "b26a3a2819c6dd338502355d2db6ed730bfd19e7546465c960de0656a780ec87",
        "rk4-projection": "b0dcaf925a312242dd1cfc7bb11e1ddfe0ce307dac17cd47df3f6b4dfd88df30",
        "rk45": "90b78fa1422619920fb24e840e68a87e9af0f04278d806817f32cfbc265eeedd",
    },
    "fourbar-clearance-auto": {
        "accel": "6a44c7cefc23ab8e36f71a24779fd0051f5e4cc3454e467114545cbe9c9fc7df",
        "rk4": "92ef80981446dc780229106b1545f78ab7c3710efe57296b5879d378579a3f82",
        "rk4-projection": "cf6ff0f2cefb04bd8d6ceb4ae0900d8806b8a960732a18be9fb88d98ec9733ef",
        "rk45": "7f3b293a0ec3345467374dc3b36160a574a3390cff3c7c367399d33cd35eefe6",
    },
    "chain4-mixed-spring": {
        "accel": "4d04a603ee6b60d207852da239fbcd306aa299bb3461268e7f5f4a09d4e73afc",
        "rk4": "872034756a03efca963c2ba9249e32a36f2f75c274455824a1eb56c1b55ad454",
        "rk4-projection": "858b54a24107904f9e7a760f820b23d05a6d2fd6b87ef2052eea29f17db7e889",
        "rk45": "211510c912a758a548f7187193dad470c73c3f9e508700ac4f7c4952b0eb4299",
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


PEAK_FUNCTIONS = ("cubic_peak", "peak_feed", "peak_last")  # mcchain.kernels.peaks, copied
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
        "group_outputs_dp",
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
    ``W[(row) * LMAX + l]``, or ``out[s0 + l, ...]`` with ``l`` nowhere else."""
    items = index.elts if isinstance(index, ast.Tuple) else [index]
    uses_l = [any(isinstance(n, ast.Name) and n.id == "l" for n in ast.walk(i)) for i in items]
    text = ast.unparse(items[0])
    if array == "W" and len(items) == 1:
        if m := re.fullmatch(r"(\d+) \+ l", text):
            return int(m.group(1)) % LMAX_PINNED == 0
        row = re.fullmatch(rf"\((.+)\) \* {LMAX_PINNED} \+ l", text)
        return row is not None and not re.search(r"\bl\b", row.group(1))
    return text == "s0 + l" and not any(uses_l[1:])


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
        for node in ast.walk(loop):
            if isinstance(node, ast.Subscript):
                assert _lane_index_ok(ast.unparse(node.value), node.slice), ast.unparse(node)
            if isinstance(node, ast.Call) and ast.unparse(node.func) != "range":
                assert ast.unparse(node.func) in PURE_CALLS, ast.unparse(node)
