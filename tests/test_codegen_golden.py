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
        "rk4": "13311a6d8a58800673184fb82cfed6b32a73623735eef89652bbe818f9b87c2b",
        "rk4-projection": "a2bf4f3c56325eb9be6fcb190cf6f71a280c0cdf2ab2be1ee2101440168c6357",
        "rk45": "8b7d12da6f95321c0bf1b26e917fc428c09c821b96891a250c84e0c08966c037",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "d4995475c1b9e6b7513fc1bfc1f4dfd6c5a262cfb3f97dd96db32d8dc597ff9f",
        "rk4-projection": "ba7f7028505d6b076f53bb67e8d1f4a0cb4d8ac4db2b8b4f197926184ae86f7f",
        "rk45": "cc8bf067f50d1246f68ff1c3ccc1e7867d91cba719927e77485e0f6b9dfb64de",
    },
    "fourbar-clearance-auto": {
        "accel": "a8f3d1ac7b829ca31c17b5a259664b33a309c49eabf87d090ffdcb552ee6d961",
        "rk4": "0d66cc72e7531da95c6ee539eade8ca480fb4f5b2d6ab4b5e5d7fa832bcc5f77",
        "rk4-projection": "4e180ea071e172631760f93d69babdf9ac85adebb1d1f1700cccf4b89ffe7d0c",
        "rk45": "87334ac45a45ada4214f6b4e25d1eb7cce1e6cafd20f183ed4c246728f540f43",
    },
    "chain4-mixed-spring": {
        "accel": "6374ec1e710b673fe61e05d1693e4fc89dd5383778283e6d3d3a9f33bd2489f6",
        "rk4": "9100b9c4cfdc688bd87075c9d30fec2dc4d2ab59e3034240064d2f2a0d1ef54b",
        "rk4-projection": "04f1e16b475865488f6b726272813cc59f280a6362322f7866c8d17300207599",
        "rk45": "fde6b234f17b9138be780fdacd2874b9d21ea4e61a4a93a9896f4e85bfffec17",
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
