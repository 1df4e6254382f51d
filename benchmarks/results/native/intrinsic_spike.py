"""Spike, not kept (issue 29, item 4; see intrinsic.md beside this file): the translated IR
called from a numba.extending.intrinsic inside an @njit wrapper, against the ctypes entry of
mcchain.codegen.native.

For one scene: the lane entry's real call is captured from a short simulate run, then
(in fresh processes each) compiled and timed both ways: compile = first call - a warm call;
lanes = best warm call of the captured arguments (one thread).

    python intrinsic_spike.py capture double_pendulum '{"t_end": 0.5, "dt": 1e-4,
        "output_dt": 1e-2, "method": "rk4"}' 64 dp.pkl
    MCCHAIN_CACHE_DIR=$(mktemp -d) python intrinsic_spike.py native dp.pkl 5
    python intrinsic_spike.py intrinsic dp.pkl 5
"""

from __future__ import annotations

import json
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO))


def capture(scene: str, settings: dict, nsample: int, out: Path) -> None:
    from mcchain.codegen import native
    from mcchain.testing.comparisons import simulate_float64
    from mcchain.testing.scenes import model_of, scene_model

    if scene == "fourbar-contact":
        text = (REPO / "configs" / "fourbar-clearance.toml").read_text()
        model = model_of(text, nsample=nsample, name="fourbar-clearance")
    else:
        model = scene_model(scene, nsample=nsample)
    calls = []
    original = native.NativeModule.__getattr__

    def getattr_(self, name):
        fn = original(self, name)

        def call(*args):
            if not calls:
                calls.append(
                    (
                        self.source,
                        self.name,
                        name,
                        [a.copy() if isinstance(a, np.ndarray) else a for a in args],
                    )
                )
            return fn(*args)

        return call

    native.NativeModule.__getattr__ = getattr_
    os.environ["NUMBA_NUM_THREADS"] = "1"
    simulate_float64(model, settings)
    out.write_bytes(pickle.dumps(calls[0]))


def _fresh(args):
    return [a.copy() if isinstance(a, np.ndarray) else a for a in args]


def run_native(path: Path, rounds: int) -> dict:
    from mcchain.codegen.native import NativeModule

    source, modname, entry, args = pickle.loads(path.read_bytes())
    module = NativeModule(source, modname + "_spike")
    fn = getattr(module, entry)
    return _timed(fn, args, rounds)


def run_intrinsic(path: Path, rounds: int) -> dict:
    from llvmlite import ir
    from numba import njit, types
    from numba.core import cgutils
    from numba.core.typing import signature
    from numba.extending import intrinsic

    from mcchain.codegen import native as nat
    from mcchain.kernels.config import LANE_JIT

    source, modname, entry, args = pickle.loads(path.read_bytes())
    argtypes = tuple(nat.type_of_value(a) for a in args)
    codegen = nat._codegen()
    symbol = f"{modname}.{entry}.intrinsic"

    def build_library():
        translator = nat.ModuleTranslator(source, symbol, nat._target_data(codegen))
        callee, _ = translator.specialize(entry, argtypes)
        # an external function taking the unpacked arguments, calling the internal one
        fn = ir.Function(translator.ir_module, callee.function_type, symbol)
        b = ir.IRBuilder(fn.append_basic_block())
        b.call(callee, list(fn.args))
        b.ret_void()
        nat._contract(translator.ir_module)
        library = codegen.create_library(symbol)
        library.add_ir_module(translator.ir_module)
        return library, callee.function_type

    def typer(typingctx, *arg_types):
        sig = signature(types.void, *arg_types)

        def codegen_(context, builder, sig_, values):
            library, fnty = build_library()
            context.active_code_library.add_linking_library(library)
            fn = cgutils.get_or_insert_function(builder.module, fnty, symbol)
            unpacked = []
            for ty, value in zip(sig_.args, values, strict=True):
                if isinstance(ty, types.Array):
                    ary = context.make_array(ty)(context, builder, value)
                    unpacked.append(ary.data)
                    unpacked += cgutils.unpack_tuple(builder, ary.shape)
                    unpacked += cgutils.unpack_tuple(builder, ary.strides)
                elif isinstance(ty, types.Boolean):
                    unpacked.append(value)
                else:
                    unpacked.append(value)
            builder.call(fn, unpacked)
            return context.get_dummy_value()

        return sig, codegen_

    names = [f"a{k}" for k in range(len(args))]
    ns = {"typer": typer}
    exec(
        f"def call_entry(typingctx, {', '.join(names)}):\n"
        f"    return typer(typingctx, {', '.join(names)})\n",
        ns,
    )
    call_entry = intrinsic(ns["call_entry"])
    text = f"def wrapper({', '.join(names)}):\n    call_entry({', '.join(names)})\n"
    namespace = {"call_entry": call_entry}
    exec(text, namespace)
    options = {k: v for k, v in LANE_JIT.items() if k != "cache"}
    wrapper = njit(**options)(namespace["wrapper"])
    return _timed(wrapper, args, rounds)


def _timed(fn, args, rounds: int) -> dict:
    """The first call (compile and run), the best of ``rounds`` warm ones, and a digest of
    the arrays after the last."""
    a = _fresh(args)
    t0 = time.perf_counter()
    fn(*a)
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(rounds):
        a = _fresh(args)
        t0 = time.perf_counter()
        fn(*a)
        best = min(best, time.perf_counter() - t0)
    return {"first": first, "warm": best, "compile": first - best, "out": _digest(a)}


def _digest(args) -> str:
    import hashlib

    h = hashlib.sha256()
    for a in args:
        if isinstance(a, np.ndarray):
            h.update(np.nan_to_num(a, nan=1234.5).tobytes() if a.dtype.kind == "f" else a.tobytes())
    return h.hexdigest()[:12]


if __name__ == "__main__":
    what = sys.argv[1]
    if what == "capture":
        capture(sys.argv[2], json.loads(sys.argv[3]), int(sys.argv[4]), Path(sys.argv[5]))
    else:
        fn = run_native if what == "native" else run_intrinsic
        # numba itself imported and warmed before the clock starts, as in a run
        import numba  # noqa: F401

        print(json.dumps(fn(Path(sys.argv[2]), int(sys.argv[3]))))
