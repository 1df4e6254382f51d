"""codegen: the generated lane-kernel text, pinned by SHA-256 for three topologies.

A move or rename inside the generator must leave these hashes alone; a change of the generated
text updates them in the same commit and says so. The work-row length is pinned to 4 (AVX2)
so the hashes do not depend on the CPU that runs the test.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from factory import chain_scene_text

from mcchain.codegen.generate import generate_source
from mcchain.codegen.topology import Topology
from mcchain.scene import compile_model, load_scene, load_scene_text

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
LMAX_PINNED = 4  # one AVX2 register of doubles; the text depends on the row length

GOLDEN = {
    "double-pendulum-clearance": "375d94a2dbd8b954a9fd742706ed946da309911b8c703a0628eeb55c1da15a7c",
    "fourbar-clearance": "fa5b09847121456e6d54d9c308d5c0373277c2ded12f67464bc3797f73dd7f76",
    "chain4-mixed-spring": "7181aa660e7f668924d521f31d42f35f4298e6a8581afd1c719984a1fbf932f5",
}


def _topology(name: str) -> Topology:
    if name == "chain4-mixed-spring":
        text = chain_scene_text(4, {1, 3}, 11, springs=1, forces=1, equilibrium=False, modes=False)
        return Topology.from_model(compile_model(load_scene_text(text, name=name)))
    return Topology.from_model(compile_model(load_scene(CONFIGS / f"{name}.toml")))


@pytest.mark.parametrize("name", list(GOLDEN))
def test_generate_source__text_matches_the_golden_hash(name):
    source = generate_source(_topology(name), lmax=LMAX_PINNED)
    assert hashlib.sha256(source.encode()).hexdigest() == GOLDEN[name]
