"""Per-test CPU and numba compiles of a test run (issue 36, item 5; ci.md in this folder).

As a pytest plugin (``-p cold_profile`` with this folder on ``PYTHONPATH`` and
``COLD_PROFILE_DIR`` naming an output folder) it appends one JSON line per test to
``<worker>.jsonl``: the test's wall time, the CPU time (user + sys, s) of its process and of
the child processes it waited for, and every numba compile it triggered (the function, its
signature, the compile's wall time, its nesting depth: 0 for a compile the test asked for,
more for the functions that compile pulled in).

As a script (``python cold_profile.py FOLDER``) it prints the summary ci.md quotes: CPU per
file and per test, each worker's files in the order they ran and when it finished, and the
numba compiles: how many distinct kernels and signatures, which were compiled by both
workers (their CPU paid twice), which functions compiled in more than one signature.
"""

from __future__ import annotations

import collections
import json
import os
import resource
import sys
import time
from pathlib import Path
from typing import Any

import pytest

_out: Any = None
_started: list[float] = []
_compiles: list[dict[str, Any]] = []


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, children.ru_utime + children.ru_stime


def pytest_configure(config: Any) -> None:
    global _out
    folder = os.environ.get("COLD_PROFILE_DIR")
    if not folder:
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    _out = open(Path(folder) / f"{worker}.jsonl", "a")  # kept open: one line per test
    from numba.core import event

    class Compiles(event.Listener):
        def on_start(self, ev: Any) -> None:
            _started.append(time.perf_counter())

        def on_end(self, ev: Any) -> None:
            began = _started.pop()
            data = ev.data or {}
            func = getattr(data.get("dispatcher"), "py_func", None)
            name = f"{getattr(func, '__module__', '')}.{getattr(func, '__qualname__', func)}"
            _compiles.append(
                {
                    "f": name,
                    "sig": str(data.get("args")),
                    "dt": round(time.perf_counter() - began, 3),
                    "depth": len(_started),
                }
            )

    event.register("numba:compile", Compiles())


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: Any, nextitem: Any) -> Any:
    if _out is None:
        yield
        return
    _compiles.clear()
    own0, children0 = _cpu()
    wall0, start = time.perf_counter(), time.time()
    yield
    own1, children1 = _cpu()
    record = {
        "id": item.nodeid,
        "start": start,
        "wall": round(time.perf_counter() - wall0, 3),
        "cpu": round(own1 - own0, 3),
        "child": round(children1 - children0, 3),
        "compiles": list(_compiles),
    }
    _out.write(json.dumps(record) + "\n")
    _out.flush()


def _rows(folder: Path) -> list[dict[str, Any]]:
    rows = []
    for path in sorted(folder.glob("*.jsonl")):
        for line in path.read_text().splitlines():
            rows.append({**json.loads(line), "w": path.stem})
    return rows


def summary(folder: Path, top: int = 40) -> None:
    rows = _rows(folder)
    own = sum(r["cpu"] for r in rows)
    children = sum(r["child"] for r in rows)
    print(f"{len(rows)} tests: CPU {own:.0f} s in the workers + {children:.0f} s in children")
    per_file: dict[str, float] = collections.Counter()
    for r in rows:
        per_file[r["id"].split("::")[0]] += r["cpu"] + r["child"]
    print("\nCPU per file (s)")
    for name, cpu in sorted(per_file.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{cpu:7.1f}  {name}")
    print("\nCPU per test (s): own, children, wall")
    for r in sorted(rows, key=lambda r: -(r["cpu"] + r["child"]))[:top]:
        print(f"{r['cpu']:7.1f} {r['child']:6.1f} {r['wall']:7.1f}  {r['w']} {r['id']}")
    t0 = min(r["start"] for r in rows)
    print("\nWorkers: files in the order they ran (@ start s: CPU s), and when each finished")
    for worker in sorted({r["w"] for r in rows}):
        mine = sorted((r for r in rows if r["w"] == worker), key=lambda r: r["start"])
        end = max(r["start"] + r["wall"] for r in mine) - t0
        files: list[list[Any]] = []
        for r in mine:
            name = r["id"].split("::")[0].removeprefix("tests/")
            if not files or files[-1][0] != name:
                files.append([name, r["start"] - t0, 0.0])
            files[-1][2] += r["cpu"] + r["child"]
        print(f"{worker}: {len(mine)} tests, last ended at {end:.0f} s")
        print("   " + " | ".join(f"{n}@{s:.0f}:{c:.0f}" for n, s, c in files))
    # numba compiles the tests asked for (depth 0), CPU estimated from the test's CPU share
    kernels: dict[tuple[str, str], list[tuple[str, str, float]]] = collections.defaultdict(list)
    for r in rows:
        share = r["cpu"] / r["wall"] if r["wall"] else 0.0
        for c in r["compiles"]:
            if c["depth"] == 0:
                kernels[(c["f"], c["sig"])].append((r["w"], r["id"], c["dt"] * share))
    total = sum(x[2] for v in kernels.values() for x in v)
    functions = {f for f, _ in kernels}
    print(
        f"\nnumba: {len(kernels)} distinct kernel signatures of {len(functions)} functions "
        f"compiled at a test's request, about {total:.0f} s of CPU"
    )
    twice = {k: v for k, v in kernels.items() if len({w for w, _, _ in v}) > 1}
    print(f"compiled by both workers: {len(twice)}")
    for (f, _), v in twice.items():
        print(f"   {f}: " + ", ".join(f"{w} {i} {c:.1f} s" for w, i, c in v))
    signatures = collections.defaultdict(list)
    for (f, _), v in kernels.items():
        signatures[f].append(v[0])
    print("functions compiled in more than one signature:")
    for f, v in signatures.items():
        if len(v) > 1 and f != "None.prog":
            print(f"   {f}: " + ", ".join(f"{i} {c:.1f} s" for _, i, c in v))


if __name__ == "__main__":
    summary(Path(sys.argv[1]))
