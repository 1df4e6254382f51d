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
        "rk4": "a058d893986098a6d4e9774b1f0c18e8c00f78439f062b4df0308094acd29b0a",
        "rk4-projection": "ff806b0b6f351db088f768634b18d58b625e4dd48c605e8a75c48e7d02766f3a",
        "rk45": "504eb26c5ee36f0faacd94435ce822e3d15dd61c5887c68de71a878f2718deb9",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "6df9b9e5d5f07cce7430bd72ac48662afab444e79b9123bcbc0fe5756e4bb9c6",
        "rk4-projection": "db0d39e9ca5f9a9fb835a1e4f35da5d09ec19306fdcb8a93a631c1c26b34b4d3",
        "rk45": "0e074d917d16a14184587c8a202e3c621643f1bc19003cb0c37354c6774aa04c",
    },
    "fourbar-clearance-auto": {
        "accel": "dc018914fd8d8011f89027f6b908dcfbe353c7063075d0bbe07e006842592e29",
        "rk4": "98959a77a5c1ec6d7295563a1b89003fc4e12e9826fdb051e515df867fa412e8",
        "rk4-projection": "c954988bb05bee58b8fe10390132ceed7f3fc334166f3610547ff158aad416e2",
        "rk45": "9ea080838591f8c0f5dd0907cf4e184013792004b9e7b70b5bfd09ecb7920854",
    },
    "chain4-mixed-spring": {
        "accel": "6374ec1e710b673fe61e05d1693e4fc89dd5383778283e6d3d3a9f33bd2489f6",
        "rk4": "c72bee9e1174c7d9dcbd0c191ffbb49e7458426e1141c184837e39c01587401c",
        "rk4-projection": "9696cf51c5d2e9377400c90c4060631222fae2debeab88b8072bd0ce209a86d0",
        "rk45": "eb8485813c495e4c4afaa25d4b1fc3c1d122fd0b4c718d03c580161243290427",
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


FUNCTIONS = {
    "accel": {"accel", "outputs"},
    "rk4": {"erk_run", "group_outputs_erk"},
    "rk4-projection": {
        "erk_project_run",
        "group_outputs_erkp",
        "group_project_erkp",
    },
    "rk45": {"adaptive_run", "group_outputs_dp", "group_first_stage_dp", "group_stage_dp"},
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
