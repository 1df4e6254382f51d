"""A lane's history point: the numbers the lane kernels write at each output time, in one
place for the layout that stages them (the adaptive kernel's rows ``ost``) and the code that
stores them (the ``store_outputs`` blocks of :mod:`mcchain.codegen.generate`)."""

from __future__ import annotations

from collections import Counter

from mcchain.codegen.topology import Topology

LINE_BYTES = 64
"""A cache line, in bytes."""

ITEM_BYTES = 4
"""A history element's bytes in the smaller of the histories' dtypes (float32)."""


def history_stores(topo: Topology) -> list[tuple[str, str]]:
    """The history point of lane ``l`` at output index ``it`` of sample ``sl``, as
    ``(target, value)`` pairs: a history element and the emitter's output it takes. In
    order: q and v of each coordinate, each joint's force (x, y) and contact force, each
    driver's torque, the constraint error and the energy, each contact-law joint's
    penetration and mode."""
    stores = []
    for i in range(topo.ndof):
        stores += [(f"out_q[sl, it, {i}]", f"q{i}"), (f"out_v[sl, it, {i}]", f"v{i}")]
    for k in range(topo.njoint):
        stores += [
            (f"out_jf[sl, it, {2 * k}]", f"jfx{k}"),
            (f"out_jf[sl, it, {2 * k + 1}]", f"jfy{k}"),
            (f"out_cf[sl, it, {k}]", f"cf{k}"),
        ]
    stores += [(f"out_dtq[sl, it, {d}]", f"dtq{d}") for d in range(topo.ndriver)]
    # energy · 0: NaN for a killed lane's NaN state (max() in phimax drops a NaN), 0 otherwise.
    stores += [("out_cerr[sl, it]", "phimax + energy * 0.0"), ("out_en[sl, it]", "energy")]
    for j, k in enumerate(topo.contact_joints):
        stores += [
            (f"out_ct[sl, it, {2 * j}]", f"pen{k}"),
            (f"out_ct[sl, it, {2 * j + 1}]", f"mode{k}"),
        ]
    return stores


def history_prefetches(topo: Topology) -> list[str]:
    """Prefetches of the lines that lane ``l``'s later history points will be written to
    (the adaptive kernel's landed lanes, after their stores): per history array, the row of
    sample ``sl`` a cache line or more past row ``it``'s start (in float32 rows; float64
    rows are twice as far). A sample's rows are contiguous (sample, time, k), so each array
    is a slow stream per lane, too many at once for the hardware's prefetchers: without
    them the stores missed to memory (reading.md, eleventh stop). Past the last time the
    address is the next sample's or past the array, which a prefetch allows."""
    row_length = Counter(target.split("[")[0] for target, _ in history_stores(topo))
    return [
        f"prefetch({array}, sl, it + {-(-LINE_BYTES // (ITEM_BYTES * n))})"
        for array, n in row_length.items()
    ]
