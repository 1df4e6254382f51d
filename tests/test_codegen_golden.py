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
        "accel": "6cb53eabfc03d163c19da3f95a32cceb15054540a36a8d89e1cd2ebecfc849b7",
        "rk4": "bb2dfdef1e358e94a49f3afc40d88b7eaaed214ca98526bc4f8a07deb3fee9ce",
        "rk4-projection": "2638910f3ad6525e1db4ee49550aec1d2de508fc40be722b9327b1ea203f5b0e",
        "rk45": "2ae4e487e6aa648f4e3831ca307cba96dcd729f3aafa45d33679144a026d4146",
    },
    "fourbar-clearance": {
        "accel": "591c2ff2a891bbf23eb1ef4a26700485c5979dee9fa144b26809f6b47515a400",
        "rk4": "5d2fd855184fa4d201f6c5893e560560c13bb6a64a6d3ed3c57e82a0ce103cb9",
        "rk4-projection": "8bfb85226d741b00d2ffd1f6eef9c811a10cf470ba2d310bf5b271a93a5bf872",
        "rk45": "d7a44c9c37e34f990579bd3b1b0e967e968cb55cac99cdf6b96291c7f420893d",
    },
    "fourbar-clearance-auto": {
        "accel": "1bfca52e2598549c0a9cde420f0c870f1a3aed2fd0b603f3b5277920be7bbfe4",
        "rk4": "e63a5c9a5ba1b190fb1ecfda9505d7d05b8ec6a439ae7cc462d39340265c43f8",
        "rk4-projection": "6c0f8393db39906bd02962292ae0cca7ab0ffb7c78c38e89dfff519db81c9d1b",
        "rk45": "c8b63cb243eee5ded2f35083437382453a6f19bdfc789cb7407058281dcdbc43",
    },
    "chain4-mixed-spring": {
        "accel": "a88e7a8157a86e4e8f7931acabc9df69ea4ed2cfcac5abbf7b9c59e4d16ab96c",
        "rk4": "06320154ec6f3d395fe852fc16b59d4c92b595637cbdf10623035862898ae7c7",
        "rk4-projection": "d85ef2f3bb798a598ce8896756c8a409f18b0e29b80ac0bc5402d25ec571a6fd",
        "rk45": "c0ab9adb83312b6e921d3361307d3814cee48239ddc38192b8cd9c8fc134aeb2",
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
