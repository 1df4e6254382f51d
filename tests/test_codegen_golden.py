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
        "accel": "5d35b27eba1e9d46141ec2413f96de7e75d75237aa3e217c0b22e19fe3674ef3",
        "rk4": "cbb4ca5383443d1c0c6c5bc9fcbc9cf4dfb7be4621d40d76602b03d97032be9f",
        "rk4-projection": "451eb679aac2d55471480389846ad5932b711246e4b049a8244fa62f7ccee8c9",
        "rk45": "92e5bccd052c34b6130646e498ce4760f30ce0ee28557ed8862587a1165dfd2a",
    },
    "fourbar-clearance": {
        "accel": "bbb59dd6a89da1aee006ec35981de6b29659f34b5b6e0eaaa0ce2185e0f8e404",
        "rk4": "eab7ec975691704870f20b350003278665352daeb308844942b60b054a472a1e",
        "rk4-projection": "cf963fd39c381c0a3e01bc0cfce36b33e0cc2af23a86e311eb399785f890c0c5",
        "rk45": "87bb0d9d4697449741d4d059dc9ee35413c96188556e4bdfe648e3e901ad3b3c",
    },
    "fourbar-clearance-auto": {
        "accel": "7118f4934ffa5ef307ce36816c33523278bd4cca7b47ca2ee6e55a060b0b418f",
        "rk4": "f53de8cbca8e5066619ffc42b2c7018b1cf83e1eab6ee574ec06ad234fb70c4d",
        "rk4-projection": "f55df8bd8971785b9a7951cbcab4327c3fda6b0f7266769843bc6f8024e1f8dd",
        "rk45": "448ff4b8b026d82c9f8dbec352ff59ca167044b5ca3d42bb603b4f4a4e0d196a",
    },
    "chain4-mixed-spring": {
        "accel": "f1cbc2a53c8fc2f050fdd0fda1d112eb27d39b84a4774371c5a29c9561ffe5e2",
        "rk4": "8b05f876b596f97e5610d1015d3ebb898d97f7ee7ba737f08cf065dc62b36f9d",
        "rk4-projection": "a67dc1d6ea10574ddcc32440d7158f8a2a81b488c5d82cf3e6066e8ade9b206a",
        "rk45": "05c83421ed8f6df03da0c4f984d248f9db1a1ae28005441548d03728962d8ab2",
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
        # kw, kr: the fixed step's stage rows, whole rows apart (checked below)
        if m := re.fullmatch(r"(?:k[wr] \+ )?(\d+) \+ l", text):
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
    for node in ast.walk(ast.parse(source)):  # the stage rows' offsets: whole rows
        if isinstance(node, ast.Assign) and ast.unparse(node.targets[0]) in ("kw", "kr"):
            assert re.fullmatch(rf"\(.+\) \* {LMAX_PINNED}", ast.unparse(node.value))
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
