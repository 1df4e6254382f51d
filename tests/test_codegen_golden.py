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
        "rk4": "4c30e2e3e05dfc14510516fa2ad7d0759a8498737f919c8186fb810ab82de5fa",
        "rk4-projection": "64f07d536b1e4fca6c4a208c692c820bcc4ba0229b693a8adcde347ef69718c8",
        "rk45": "8ba152bb4282f4ef7ec61bebf96ab294c5537d9d7a855386cb46dc94da090eb7",
    },
    "fourbar-clearance": {
        "accel": "ea24d2a29ea8272d76dd4172106ca88d596b1af8de51adbbeb3acd31218a0ccd",
        "rk4": "8f261a84c3e43a06f03724c67f4d2ec9fac781165b48db6e35526994234e3e1a",
        "rk4-projection": "870afc6bbb97d320d4f4833298846acbaf2dadfaca5beb77dd5d892c649bfd7a",
        "rk45": "3a289147e83ee07d6027e30651d9283798e629c753849ba6a314d94d4684e052",
    },
    "fourbar-clearance-auto": {
        "accel": "eae9d34c8b3f5a33ad04d57608cf5503f1a30d4154a840766c99a2fba99a9879",
        "rk4": "ebdb349c93b504880cad4fd64b38e4324037c790b641f6d519d5deb815df971e",
        "rk4-projection": "e5d2231fd6b7a5f64cfe0c18c5f8ac86f25705670668f381c2ed4745fa25bc39",
        "rk45": "4bd4992962d99350fff5d864009053eda047eb2e5c113e06229d84c20ede5d27",
    },
    "chain4-mixed-spring": {
        "accel": "105998c4aa9ba3f47261e2b8863082059c91f9411f0f49b2357f76e72a25c167",
        "rk4": "f3033d3730ba2198f598793d5edfe7f953b77db61e5cff881148a11d7fab5f1c",
        "rk4-projection": "54595bda750fb7c11eac47381a6473e4bbd506731a3d1cc7e328dc8c905340fa",
        "rk45": "ccd79a5895d4e6744e3d355d9ac30ed41f5a5471be6cda47d2da157e9b6756db",
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
