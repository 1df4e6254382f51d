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
    "double-pendulum-clearance": "baac1c5ac174694864493d96ced79ef05afc9f1b041bd1a6454ef5ad085bb8d8",
    "fourbar-clearance": "324a6df0ff99f6f277a5e0359e4bc5808d2e82e7775570352cffb81de73000cb",
    "chain4-mixed-spring": "2d4b6da496b32b2e287be0319932161cd458cdab1b72a9e886e90e8edcb24c7a",
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
