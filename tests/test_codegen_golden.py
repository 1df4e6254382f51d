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
        "rk45": "b7dcd86411eee665bdfd19bddf2818aa997a3a6c2136f4c62e7d0d0b9ac4c59d",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "effb2624d9c5e6a2519f33a60f360e4176f1f079a391b700fd088176c97be176",
        "rk4-projection": "feb2bb6879cae6250cbe01cf0127bf8b09a8a9cafef97e59b4073009d40572f9",
        "rk45": "406fb8337c6b76375c109a7ddc7330f0b9ba1bb08d77c95b10e4ca17c2debb88",
    },
    "fourbar-clearance-auto": {
        "accel": "86e32d2d5657cb7fd633ef2b973c48781a8539dfe3db0e50d2dfee88ac957acb",
        "rk4": "5553b865d23a3291aa0aaa97b0b2bfec5d039f86ef7fa941efe186d49356a13b",
        "rk4-projection": "6121cb843e941a3d50d199c16012b90fc320e87c1eff446cdde9a52187540b0f",
        "rk45": "7274fcff2de2bf8140b863d617c3db5942e6ec8f59382f855aa9825f60181520",
    },
    "chain4-mixed-spring": {
        "accel": "60bb1204e42d054c75e3d065cdd5c38bce39cd698fcb21fb515bd8b59ea79255",
        "rk4": "6ef1c0b4b608682987c64d5d8beab2f6d744c974aadcd5c783a54c169b1abc34",
        "rk4-projection": "e014e671f9389656be3dc5b9b1401fcc37a10e1033f34c64992d09bf652ce9c8",
        "rk45": "3f12809a73458cc57eb2b96cdd3202cbb74bdb0fbafc4a46ec5310145208dc4d",
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
