"""Demand-order scheduling of generated lane loops (shorter live ranges, same values)."""

from __future__ import annotations

import heapq
import re

_NAME = re.compile(r"\b[A-Za-z_]\w*\b")
_ASSIGN = re.compile(r"^(\w+)\s*([-+*]?)=\s*(.*)$")
_ROW = re.compile(r"W\[[^\]]+\]")

INDEPENDENT_MARK = "# lanes: independent"
"""The comment ending the line of a ``for`` loop whose iterations read and write disjoint
memory: a lane loop whose lane ``l`` touches only ``W[row * LMAX + l]`` and its own
sample's elements. :mod:`mcchain.codegen.native` tells LLVM so. Its reads of the
function's own arrays (``W``) are in bounds whatever a branch decides, so the translator
evaluates the arms of its conditional expressions eagerly and selects (a branch there
vectorises into masked stores, slow on AMD Zen 1-3)."""

INTERLEAVE_CONSTANT = "INTERLEAVE"
"""The generated module's constant naming how many SIMD registers of lanes a lane loop's
vector body takes at once (:mod:`mcchain.codegen.native` asks LLVM to interleave that many)."""


def schedule_lane_loops(text: str) -> str:
    """Reorder the body of every lane loop marked ``# lanes: schedule`` so that each value is
    computed just before its first use.

    Why: the emitter writes stage by stage over all bodies (every sin/cos, then every joint,
    ...), so on a long chain most values stay live across the whole body and the register
    allocator spills them; demand order shortens the live ranges (rk4, 1 thread: 8-bar chain
    843 -> 713 ns, 16-bar 1,955 -> 1,588 ns per instance-step; the double pendulum is
    unchanged). The body is straight-line code: names are renamed to single assignments,
    then the lines are emitted depth-first from the stores to W, in their original order;
    loads and stores of the same W element keep their order. Values are the same
    expressions, so results do not change. Such a body reads and writes its lane's rows
    only (``W[c + l]``), so the loop comes out marked :data:`INDEPENDENT_MARK`.
    """
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.rstrip().endswith("# lanes: schedule"):
            out.append(line)
            i += 1
            continue
        indent = _indent(line)
        j = i + 1
        while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > indent):
            j += 1
        body = [b.strip() for b in lines[i + 1 : j] if b.strip()]
        pad = " " * _indent(lines[i + 1])
        out.append(line[: line.index("#")].rstrip() + "  " + INDEPENDENT_MARK)
        out.extend(pad + b for b in demand_order(body))
        i = j
    return "\n".join(out)


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def demand_order(body: list[str]) -> list[str]:
    """The lines of ``body`` renamed to single assignments (``x__2``) in demand order, with
    stores and running accumulations as early as their inputs allow."""
    version: dict[str, int] = {}
    defined_by: dict[str, int] = {}
    last_store: dict[str, int] = {}
    reads_since_store: dict[str, list[int]] = {}
    texts: list[str] = []
    deps: list[set[int]] = []
    chained: list[int | None] = []
    stores: list[int] = []
    for line in body:
        m = _ASSIGN.match(line)
        if m:
            name, op, rhs = m.groups()
            expr, target = (f"{name} {op} ({rhs})" if op else rhs), ""
        else:  # W[...] = expression
            target, expr = (x.strip() for x in line.split("=", 1))
            name = None
        k = len(texts)
        need: set[int] = set()
        running = name is not None and name in version and re.search(rf"\b{name}\b", expr)
        chained.append(defined_by[name] if name is not None and running else None)

        def rename(match: re.Match[str], need: set[int] = need) -> str:
            word = match.group(0)
            if word not in version:
                return word
            need.add(defined_by[word])
            return f"{word}__{version[word]}"

        expr = _NAME.sub(rename, expr)
        for row in _ROW.findall(expr):
            if row in last_store:
                need.add(last_store[row])
            reads_since_store.setdefault(row, []).append(k)
        if name is not None:
            version[name] = version.get(name, 0) + 1
            defined_by[name] = k
            texts.append(f"{name}__{version[name]} = {expr}")
        else:
            need.update(r for r in reads_since_store.get(target, []) if r != k)
            if target in last_store:
                need.add(last_store[target])
            reads_since_store[target] = []
            last_store[target] = k
            stores.append(k)
            texts.append(f"{target} = {expr}")
        deps.append(need)
    done = [False] * len(texts)
    order: list[int] = []
    for root in stores + list(range(len(texts))):
        stack = [(root, False)]
        while stack:
            node, expanded = stack.pop()
            if done[node]:
                continue
            if expanded:
                done[node] = True
                order.append(node)
                continue
            stack.append((node, True))
            stack.extend((d, False) for d in sorted(deps[node], reverse=True) if not done[d])
    # Stores and running accumulations (x = x + term, max(x, term); and their start values)
    # consume values and make nothing else need them: each goes right after the last line
    # it needs (lowest line first when several become ready), so the values die there
    # instead of living to the end of the body.
    sinks = set(stores) | {k for k, c in enumerate(chained) if c is not None}
    sinks |= {c for c in chained if c is not None}
    missing = {k: len(deps[k]) for k in sinks}
    sinks_after: dict[int, list[int]] = {}
    for k in sinks:
        for d in deps[k]:
            sinks_after.setdefault(d, []).append(k)
    ready = [k for k in sinks if missing[k] == 0]
    heapq.heapify(ready)
    placed = [False] * len(texts)
    result: list[int] = []

    def place(node: int) -> None:
        for dep in sorted(deps[node]):  # a sink this line needs is not placed yet
            if not placed[dep]:
                place(dep)
        if placed[node]:
            return
        result.append(node)
        placed[node] = True
        for sink in sinks_after.get(node, ()):
            missing[sink] -= 1
            if missing[sink] == 0:
                heapq.heappush(ready, sink)

    for node in order:
        if node not in sinks:
            place(node)
        while ready:
            sink = heapq.heappop(ready)
            if not placed[sink]:
                place(sink)
    for node in order:  # sinks nothing led to (none in generated bodies)
        if not placed[node]:
            place(node)
    return [texts[k] for k in result]
