"""codegen: the generated lane-kernel text, pinned by SHA-256 for three topologies and
each variant of the module (the functions one method calls).

A move or rename inside the generator must leave these hashes alone; a change of the generated
text updates them in the same commit and says so. A module with contact-law joints carries a
digest of ``mcchain/kernels/contact.py`` (numba's cache key): an edit there changes its hash.
The work-row length is pinned to 4 (AVX2) so the hashes do not depend on the CPU that runs the
test.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import pytest

from mcchain.codegen.generate import VARIANTS, generate_source
from mcchain.codegen.topology import Topology
from mcchain.scene import compile_model, load_scene, load_scene_text
from mcchain.testing.factory import chain_scene_text

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
LMAX_PINNED = 4  # one AVX2 register of doubles; the text depends on the row length

GOLDEN = {
    "double-pendulum-clearance": {
        "accel": "769ae1636e4f9d307cea35946b4cf32754755a3563c4dc23556ebe4336498bc8",
        "rk4": "91cc34773b535c4c97cb240eb44b5ca1272b2b4c055ef39e2269bbd90ed6e16d",
        "rk4-projection": "0e8154f385f56b8cb4b541a7c5616f34809bec0407b7d7eaa47d7b972410bea9",
        "rk45": "a20a393f8f4b439e5eefe65f64c2d3e6ed49773089ca2322f9b90575b69e5ceb",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "98d2ced30b83e8b3c7f98c98824778430180bfebe4e96903b49ee8d40456e21f",
        "rk4-projection": "1fd4ef4022be94ada27f5065068e951f576d455576435fb4692cd756ad2ecc5e",
        "rk45": "af8d8b479e138a9d434551bda0838e835775f3cee28a1acbf699e4f7db786e34",
    },
    "fourbar-clearance-auto": {
        "accel": "86e32d2d5657cb7fd633ef2b973c48781a8539dfe3db0e50d2dfee88ac957acb",
        "rk4": "c3b2bd23ce34b37492f7e48ab84fbff61b71e899538f125a92223cf00d686a84",
        "rk4-projection": "3ebe75fb631107a2df40c5e18240c16eb736f8fd6fe1240653d8382942e23915",
        "rk45": "ea8e20ee1a8b824cf599cc866e969c9147259255f69cfc1e7353f9761d29eddf",
    },
    "chain4-mixed-spring": {
        "accel": "6374ec1e710b673fe61e05d1693e4fc89dd5383778283e6d3d3a9f33bd2489f6",
        "rk4": "cd0d02b3df40355abf7bad0cc8c5a7fef635bb11f574f3cf8a48b872568ce77a",
        "rk4-projection": "09ca72e59ae621c2d11005c6b8aa7beb33f6259ceb2e9a0bc517a13bcc821a2c",
        "rk45": "943c2db043e259687a8d9c729a1970fa0267eaec8bd20375599f04a35f2646af",
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
