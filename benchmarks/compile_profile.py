"""Which kernels a CLI command compiles, and for how long: numba's compile events, in process.

Usage::

    NUMBA_CACHE_DIR=$(mktemp -d) MCCHAIN_CACHE_DIR=$(mktemp -d) \\
        python benchmarks/compile_profile.py run configs/clearance-sweep.toml --quiet

Runs ``mcchain <arguments>`` and prints, per compiled function, the exclusive time (without
the functions it compiled meanwhile), the inclusive time and the number of compiles (more
than one: another signature, e.g. another array layout). With empty caches (as above) it
times a cold start; the figures of benchmarks/results/startup/breakdown.md come from it.
"""

from __future__ import annotations

import sys
import time
from collections import Counter, defaultdict

from numba.core import event


class _CompileTimes(event.Listener):
    def __init__(self) -> None:
        self.inclusive: defaultdict[str, float] = defaultdict(float)
        self.exclusive: defaultdict[str, float] = defaultdict(float)
        self.count: Counter[str] = Counter()
        self._stack: list[list] = []

    def on_start(self, ev: event.Event) -> None:
        func = ev.data["dispatcher"].py_func
        name = f"{str(func.__module__).rsplit('.', 1)[-1]}.{func.__qualname__}"
        self._stack.append([name, time.perf_counter(), 0.0])

    def on_end(self, ev: event.Event) -> None:
        name, t0, children = self._stack.pop()
        seconds = time.perf_counter() - t0
        self.inclusive[name] += seconds
        self.exclusive[name] += seconds - children
        self.count[name] += 1
        if self._stack:
            self._stack[-1][2] += seconds


def main(argv: list[str]) -> int:
    times = _CompileTimes()
    event.register("numba:compile", times)
    from mcchain.cli import main as mcchain_main

    t0 = time.perf_counter()
    try:
        mcchain_main(argv)
    except SystemExit:
        pass
    total = time.perf_counter() - t0
    print(f"\n{total:.1f} s in all; exclusive / inclusive compile time, s, and compiles:")
    for name, seconds in sorted(times.exclusive.items(), key=lambda kv: -kv[1])[:30]:
        print(f"{seconds:7.2f} {times.inclusive[name]:7.2f} {times.count[name]:3d}  {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
