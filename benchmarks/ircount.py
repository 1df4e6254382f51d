"""Executed floating-point operations and memory traffic of compiled kernels, counted in
their optimised LLVM IR (for ``bench_roofline.py``).

Every module numba's code generator finalises in this process (numba's ``@njit`` kernels
and the generated lanes of :mod:`mcchain.codegen.native`, which use the same code
generator) is instrumented after LLVM's optimisation passes and before machine code is
emitted: each basic block increments a counter of its own. Each block's content is read once
from the IR text, so a run gives, exactly, the operations the optimised IR executed:

* flops: ``fadd``, ``fsub``, ``fmul``, ``fdiv``, ``frem`` and ``llvm.sqrt`` count 1 per
  element (a ``<8 x double>`` operation is 8), ``llvm.fma``/``llvm.fmuladd`` 2 (1 where the
  addend is a zero constant: ``fma(b, k, 0.0)`` is a product rounded on its own, written so
  that LLVM cannot fuse it into a sum, e.g. the fixed-step lanes' combine). The fused
  multiply-adds the "contract" flag allows are formed later, when instructions are selected:
  an fmul and an fadd are 2 flops either way. ``fneg``, ``fabs``, compares, selects,
  min/max and conversions are not flops (counted apart as ``fp_other``);
* libm calls (``sin``, ``cos``, ``hypot``, ``exp``, ``pow``, ...), counted as calls: their
  flops are not in the figure;
* bytes: every ``load`` and ``store`` at its type's size (gathers and scatters at their
  elements'), whatever the memory level (the kernels' work arrays live in L1).

Nothing cached may be loaded (it would skip the instrumentation): run in a process whose
``MCCHAIN_CACHE_DIR`` and ``NUMBA_CACHE_DIR`` are empty folders, and call :func:`install`
before any kernel compiles. The counters are process-wide (run one thread while counting).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

SYMBOL = "mcchain_roofline_counts"
CAPACITY = 1 << 21

_FLOP = re.compile(
    r"=\s*(fadd|fsub|fmul|fdiv|frem)\b[^<\d]*?(<(\d+) x (double|float)>|double|float)(?![\w])"
)
_OTHER = re.compile(r"=\s*(fneg|fcmp|fptosi|fptoui|sitofp|uitofp|fpext|fptrunc)\b")
_INTRINSIC = re.compile(
    r"@llvm\.(sqrt|fma|fmuladd|fabs|minnum|maxnum|copysign|floor|ceil|"
    r"round|rint|trunc|masked\.gather|masked\.scatter|masked\.load|"
    r"masked\.store)\.(v(\d+))?(f64|f32)"
)
_ZERO_ADDEND = re.compile(r"(?:zeroinitializer|double -?0\.000000e\+00)\)")
_LIBM = re.compile(
    r"call [^@]*@(sin|cos|tan|hypot|atan2|atan|asin|acos|exp|log|pow|sinh|cosh|"
    r"tanh|expm1|log1p|cbrt|fmod)\b"
)
_LOAD = re.compile(r"=\s*load (?:volatile |atomic )?([^,]+),")
_STORE = re.compile(r"^\s*store (?:volatile |atomic )?(.+?) [^ ,]+, ptr")
_LABEL = re.compile(r'^([\w.$-]+|"[^"]+"):')


def _size(ty: str) -> int:
    """Bytes of an IR type (scalars and vectors of them; pointers 8)."""
    ty = ty.strip()
    m = re.fullmatch(r"<(\d+) x (.+)>", ty)
    if m:
        return int(m.group(1)) * _size(m.group(2))
    if ty == "ptr" or ty.endswith("*"):
        return 8
    m = re.fullmatch(r"i(\d+)", ty)
    if m:
        return max(1, int(m.group(1)) // 8)
    return {"double": 8, "float": 4, "half": 2}.get(ty, 0)


@dataclass
class Block:
    """What one basic block executes once."""

    module: str
    function: str
    label: str = ""
    instructions: int = 0  # IR instructions (a proxy for the machine code's)
    flops: int = 0
    fma: int = 0  # elements of llvm.fma / fmuladd with an addend (2 flops each, in flops)
    vector_flops: int = 0  # of the flops, those in vector operations
    fp_other: int = 0
    libm: int = 0
    load_bytes: int = 0
    store_bytes: int = 0


@dataclass
class Registry:
    counts: np.ndarray = field(default_factory=lambda: np.zeros(CAPACITY, np.int64))
    blocks: list[Block] = field(default_factory=list)


REGISTRY = Registry()


def _analyse(line: str, block: Block) -> None:
    m = _FLOP.search(line)
    if m:
        n = int(m.group(3) or 1)
        block.flops += n
        if m.group(3):
            block.vector_flops += n
        return
    if _OTHER.search(line) or " select " in line:
        block.fp_other += 1 if ("double" in line or "float" in line) else 0
    m = _INTRINSIC.search(line)
    if m and "call " in line:
        kind, n = m.group(1), int(m.group(3) or 1)
        elem = 8 if m.group(4) == "f64" else 4
        if kind == "sqrt":
            block.flops += n
            block.vector_flops += n if m.group(3) else 0
        elif kind in ("fma", "fmuladd"):
            per = 1 if _ZERO_ADDEND.search(line) else 2  # a product alone: one flop
            block.flops += per * n
            block.fma += n if per == 2 else 0
            block.vector_flops += per * n if m.group(3) else 0
        elif kind in ("masked.gather", "masked.load"):
            block.load_bytes += n * elem
        elif kind in ("masked.scatter", "masked.store"):
            block.store_bytes += n * elem
        else:
            block.fp_other += n
        return
    if _LIBM.search(line):
        block.libm += 1
        return
    m = _LOAD.search(line)
    if m:
        block.load_bytes += _size(m.group(1))
        return
    m = _STORE.match(line)
    if m:
        block.store_bytes += _size(m.group(1))


def instrument(text: str, module: str) -> str:
    """``text`` (an LLVM IR module) with a counter increment at the top of every basic
    block of every defined function (but those already counted: numba links the modules of
    the functions a kernel calls, instrumented when they were finalised, into its own)."""
    out: list[str] = []
    lines = text.split("\n")
    counted = _counted_functions(text)
    function = None
    block: Block | None = None
    label = ""
    pending = False  # a block began: its increment goes after its phi nodes
    for line in lines:
        stripped = line.strip()
        if line.startswith("define "):
            function = re.search(r"@(\"[^\"]+\"|[\w.$-]+)\(", line).group(1)
            out.append(line)
            pending = function not in counted
            block = None
            label = ""
            continue
        if function is None:
            out.append(line)
            continue
        if line.startswith("}"):
            function = None
            out.append(line)
            continue
        if _LABEL.match(line):
            out.append(line)
            pending = function not in counted
            label = _LABEL.match(line).group(1)
            continue
        starts = stripped and not stripped.startswith(";")
        if pending and starts and " phi " not in stripped and "landingpad" not in stripped:
            k = len(REGISTRY.blocks)
            if k >= CAPACITY:
                raise RuntimeError("too many basic blocks to count")
            block = Block(module, function, label)
            REGISTRY.blocks.append(block)
            out.append(f"  %__rca{k} = getelementptr i64, ptr @{SYMBOL}, i64 {k}")
            out.append(f"  %__rcv{k} = load i64, ptr %__rca{k}")
            out.append(f"  %__rcw{k} = add i64 %__rcv{k}, 1")
            out.append(f"  store i64 %__rcw{k}, ptr %__rca{k}")
            pending = False
        if block is not None and stripped and not stripped.startswith(";"):
            block.instructions += 1
            _analyse(line, block)
        out.append(line)
    if f"@{SYMBOL} = " not in text:
        out.append(f"@{SYMBOL} = external global [0 x i64]")
    return "\n".join(out)


def _counted_functions(text: str) -> set[str]:
    """The functions of ``text`` whose blocks already increment a counter."""
    counted, function = set(), None
    for line in text.split("\n"):
        if line.startswith("define "):
            function = re.search(r"@(\"[^\"]+\"|[\w.$-]+)\(", line).group(1)
        elif line.startswith("}"):
            function = None
        elif function and f"@{SYMBOL}" in line:
            counted.add(function)
    return counted


LINE = [0]
"""The line of the generated text being translated (block names ``L<line>``)."""


def install(line_labels: bool = True) -> None:
    """Instrument every module numba's code generator finalises from now on; with
    ``line_labels``, the generated lanes' basic blocks are named after the line of the
    text that made them (``L<line>``, kept by LLVM with suffixes), for :func:`profile`."""
    from llvmlite import binding, ir
    from numba.core import codegen

    if line_labels:
        from mcchain.codegen import native_translate

        statement = native_translate.FunctionTranslator._statement

        def statement_at_line(self, stmt):  # type: ignore[no-untyped-def]
            LINE[0] = getattr(stmt, "lineno", LINE[0])
            return statement(self, stmt)

        native_translate.FunctionTranslator._statement = statement_at_line
        append = ir.Function.append_basic_block

        def named_block(self, name=""):  # type: ignore[no-untyped-def]
            return append(self, name or f"L{LINE[0]}")

        ir.Function.append_basic_block = named_block

    binding.add_symbol(SYMBOL, REGISTRY.counts.ctypes.data)
    original = codegen.CPUCodeLibrary._optimize_final_module

    def optimise_then_count(self):  # type: ignore[no-untyped-def]
        original(self)
        text = instrument(str(self._final_module), self.name)
        module = binding.parse_assembly(text)
        module.verify()
        self._final_module = module

    codegen.CPUCodeLibrary._optimize_final_module = optimise_then_count


def reset() -> None:
    REGISTRY.counts[:] = 0


@dataclass
class Totals:
    flops: float = 0.0
    fma: float = 0.0
    vector_flops: float = 0.0
    fp_other: float = 0.0
    libm: float = 0.0
    load_bytes: float = 0.0
    store_bytes: float = 0.0
    by_function: dict[str, float] = field(default_factory=dict)  # flops

    @property
    def bytes(self) -> float:
        return self.load_bytes + self.store_bytes


def totals() -> Totals:
    """What every counted block executed since the last :func:`reset`."""
    out = Totals()
    n = len(REGISTRY.blocks)
    counts = REGISTRY.counts[:n]
    for k in np.flatnonzero(counts):
        b, c = REGISTRY.blocks[k], float(counts[k])
        out.flops += c * b.flops
        out.fma += c * b.fma
        out.vector_flops += c * b.vector_flops
        out.fp_other += c * b.fp_other
        out.libm += c * b.libm
        out.load_bytes += c * b.load_bytes
        out.store_bytes += c * b.store_bytes
        key = b.function
        out.by_function[key] = out.by_function.get(key, 0.0) + c * b.flops
    return out


def profile(top: int = 40) -> list[tuple[float, str, str]]:
    """(IR instructions executed, function, block label) of the busiest blocks since the
    last :func:`reset`, busiest first."""
    n = len(REGISTRY.blocks)
    counts = REGISTRY.counts[:n]
    agg: dict[tuple[str, str], float] = {}
    for k in np.flatnonzero(counts):
        b = REGISTRY.blocks[k]
        key = (b.function, re.sub(r"[.].*$", "", b.label))
        agg[key] = agg.get(key, 0.0) + float(counts[k]) * b.instructions
    rows = sorted(((v, f, lab) for (f, lab), v in agg.items()), reverse=True)
    return rows[:top]
