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
        "accel": "1a41bfb571f6ca124a599e0dd71a185981a4aed4b1425150719019ce91b11038",
        "rk4": "cf9caef9c1e24beaae949cc30cbd8f9ae5f853fee2615e16f49ec9cf465c820b",
        "rk4-projection": "b41fa620a3d1299b2ad3136bc037f5b1725e444adf9bdbe3337a414281bb7ce7",
        "rk45": "a41e6853e8fe0a0955900502fc3794a79115a6cd5f7fd15c42746aeb9853cd72",
    },
    "fourbar-clearance": {
        "accel": "e184b480b6a9a4ee302f08d8efbf7cb17ebaf3650a0e8ee248c102fe489b0d6b",
        "rk4": "f0580999bc5d885ad1a4ac163f48a6c76ae4e6063f97dba36ee86de7fb98da72",
        "rk4-projection": "7f82216fa75ee752e532e36c85c7ba197d03c315a861e740af3845f6a9190f79",
        "rk45": "81518a07385fd3b8b4c19f8bcd3b24e0107dd1cf24a2c629221c3a52be318ee6",
    },
    "fourbar-clearance-auto": {
        "accel": "367d77f036121918d788466d8220aa0b47c25b3422f9da0bd0431b2a95d94b5d",
        "rk4": "268f9360dbc54ee3e8e2ff30a19d72c0827a2d881a1dbf6bdc79287755e8a93a",
        "rk4-projection": "5db67614beeb4df64a1c523b8ef950289fa0a11657c2943bedd9c1ad2a253ef2",
        "rk45": "c1191d58bccf793ced10232ec139f145cd2793cfd6171eb50e2708249cbe52a7",
    },
    "chain4-mixed-spring": {
        "accel": "b731760ef4c677815383a346aef8f0bbdd888aae32c2504e9862cf5d94cce221",
        "rk4": "975da64197cb3a5959ad01fee57ae59277c2657083673d5c14d66905547bc5ee",
        "rk4-projection": "f00c8d7785f9613567b6e2a0409a6e9fe2f133c5fdb3221bc286f1c93262da0a",
        "rk45": "3a47af4fa29652d7ad7d260e0c4533cee21f66b88f6f7846723dbb093f734ad2",
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
        "nan_history",
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
