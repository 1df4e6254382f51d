"""This machine's measured ceilings, for ``bench_roofline.py``: floating-point peak (a pure
fused-multiply-add loop, and NumPy's dgemm), L1 load bandwidth and memory bandwidth.

* FMA peak: an LLVM IR loop of 16 independent ``llvm.fma`` chains on vectors of one SIMD
  register (8 doubles with AVX-512, 4 with AVX2: the target numba compiles for), compiled
  by numba's code generator for this CPU and run on 1 and 2 threads (ctypes releases the
  GIL). 16 chains hide the FMA latency (4 cycles) on two FMA ports. 2 flops per element.
* add/mul peak: the same loop with ``fmul`` then ``fadd`` (1 flop each): the ceiling of code
  whose multiplies and adds are not fused.
* dgemm: ``A @ B`` (n = 3000, float64) through NumPy's BLAS, ``OPENBLAS_NUM_THREADS`` 1 and 2,
  in a fresh process each; ``OPENBLAS_CORETYPE`` as set (or unset: OpenBLAS picks its kernel
  from the CPU; ``Haswell`` caps it at AVX2) is reported with the kernel OpenBLAS chose.
* L1 load bandwidth: 8 chains of vector ``fadd`` over a 16 KiB buffer (stays in L1),
  counted as bytes loaded.
* memory bandwidth: ``np.copyto`` of 256 MiB (bytes read + written).

Each figure is the best of several runs, timed on CPU time (per thread: the longest of the
threads'): the machine is shared, and wall time would count the other jobs' turns.
"""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys
import threading
import time
from typing import Any

import numpy as np

CHAINS = 12
"""Independent FMA chains of the flop loop: enough to cover an FMA's latency on both FP pipes
(4-5 cycles × 2), few enough that they and the loop's two constants fit the SIMD registers
(16 on AVX2). 16 chains spilled on an AMD Zen 3 (AVX2): 26.7 GFLOP/s on 1 thread where 12, 10
and 8 chains gave 46.3, 47.9, 48.1 (and NumPy's dgemm 38.5)."""


def _simd() -> int:
    from mcchain.codegen.layout import LMAX

    return LMAX


def _library(ir_text: str, name: str) -> Any:
    from numba.core.registry import cpu_target

    codegen = cpu_target.target_context.codegen()
    library = codegen.create_library(name)
    from llvmlite import binding

    module = binding.parse_assembly(ir_text)
    module.verify()
    library.add_llvm_module(module)
    from numba.core.compiler_lock import global_compiler_lock

    with global_compiler_lock:
        library.finalize()
    return library


def _flop_loop_ir(width: int, fused: bool) -> str:
    """``void f(i64 n, ptr out)``: n iterations of CHAINS chains (fma, or fmul + fadd)."""
    vec = f"<{width} x double>"
    splat = lambda x: "<" + ", ".join([f"double {x}"] * width) + ">"  # noqa: E731
    a, b = splat("0x3FEFFFFFFFFFFFFF"), splat("0x3E50000000000000")
    lines = [
        f"declare {vec} @llvm.fma.v{width}f64({vec}, {vec}, {vec})",
        "define void @loop(i64 %n, ptr %out) {",
        "entry:",
        "  br label %head",
        "head:",
        "  %i = phi i64 [0, %entry], [%i1, %head]",
    ]
    for c in range(CHAINS):
        lines.append(f"  %x{c} = phi {vec} [{splat(float(c + 1))}, %entry], [%y{c}, %head]")
    for c in range(CHAINS):
        if fused:
            operands = f"{vec} %x{c}, {vec} {a}, {vec} {b}"
            lines.append(f"  %y{c} = call {vec} @llvm.fma.v{width}f64({operands})")
        else:
            lines.append(f"  %m{c} = fmul {vec} %x{c}, {a}")
            lines.append(f"  %y{c} = fadd {vec} %m{c}, {b}")
    lines += [
        "  %i1 = add i64 %i, 1",
        "  %more = icmp slt i64 %i1, %n",
        "  br i1 %more, label %head, label %exit",
        "exit:",
    ]
    acc = "%y0"
    for c in range(1, CHAINS):
        lines.append(f"  %s{c} = fadd {vec} {acc}, %y{c}")
        acc = f"%s{c}"
    lines += [f"  store {vec} {acc}, ptr %out, align 8", "  ret void", "}"]
    return "\n".join(lines)


def _load_loop_ir(width: int, doubles: int) -> str:
    """``void f(i64 n, ptr buf, ptr out)``: n passes over ``doubles`` doubles, 8 chains."""
    vec = f"<{width} x double>"
    per_pass = doubles // width
    zero = "zeroinitializer"
    lines = [
        "define void @loop(i64 %n, ptr %buf, ptr %out) {",
        "entry:",
        "  br label %head",
        "head:",
        "  %j = phi i64 [0, %entry], [%j1, %head]",
    ]
    for c in range(8):
        lines.append(f"  %x{c} = phi {vec} [{zero}, %entry], [%y{c}, %head]")
    lines.append(f"  %k = urem i64 %j, {per_pass // 8}")
    lines.append(f"  %base = mul i64 %k, {8 * width}")
    for c in range(8):
        lines.append(f"  %o{c} = add i64 %base, {c * width}")
        lines.append(f"  %p{c} = getelementptr double, ptr %buf, i64 %o{c}")
        lines.append(f"  %v{c} = load {vec}, ptr %p{c}, align 64")
        lines.append(f"  %y{c} = fadd {vec} %x{c}, %v{c}")
    lines += [
        "  %j1 = add i64 %j, 1",
        "  %more = icmp slt i64 %j1, %n",
        "  br i1 %more, label %head, label %exit",
        "exit:",
    ]
    acc = "%y0"
    for c in range(1, 8):
        lines.append(f"  %s{c} = fadd {vec} {acc}, %y{c}")
        acc = f"%s{c}"
    lines += [f"  store {vec} {acc}, ptr %out, align 8", "  ret void", "}"]
    return "\n".join(lines)


