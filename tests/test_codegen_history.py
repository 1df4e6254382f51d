"""codegen: a lane's history point (``mcchain.codegen.history``) and the prefetches of the
lines its next points will be written to."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import pytest

from mcchain.codegen.history import ITEM_BYTES, LINE_BYTES, history_prefetches, history_stores
from mcchain.codegen.topology import Topology
from mcchain.scene import compile_model, load_scene

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


@pytest.mark.parametrize("config", ["double-pendulum-clearance", "slider-crank-flores"])
def test_prefetches__one_per_history_array_the_first_row_a_line_ahead(config):
    """Every array the history point writes is prefetched once, at the first row of the same
    sample whose float32 start lies a cache line or more past row ``it``'s start (the
    slider-crank: a driver and a contact-law joint, so every kind of history array)."""
    topo = Topology.from_model(compile_model(load_scene(CONFIGS / f"{config}.toml")))
    row_length = Counter(target.split("[")[0] for target, _ in history_stores(topo))
    prefetches = history_prefetches(topo)
    ahead = {}
    for line in prefetches:
        m = re.fullmatch(r"prefetch\((\w+), sl, it \+ (\d+)\)", line)
        assert m, line
        ahead[m.group(1)] = int(m.group(2))
    assert list(ahead) == list(row_length) and len(prefetches) == len(ahead)
    for array, rows in ahead.items():
        row_bytes = ITEM_BYTES * row_length[array]
        assert rows * row_bytes >= LINE_BYTES > (rows - 1) * row_bytes, array
    if config == "slider-crank-flores":
        assert {"out_dtq", "out_ct"} <= set(ahead)
