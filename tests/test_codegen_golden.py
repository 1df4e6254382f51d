"""codegen: the generated lane-kernel text, pinned by SHA-256 for three topologies and
each variant of the module (the functions one method calls).

A move or rename inside the generator must leave these hashes alone; a change of the generated
text updates them in the same commit and says so. The work-row length is pinned to 4 (AVX2)
so the hashes do not depend on the CPU that runs the test.
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
        "accel": "6cb53eabfc03d163c19da3f95a32cceb15054540a36a8d89e1cd2ebecfc849b7",
        "rk4": "3500754744007b06c701976d70e0ce8021d6aaafb4df646725e77443a5a94851",
        "rk4-projection": "8a470c61ea4e88bf2ae2d7abfdd10997f51f3985501d0490b879b7cab50947ac",
        "rk45": "872e6bd7254dca9ddf1ced87b227a98d39a9916ba6724234c60870a4559fd462",
    },
    "fourbar-clearance": {
        "accel": "591c2ff2a891bbf23eb1ef4a26700485c5979dee9fa144b26809f6b47515a400",
        "rk4": "e10f036f5725a851cf0e12dc508163c5241297926d584b0c3b65748da796fdad",
        "rk4-projection": "a12235e909c60f691d76cc0843e231d402591c0e614bb2c78a3bd3f708899b5b",
        "rk45": "8a563cd684d33602772e7df643927541ec7d25b40734071f2dbd27e5d4fedb0a",
    },
    "chain4-mixed-spring": {
        "accel": "a88e7a8157a86e4e8f7931acabc9df69ea4ed2cfcac5abbf7b9c59e4d16ab96c",
        "rk4": "9fd93db1041e8a99b0e5a11b4c3cbc56c0a64e437384f60124a18e13c691a2b1",
        "rk4-projection": "04e84cd5acb474b0d73ba2dd27a289d6d427c7b0c3a37b1e7071dab5dfc432a3",
        "rk45": "833f096f5a5adab0e885dbf2ce93680cd9ba952e1baf06812e744cf721de66a2",
    },
}


def _topology(name: str) -> Topology:
    if name == "chain4-mixed-spring":
        text = chain_scene_text(4, {1, 3}, 11, springs=1, forces=1, equilibrium=False, modes=False)
        return Topology.from_model(compile_model(load_scene_text(text, name=name)))
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
    "rk4": {"erk_run", "erk_group", "group_outputs_erk"},
    "rk4-projection": {
        "erk_project_run",
        "erk_project_group",
        "group_outputs_erkp",
        "group_project_erkp",
    },
    "rk45": {"adaptive_run", "adaptive_group", "group_outputs_dp", "group_first_stage_dp"},
}


@pytest.mark.parametrize("variant", list(FUNCTIONS))
def test_generate_source__a_variant_holds_only_the_functions_it_calls(variant):
    source = generate_source(_topology("fourbar-clearance"), variant, lmax=LMAX_PINNED)
    assert set(re.findall(r"^def (\w+)\(", source, re.MULTILINE)) == FUNCTIONS[variant]
