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
        "accel": "2ad8088f6b58eb68112dc271b22aeefa42f4966ebae5edcad12b9baf9b3a4954",
        "rk4": "17f6a9d11042cb04673a83349016311389a4a30bac82fb3ed08ee4e76cd44aef",
        "rk4-projection": "94563e1ed3863b6f16ea2870049de914118bec3a8870a85a6b08a4729b1d573c",
        "rk45": "0e87e533cd8b12122092369f13f0922cbb8797869381cacc5914fae034316cd1",
    },
    "fourbar-clearance": {
        "accel": "48eb5c4fa719742757bf94dfbec5d404c39dba1622078d1362e3ea6083bb6069",
        "rk4": "1972cd479e34935b0b3535328ad1497b5d5d5120ab4987619f48e0a5b30b554f",
        "rk4-projection": "75b6f751f9ff0b11f95ebce6f7f67a87ef846ee9bdba39da55324cab0a228613",
        "rk45": "1458e6af5f8544b376d5352e14ff57a49a41b44b67efc030427a0bb3643852de",
    },
    "fourbar-clearance-auto": {
        "accel": "c94e9149069771a63678d610b9641e8535711cc838da674db730fe9cc8717511",
        "rk4": "318f525eb701de8524e41c42e9d8d34000485d7e58a0812ade6c4c5000b8559b",
        "rk4-projection": "6f67055c98bdb966e74308375c3c3d9871aef8c34ab832b3fbb050e23b460b35",
        "rk45": "21b2105b4f0fa606b965d8ba93b3caa4e22879643da31ab068a5c9d2f7f07f0a",
    },
    "chain4-mixed-spring": {
        "accel": "f20493b13273534cfa99e5f8e799e8a69f6084ccabd4a12c22edfa662efb1bf1",
        "rk4": "1eebf007bcf4e99702c8f99fd5629121a2ebafcdafcbb8549a47976f0be61259",
        "rk4-projection": "7e828bd94f6a643d40df212c84ba4ae1645e5d981ec9299cc2dc7294e8b0e50d",
        "rk45": "58432027dd7ec825095fd06bc80178ec47d753b88f96752d1c67ebe598b90431",
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
