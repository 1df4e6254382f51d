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
        "rk4": "ffdd58b088bedc9327c006be5494fd5769c85fa0828276167c120bfc557d643f",
        "rk4-projection": "577b438e59efb76f37ed1ffb5e5aaeadeebe2db67932a0f1e75683e76034f2f8",
        "rk45": "ae1a9c85deb7fa0a0d1924d437acfe1d019c74a4e5ee6bfb2be7044ae40f4edf",
    },
    "fourbar-clearance": {
        "accel": "6f3551001b12cb65710a2e0332530bbc91ebbcfd151bdecd33ed16dbd2576d0a",
        "rk4": "977c6159e9fd5e46864177a6e7211189a795f5941055397cfbaa2a058cc468e9",
        "rk4-projection": "459d3422a6c19b36e7d3b5a8e39c08f12d7002a2e8591abc9a1c924bcb485a01",
        "rk45": "3f4267b18afbcfe4be8a61e02c1aa208ff810ab26301e64978390a7d2d85efb0",
    },
    "fourbar-clearance-auto": {
        "accel": "632537b19cc322c7b3299b8436ee4b44b8672bb01381690cd0ee8d841f292982",
        "rk4": "676f130f99345a38dcbc6b26235b6e525e404b715af35177b76ac318b969577e",
        "rk4-projection": "55fef7b3f158d799a9281ecd764331fb2a29a83342ce1e3800868ac0b5760595",
        "rk45": "437dd25c9d2ddab424c4767f2b5a0f1a06a7fa9dae71ec0cf8a95e29bacbe826",
    },
    "chain4-mixed-spring": {
        "accel": "ab81033088607ce431c4becde7eb25e39a776f907ec19967086763efc83cf224",
        "rk4": "0c7d2a7b27710fb9f741a64d04f1313d0dd637c300b601aadafaa319881237f5",
        "rk4-projection": "3f37b6b1c125bdfafa5b62f8a62c9d1a3f5ec21b2403e5369e9f9d0ab3349781",
        "rk45": "fdf0dc3651983942f1624061fb13da3c2f23c682d95497b9dd8ee0fa21df6e9d",
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


PURE_CALLS = {"abs", "max", "min", "math.sqrt", "fma", "float", "int"}


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
