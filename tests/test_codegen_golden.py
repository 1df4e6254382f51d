"""codegen: the generated lane-kernel text, pinned by SHA-256 for three topologies.

A move or rename inside the generator must leave these hashes alone; a change of the generated
text updates them in the same commit and says so. The work-row length is pinned to 4 (AVX2)
so the hashes do not depend on the CPU that runs the test.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from mcchain.codegen.generate import generate_source
from mcchain.codegen.topology import Topology
from mcchain.scene import compile_model, load_scene, load_scene_text
from mcchain.testing.factory import chain_scene_text

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
LMAX_PINNED = 4  # one AVX2 register of doubles; the text depends on the row length

GOLDEN = {
    "double-pendulum-clearance": "75dcdbe6938be5bfa45aefbb6833100c2a4d70eb6a347699baae2b1e139a1504",
    "fourbar-clearance": "41102c11dde47f48b92ae901244bd2fba7b46f2c7a991eb38457aab95fcb0910",
    "chain4-mixed-spring": "07dd0ee49716890803ca7b2b666fbc5e13d6d567f93cdc4f4e6edc91823fdff3",
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
