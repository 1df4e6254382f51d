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
        "rk4": "9bd571752c655d8a0cc1cbdae963ce1437707e9aad88fb3b5adf5caa2e5ffb88",
        "rk4-projection": "4dfcf561a25f719ca39c0ea6f5b38d8bb00e7a375f52a048db623c8598ed3bd5",
        "rk45": "0c784e6ee987ad4a83d0005654b6c7197f93f2399751675d7d030fbd7d3216bf",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "effb2624d9c5e6a2519f33a60f360e4176f1f079a391b700fd088176c97be176",
        "rk4-projection": "feb2bb6879cae6250cbe01cf0127bf8b09a8a9cafef97e59b4073009d40572f9",
        "rk45": "369eaab65e8b464810771f8230faadec176d59f74b403519c49a3a4fb7ed12a2",
    },
    "fourbar-clearance-auto": {
        "accel": "86e32d2d5657cb7fd633ef2b973c48781a8539dfe3db0e50d2dfee88ac957acb",
        "rk4": "c5c73b7b4a6c64462518cc0db9267f4e9169dd23eacfa64bc7018df84424d391",
        "rk4-projection": "51c3f97f7c023600dbc4874bd8862ebfb12a96a4bf2cd102c20cd4ba408a48d8",
        "rk45": "83a1c0d1224191d323c277df4ba694fbf2d325f392a20efe16eebe72d97dfa77",
    },
    "chain4-mixed-spring": {
        "accel": "6374ec1e710b673fe61e05d1693e4fc89dd5383778283e6d3d3a9f33bd2489f6",
        "rk4": "e2eb800723a2a8f84e713fcb69c828846f8662677c03ee6a605090b166f37816",
        "rk4-projection": "1b5b27053ddac48aa39ad04a3537d0a2a1f2799fcc50774ebcf77342efdc0cba",
        "rk45": "e883e19df2141cbccee694b5be3718cf935a8d61626cd39ad12580e8a9d289a9",
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
    "rk45": {"adaptive_run", "group_outputs_dp", "group_first_stage_dp"},
}


@pytest.mark.parametrize("variant", list(FUNCTIONS))
def test_generate_source__a_variant_holds_only_the_functions_it_calls(variant):
    source = generate_source(_topology("fourbar-clearance"), variant, lmax=LMAX_PINNED)
    assert set(re.findall(r"^def (\w+)\(", source, re.MULTILINE)) == FUNCTIONS[variant]
