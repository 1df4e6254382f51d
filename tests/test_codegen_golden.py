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
        "rk4": "9d5c840d0ffb814465c38179bb0b9ebcf9ca9f67bde1f066011eccf5e2463017",
        "rk4-projection": "3a08788eb69ff3bbc5abc46b59a2ae4acb669e831a5d998cfab010f0ddfe7600",
        "rk45": "474f63dc79c3dca4d77c85364817d8fd41af01e72dcda5fd3730ccc93f0b071d",
    },
    "fourbar-clearance": {
        "accel": "14fff05d0afbcb6b91ddf87bd53ad050687319812e14acf28e101bd5f88c2d06",
        "rk4": "c362c144368761ce7f90ce6b5079a88d29c78dcfd511da5dfd350d89b904156a",
        "rk4-projection": "53d247d12e630c79a6c976981402219a4f32691d46753a56bd2b8f13a879ba03",
        "rk45": "36619d6a211d6c860aba9b1b33f0c67beaacbdaea9acf38086484d8e6762ddd6",
    },
    "fourbar-clearance-auto": {
        "accel": "86e32d2d5657cb7fd633ef2b973c48781a8539dfe3db0e50d2dfee88ac957acb",
        "rk4": "7ba4e63b7674cead741d3580cd73ba91134ef2a6be08ecfc4951937df013b58a",
        "rk4-projection": "9d63279fcfb4f80ca6ca353ebbc017aee9daefb3db9273ef4da4de1e084b5bea",
        "rk45": "381f6e3e25a0b86d48e96f00f1c3a99b040b344cb5c777fcd32a9a4e0b77c9fd",
    },
    "chain4-mixed-spring": {
        "accel": "6374ec1e710b673fe61e05d1693e4fc89dd5383778283e6d3d3a9f33bd2489f6",
        "rk4": "7a1bd80c30a0f676773f4075180a6e0361c41ddbfd9241657bb1861b99bf2049",
        "rk4-projection": "16f120cb9b19cd3589cd96fa706a2af761eb81ec13693a3a9028360e12ba04f4",
        "rk45": "9805c7cd13aaeaec9f089b6d0b71b65af953d5701d3e9f1726c91ca2d7a1a391",
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