def _threaded(call: Any, threads: int, repeat: int) -> float:
    """Best time of ``threads`` simultaneous calls of ``call()``: the longest CPU time of
    one of the threads (on a machine shared with other jobs, wall time also counts the time
    the scheduler gave them; the CPU time is what the loop itself needs)."""
    best = np.inf
    for _ in range(repeat):
        spent = [0.0] * threads

        def timed(i: int, spent: list[float] = spent) -> None:
            t0 = time.thread_time()
            call()
            spent[i] = time.thread_time() - t0

        workers = [threading.Thread(target=timed, args=(i,)) for i in range(threads)]
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        best = min(best, max(spent))
    return float(best)


def flop_peak(threads: int, fused: bool, repeat: int = 7) -> float:
    """GFLOP/s of the FMA (or fmul + fadd) loop on ``threads`` threads."""
    width = _simd()
    lib = _library(_flop_loop_ir(width, fused), f"peak_{'fma' if fused else 'mul_add'}")
    address = lib.get_pointer_to_function("loop")
    fn = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_void_p)(address)
    out = np.zeros(width)
    n = 20_000_000
    fn(1000, out.ctypes.data)
    seconds = _threaded(lambda: fn(n, out.ctypes.data), threads, repeat)
    flops = n * CHAINS * width * 2 * threads  # an fma, or an fmul and an fadd: 2 flops
    return flops / seconds / 1e9


def l1_bandwidth(threads: int, repeat: int = 7) -> float:
    """GB/s of vector loads from a 16 KiB buffer (L1-resident), per ``threads`` threads."""
    width = _simd()
    doubles = 2048
    lib = _library(_load_loop_ir(width, doubles), "peak_l1")
    fn = ctypes.CFUNCTYPE(None, ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p)(
        lib.get_pointer_to_function("loop")
    )
    bufs = [np.ones(doubles + 16) for _ in range(threads)]
    aligned = [b[(-(b.ctypes.data // 8)) % 8 :] for b in bufs]
    out = [np.zeros(width) for _ in range(threads)]
    n = 40_000_000
    fn(1000, aligned[0].ctypes.data, out[0].ctypes.data)
    seconds = _threaded(lambda: fn(n, aligned[0].ctypes.data, out[0].ctypes.data), threads, repeat)
    return n * 8 * width * 8 * threads / seconds / 1e9


def memory_bandwidth(repeat: int = 5) -> float:
    """GB/s of ``np.copyto`` (read + write) on 256 MiB."""
    a = np.ones(32 << 20)
    b = np.empty_like(a)
    np.copyto(b, a)
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        np.copyto(b, a)
        best = min(best, time.process_time() - t0)
    return 2 * a.nbytes / best / 1e9


_DGEMM = """
import json, os, sys, time
import numpy as np
n = 3000
a = np.random.default_rng(0).random((n, n)); b = a.T.copy()
a @ b
threads = int(os.environ["OPENBLAS_NUM_THREADS"])  # CPU time per BLAS thread (shared machine)
best = min((lambda t0: (a @ b, (time.process_time() - t0) / threads)[1])(time.process_time())
           for _ in range(5))
try:
    from threadpoolctl import threadpool_info
    arch = [i.get("architecture") for i in threadpool_info() if i.get("internal_api") == "openblas"]
except Exception:
    arch = []
print(json.dumps({"gflops": 2 * n**3 / best / 1e9, "kernel": arch[0] if arch else None}))
"""


def dgemm(threads: int, coretype: str | None) -> dict[str, Any]:
    """GFLOP/s of NumPy's float64 matmul on ``threads`` BLAS threads (fresh process), with
    ``OPENBLAS_CORETYPE`` = ``coretype`` (None: unset)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
    env.pop("OPENBLAS_CORETYPE", None)
    if coretype:
        env["OPENBLAS_CORETYPE"] = coretype
    out = subprocess.run([sys.executable, "-c", _DGEMM], env=env, capture_output=True, text=True,
                         check=True)  # fmt: skip
    return dict(json.loads(out.stdout), coretype=coretype or "(unset)", threads=threads)


def measure() -> dict[str, Any]:
    """Every ceiling, on 1 and 2 threads."""
    result: dict[str, Any] = {"simd_doubles": _simd(), "load": os.getloadavg()[0]}
    for th in (1, 2):
        result[f"fma_{th}"] = flop_peak(th, fused=True)
        result[f"mul_add_{th}"] = flop_peak(th, fused=False)
        result[f"l1_{th}"] = l1_bandwidth(th)
        for coretype in (os.environ.get("OPENBLAS_CORETYPE"), "Haswell"):
            d = dgemm(th, coretype)
            result.setdefault(f"dgemm_{th}", []).append(d)
    result["memory"] = memory_bandwidth()
    result["env_OPENBLAS_CORETYPE"] = os.environ.get("OPENBLAS_CORETYPE", "(unset)")
    return result


if __name__ == "__main__":
    print(json.dumps(measure(), indent=1))
