"""codegen.native: the generated text compiled without numba's type inference.

References: the same functions run as plain Python (every operator and construct of the
translated subset, on hypothesis' values), and numba itself: the lane kernels compiled by
numba from the same text give the same bits, history by history, on the scenes of every
variant (the four-bar under the contact law among them).

Bit for bit means every number; a NaN only has to be a NaN at the same place. Its sign bit
is not kept by LLVM (``-x + y`` may become ``y - x``) nor by x86 (a fused multiply-add
returns the first NaN of its operands, in the order the register allocator picked): the
four-bar's joint force at a contact joint is NaN at t = 0 in 14 places, with the sign bit
set by numba and clear here.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import sys
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mcchain.codegen import generate
from mcchain.codegen.native import NativeModule
from mcchain.codegen.native_expressions import TranslationError
from mcchain.testing.comparisons import simulate_float64
from mcchain.testing.scenes import model_of, scene_model

SOURCE = """
import math
import os

import numpy as np

TABLE = (0.5, 1.5, 2.5, 3.5)
SIZE = 3


def integers(a, b, out):
    out[0] = a // b
    out[1] = a % b
    out[2] = a * b - a + 7
    out[3] = -a
    out[4] = abs(a)
    out[5] = min(a, b, 3)
    out[6] = max(a, b)
    out[7] = (a & 12) | (b & 3)
    out[8] = 1 if a < b <= 9 else 0
    out[9] = np.int64(a / b * 4.0)


def floats(x, y, n, out):
    out[0] = x / y
    out[1] = (abs(x) + 1.0) ** (y * 1e-5)
    out[2] = max(x, y)
    out[3] = min(x, y)
    out[4] = max(y, x)
    out[5] = abs(x)
    out[6] = math.sqrt(abs(y))
    out[7] = -x + n
    out[8] = x * 2.0 + y * n
    out[9] = (x > y) * 1.0 + (x != y) * 2.0 + (x == y) * 4.0 + (not (x <= y)) * 8.0
    out[10] = x if x >= y else math.nan
    out[11] = n / 4
    out[12] = np.inf if x < 0.0 or y < 0.0 else -np.inf


def control(n, out):
    total = 0
    k = 0
    while True:
        k += 1
        if k > n:
            break
        if k % 3 == 0:
            continue
        elif k % 5 == 0:
            total += 100
        else:
            total += k
    out[0] = total
    for i in range(n, 0, -2):
        out[1] += i
    for i in range(2, n):
        for j in range(i):
            if j == 2:
                break
            out[2] += i * j
    acc = 0.0
    for i in range(SIZE):
        acc = acc + TABLE[i] if i != 1 else acc
    out[3] = acc


def pair(a, b):
    s = a + b
    if s > 0.0:
        return s, a - b
    return -s, b - a


def lookup(table, x):
    return table[1] * x


def arrays(M, V, flags, counts, out32, out3):
    lo, hi = 0.0, 1.0
    local = np.zeros(4, np.uint32)
    marks = np.zeros(4, np.bool_)
    fill = np.full(SIZE, np.nan)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            M[i, j] = M[i, j] * 2.0 + V[j] + hi - lo
    for k in range(4):
        local[k] = counts[k]
        local[k] |= 8
        marks[k] = (local[k] & 1) != 0
        flags[k] = marks[k] and not flags[k]
    s, d = pair(V[0], V[1])
    counts[0] = local[0] + local[3]
    out32[0] = s / 3.0
    out32[1] = d
    out32[2] = fill[2]
    out32[3] = lookup(TABLE, d)
    out3[1, 0, :] = -1.0
    out3[0, 1, 1] = out3.shape[2]
"""


def _python(name: str, *args: Any) -> None:
    namespace: dict[str, Any] = {}
    exec(SOURCE, namespace)
    namespace[name](*args)


@pytest.fixture(scope="module")
def native() -> NativeModule:
    module = NativeModule(SOURCE, "mcchain_test_native", contract=False)  # Python's rounding
    module.integers(1, 1, np.zeros(10, np.int64))  # compiled before hypothesis' deadline
    module.floats(1.0, 1.0, 1, np.zeros(13))
    return module


def _both(native: NativeModule, name: str, *args: Any) -> tuple[list[Any], list[Any]]:
    """Arguments after the native call and after the Python one (arrays copied)."""
    mine = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
    ref = [a.copy() if isinstance(a, np.ndarray) else a for a in args]
    getattr(native, name)(*mine)
    _python(name, *ref)
    return mine, ref


def _assert_same_bits(mine: np.ndarray, ref: np.ndarray) -> None:
    """Bit for bit, NaNs at the same places (module docstring)."""
    assert mine.dtype == ref.dtype
    if mine.dtype.kind == "f":
        nan = np.isnan(mine)
        np.testing.assert_array_equal(nan, np.isnan(ref))
        mine, ref = np.where(nan, 0, mine), np.where(nan, 0, ref)
    assert mine.tobytes() == ref.tobytes(), (mine, ref)


small = st.integers(-50, 50)


@given(a=small, b=small.filter(lambda v: v != 0))
def test_integers__python_semantics(native, a, b):
    mine, ref = _both(native, "integers", a, b, np.zeros(10, np.int64))
    _assert_same_bits(mine[-1], ref[-1])


finite = st.floats(-1e6, 1e6, allow_nan=False).filter(lambda v: abs(v) > 1e-6)


@given(x=finite | st.just(math.nan), y=finite, n=small)
def test_floats__python_semantics_nan_order_included(native, x, y, n):
    mine, ref = _both(native, "floats", x, y, n, np.zeros(13))
    _assert_same_bits(mine[-1], ref[-1])


@pytest.mark.parametrize("n", [0, 1, 7, 16])
def test_control__loops_branches_break_continue(native, n):
    mine, ref = _both(native, "control", n, np.zeros(4, np.int64))
    _assert_same_bits(mine[-1], ref[-1])


def test_arrays__strided_views_locals_tuples_tables_float32(native):
    rng = np.random.default_rng(3)
    M = rng.normal(size=(3, 8))[:, ::2]  # a strided view
    assert not M.flags.c_contiguous
    V = rng.normal(size=4)
    flags = np.array([True, False, True, False])
    counts = np.array([1, 2, 3, 5], np.uint32)
    args = (M, V, flags, counts, np.zeros(4, np.float32), np.zeros((2, 2, 3)))
    mine, ref = _both(native, "arrays", *args)
    for a, b in zip(mine, ref, strict=True):
        _assert_same_bits(np.ascontiguousarray(a), np.ascontiguousarray(b))


def test_machine_code__cached_on_disk_and_a_bad_file_compiles_again(tmp_path, monkeypatch):
    """Counted: the second module loads the file (no compile), the third compiles again.
    The file is the entry's object code alone after its header and SHA-256 (no bitcode to
    parse on load); a damaged one (not a cache file, cut short, one byte changed: LLVM's
    loader would crash on it) is compiled again, with the same values."""
    from mcchain.codegen import native as native_module

    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path))
    counts = {"compiled": 0, "loaded": 0}
    monkeypatch.setattr(native_module, "COUNTS", counts)
    out = np.zeros(10, np.int64)
    NativeModule(SOURCE, "mcchain_test_cache").integers(7, 3, out)
    assert counts == {"compiled": 1, "loaded": 0}
    files = list((tmp_path / "native").iterdir())
    assert len(files) == 1
    written = files[0].read_bytes()
    header = native_module.OBJECT_HEADER
    object_code = written[len(header) + 32 :]
    assert written.startswith(header) and object_code.startswith(b"\x7fELF")  # machine code
    assert written[len(header) : len(header) + 32] == hashlib.sha256(object_code).digest()
    again = np.zeros(10, np.int64)
    NativeModule(SOURCE, "mcchain_test_cache").integers(7, 3, again)  # loaded
    assert counts == {"compiled": 1, "loaded": 1}
    changed = bytearray(written)
    changed[len(written) // 2] ^= 0xFF
    for compiles, damaged in enumerate(
        [b"not a library", written[: len(written) // 2], bytes(changed)], start=2
    ):
        files[0].write_bytes(damaged)
        monkeypatch.setattr(native_module, "_LOADED", {})  # as in a new process
        third = np.zeros(10, np.int64)
        NativeModule(SOURCE, "mcchain_test_cache").integers(7, 3, third)
        assert counts == {"compiled": compiles, "loaded": 1}
        assert out.tolist() == again.tolist() == third.tolist()
    assert out[:2].tolist() == [2, 1]


def test_machine_code__a_process_finding_the_entry_s_turn_taken_loads_what_it_wrote(
    tmp_path, monkeypatch
):
    """Two processes wanting the same entry at once (two test workers; commands started
    side by side on a cold cache) compile it once: here the test holds the entry's
    compile turn while a second process asks for the entry, writes the machine code
    (compiled beforehand in another folder) and gives the turn up; the second process
    then loads it: 0 compiles, 1 load, whether it asked before or after the file came.
    The lock file is gone afterwards."""
    import fcntl
    import shutil
    import subprocess
    import time
    from pathlib import Path

    if not Path("/proc/locks").is_file():
        pytest.skip("needs Linux's /proc/locks to see the second process wait")
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path / "first"))
    NativeModule(SOURCE, "mcchain_test_turn").integers(7, 3, np.zeros(10, np.int64))
    (compiled,) = (tmp_path / "first" / "native").iterdir()
    shared = tmp_path / "shared" / "native"
    shared.mkdir(parents=True)
    lock = shared / (compiled.stem + ".lock")
    script = f"""
import json
import numpy as np
from mcchain.codegen import native
module = native.NativeModule({SOURCE!r}, "mcchain_test_turn")
print("asking", flush=True)
out = np.zeros(10, np.int64)
module.integers(7, 3, out)
print(json.dumps({{**native.COUNTS, "out": out[:2].tolist()}}))
"""
    repo = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(repo), "MCCHAIN_CACHE_DIR": str(shared.parent)}
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX)  # the turn: taken by "another process", this test
    child = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, env=env,
    )  # fmt: skip
    hang_guard = time.monotonic() + 120.0  # only against a hang: no figure depends on it
    try:
        assert child.stdout is not None
        assert child.stdout.readline() == "asking\n"
        # Written once the child waits for the turn (Linux lists a blocked flock in
        # /proc/locks with "->"): without the turn, it would have compiled by then.
        waiting = f" {child.pid} "
        inode = f":{os.fstat(fd).st_ino} "
        while child.poll() is None and not any(
            "->" in line and waiting in line and inode in line
            for line in Path("/proc/locks").read_text().splitlines()
        ):
            assert time.monotonic() < hang_guard, "the second process never waited its turn"
            time.sleep(0.005)
        shutil.copyfile(compiled, shared / "written.tmp")
        os.replace(shared / "written.tmp", shared / compiled.name)
    except BaseException:
        child.kill()  # nothing the test starts outlives it
        child.communicate()
        raise
    finally:
        os.unlink(lock)  # as compile_turn ends a turn
        os.close(fd)
    out, err = child.communicate(timeout=300)
    assert child.returncode == 0, err[-2000:]
    assert json.loads(out) == {"compiled": 0, "loaded": 1, "out": [2, 1]}
    assert sorted(path.name for path in shared.iterdir()) == [compiled.name]


def test_machine_code__an_unwritable_cache_compiles_into_a_temporary_one(
    tmp_path, monkeypatch, capsys
):
    """``MCCHAIN_CACHE_DIR`` under a regular file: the entry compiles and runs, its machine
    code goes to ``<tmp>/mcchain-native-<uid>`` (mcchain.folders), at most one warning."""
    import tempfile

    from mcchain import folders

    (tmp_path / "a-file").write_text("")
    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path / "a-file" / "cache"))
    monkeypatch.setattr(folders, "_warned", set())
    # a fresh temporary folder, so that only this compile can have written the file found
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    out = np.zeros(10, np.int64)
    NativeModule(SOURCE, "mcchain_test_unwritable").integers(7, 3, out)
    assert out[:2].tolist() == [2, 1]
    assert list(folders.temporary_cache("native").glob("mcchain_test_unwritable-integers-*"))
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "MCCHAIN_CACHE_DIR" in err[0] and "cannot be written" in err[0]


def test_array_layout__a_numpy_laid_out_otherwise_falls_back_to_numba(monkeypatch, capsys):
    """Where the ``PyArrayObject`` fields are not where the entries read them (checked
    without following a wrong pointer), the lanes compile with numba, with one warning."""
    from types import ModuleType

    from mcchain.codegen import native
    from mcchain.codegen.topology import Topology

    assert native.array_layout_ok()
    fields = dict(native.ARRAY_FIELDS)
    monkeypatch.setattr(native, "ARRAY_FIELDS", {**fields, "data": 24})
    monkeypatch.setattr(generate, "_MODULES", {})
    native.array_layout_ok.cache_clear()
    generate._native_usable.cache_clear()
    try:
        assert not native.array_layout_ok()
        topo = Topology.from_model(scene_model("double_pendulum"))
        assert isinstance(generate.lane_kernels(topo, "rk4"), ModuleType)  # numba's @njit
        assert isinstance(generate.lane_kernels(topo, "accel"), ModuleType)
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and "compile with numba instead" in err[0]
        # the dimension count read from the data pointer's low half: a multiple of 16, never 2
        monkeypatch.setattr(native, "ARRAY_FIELDS", {**fields, "nd": 16})
        native.array_layout_ok.cache_clear()
        assert not native.array_layout_ok()
    finally:
        native.array_layout_ok.cache_clear()
        generate._native_usable.cache_clear()


@pytest.mark.parametrize(
    "body",
    [
        "out[0] = [1, 2][0]",  # a list
        "out[0] = x @ x",  # an operator outside the subset
        "out[0] = y",  # a name never assigned
        "x = 1.0\n    x = out",  # an array into a scalar
    ],
)
def test_translation__outside_the_subset_is_refused(body):
    module = NativeModule(f"def f(x, out):\n    {body}\n", "mcchain_test_refused")
    with pytest.raises(TranslationError):
        module.f(1.0, np.zeros(1))


def test_entry_points__each_library_keeps_its_own_helpers():
    """Two entry points compile into two libraries of one JIT engine; their helpers carry
    the same names but other argument types, and each must call its own."""
    source = (
        "def twice(x):\n    return x * 2\n\n"
        "def ints(out):\n    out[0] = twice(3)\n\n"
        "def floats(out):\n    out[0] = twice(1.25)\n"
    )
    module = NativeModule(source, "mcchain_test_helpers")
    a, b = np.zeros(1), np.zeros(1)
    module.ints(a)
    module.floats(b)
    assert (a[0], b[0]) == (6.0, 2.5)


LANES = """
def lanes(W, nl, out):
    for l in range(nl):  # lanes: independent
        a = W[0 + l] * 2.0
        W[8 + l] = a + W[16 + l]
        out[l] = max(a, 1.0)
    for l in range(nl):
        out[l] += W[8 + l]
"""


def test_independent_loops__said_parallel_to_llvm_same_values():
    """A loop marked ``# lanes: independent``: its loads and stores in one distinct access
    group that its latch names ``llvm.loop.parallel_accesses`` (the IR verifies); the
    unmarked loop's are not; the values are Python's."""
    from llvmlite import binding

    from mcchain.codegen.native import _codegen, _target_data
    from mcchain.codegen.native_expressions import Array
    from mcchain.codegen.native_translate import ModuleTranslator

    argtypes = (Array("f64", 1, True), "i64", Array("f64", 1, True))
    translator = ModuleTranslator(LANES, "mcchain_test_lanes", _target_data(_codegen()))
    translator.entry("lanes", argtypes, "mcchain_test_lanes_entry")
    text = str(translator.ir_module)
    binding.parse_assembly(text).verify()
    assert text.count('!"llvm.loop.parallel_accesses"') == 1
    assert text.count("!llvm.loop ") == 1 and "= distinct !{}" in text
    body = text[text.index("define internal") :]
    tagged = [line for line in body.splitlines() if "!llvm.access.group" in line]
    # W[0 + l], W[16 + l] and out[l] read, W[8 + l] and out[l] written, the scalar a's slot
    assert sum(" load " in t for t in tagged) >= 2 and sum("store " in t for t in tagged) >= 3

    W, out = np.arange(24.0), np.zeros(8)
    ref_W, ref_out = W.copy(), out.copy()
    NativeModule(LANES, "mcchain_test_lanes").lanes(W, 5, out)
    namespace: dict[str, Any] = {}
    exec(LANES, namespace)
    namespace["lanes"](ref_W, 5, ref_out)
    _assert_same_bits(W, ref_W)
    _assert_same_bits(out, ref_out)


PREFETCH = """
from mcchain.kernels.config import prefetch


def rows(out, n):
    for s in range(out.shape[0]):
        for it in range(n):
            out[s, it, 0] = s + 0.5 * it
            prefetch(out, s, it + 3)
"""


def test_prefetch__a_write_hint_past_the_array_allowed_values_unchanged():
    """``prefetch(array, sample, index)``: an ``llvm.prefetch`` for a write of the row's
    address, without ``inbounds`` (the row may lie past the array: on the last rows here),
    and nothing else: the values are plain Python's (where it is a no-op)."""
    from llvmlite import binding

    from mcchain.codegen.native import _codegen, _target_data
    from mcchain.codegen.native_expressions import Array
    from mcchain.codegen.native_translate import ModuleTranslator

    argtypes = (Array("f32", 3, True), "i64")
    translator = ModuleTranslator(PREFETCH, "mcchain_test_prefetch", _target_data(_codegen()))
    translator.entry("rows", argtypes, "mcchain_test_prefetch_entry")
    text = str(translator.ir_module)
    binding.parse_assembly(text).verify()
    calls = [line for line in text.splitlines() if 'call void @"llvm.prefetch' in line]
    assert len(calls) == 1 and calls[0].rstrip().endswith("i32 1, i32 3, i32 1)")
    defined = {line.split(" = ")[0].strip(): line for line in text.splitlines() if " = " in line}
    address = calls[0].split("(i8* ")[1].split(",")[0]
    gep = defined[defined[address].split(" to ")[0].split()[-1]]
    assert "getelementptr float" in gep and "inbounds" not in gep

    out = np.full((3, 5, 2), np.nan, np.float32)
    ref = out.copy()
    NativeModule(PREFETCH, "mcchain_test_prefetch").rows(out, 5)
    namespace: dict[str, Any] = {}
    exec(PREFETCH, namespace)
    namespace["rows"](ref, 5)
    _assert_same_bits(out, ref)


TAKE = """
from mcchain.kernels.config import take_next


def drain(queue, stop, taken, spin):
    while True:
        item = take_next(queue)
        if item >= stop:
            break
        taken[item] += 1
        x = 0.0
        for k in range(spin):  # some work between takes, so that the threads interleave
            x += k * 1e-9
        taken[item] += 0 if x >= 0.0 else 1  # x used: the work is not optimised away
"""


def _drained_on_threads(drain, stop: int) -> np.ndarray:
    """How many times each of the items 0 … stop-1 of one queue was taken, by two threads
    calling ``drain`` on it at once."""
    from concurrent.futures import ThreadPoolExecutor

    queue, taken = np.zeros(1, np.int64), np.zeros(stop, np.int64)
    with ThreadPoolExecutor(max_workers=2) as pool:
        for future in [pool.submit(drain, queue, stop, taken, 2_000) for _ in range(2)]:
            future.result()
    assert queue[0] == stop + 2  # each thread ends on one take that found the queue empty
    return taken


def test_take_next__one_atomic_add_each_item_taken_once_by_two_threads():
    """``take_next(queue)``: ``atomicrmw add`` on the queue's first element (its old value
    returned), through the native translator and through numba; two threads draining one
    queue take each item exactly once (a plain read and write can give some twice). Plain
    Python: the next value, the queue raised by one."""
    from llvmlite import binding
    from numba import njit

    from mcchain.codegen.native import _codegen, _target_data
    from mcchain.codegen.native_expressions import Array
    from mcchain.codegen.native_translate import ModuleTranslator
    from mcchain.kernels.config import register_intrinsics, take_next

    translator = ModuleTranslator(TAKE, "mcchain_test_take", _target_data(_codegen()))
    argtypes = (Array("i64", 1, True), "i64", Array("i64", 1, True), "i64")
    translator.entry("drain", argtypes, "mcchain_test_take_entry")
    text = str(translator.ir_module)
    binding.parse_assembly(text).verify()
    assert len([line for line in text.splitlines() if "atomicrmw add" in line]) == 1

    stop = 4096
    native = NativeModule(TAKE, "mcchain_test_take")
    assert np.all(_drained_on_threads(native.drain, stop) == 1)
    register_intrinsics()
    namespace: dict[str, Any] = {}
    exec(TAKE, namespace)
    compiled = njit(nogil=True)(namespace["drain"])
    assert np.all(_drained_on_threads(compiled, stop) == 1)

    queue = np.array([7], np.int64)
    assert (take_next(queue), take_next(queue), int(queue[0])) == (7, 8, 9)


def test_take_next__a_queue_of_another_type_refused():
    with pytest.raises(TranslationError, match="take_next's queue is an int64 array"):
        NativeModule(TAKE, "mcchain_test_take_f64").drain(np.zeros(1), 8, np.zeros(8, np.int64), 0)


def test_entry_points__unknown_names_are_attribute_errors(native):
    with pytest.raises(AttributeError):
        native.no_such_function  # noqa: B018


# -- the lane kernels against numba's compile of the same text ------------------------------


def _histories(model, settings, compiler: str, monkeypatch, fresh=None) -> dict[str, Any]:
    """The float64 histories with the lane kernels of ``compiler``; ``fresh``: a folder in
    which the generated text is written anew (MCCHAIN_CACHE_DIR), so that numba compiles it
    in this process. Numba's machine code loaded from its cache beside the text differs
    from its fresh compile (``energy`` 1 ulp off in a few values: benchmarks/results/ci/ci.md):
    the reference is the compile, so the test passes on a developer's second run too."""
    monkeypatch.setenv("MCCHAIN_LANE_COMPILER", compiler)
    if fresh is not None:
        monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(fresh))
        for name in [name for name in sys.modules if name.startswith("mcchain_gen_")]:
            monkeypatch.delitem(sys.modules, name)
    generate._MODULES.clear()
    try:
        return simulate_float64(model, settings)
    finally:
        generate._MODULES.clear()


def _assert_bit_identical(native: dict[str, Any], numba: dict[str, Any]) -> None:
    assert native.keys() == numba.keys()
    for key, value in native.items():
        if isinstance(value, np.ndarray):
            _assert_same_bits(value, numba[key])
        else:
            assert value == numba[key], key


CONTACT_RK45 = {"t_end": 0.05, "dt": 1e-5, "output_dt": 1e-3, "method": "rk45"}

CRANK_JOURNAL = """
[scene]
name = "crank-journal"
gravity = [0.0, -9.81]
[[body]]
name = "crank"
mass = 0.1
inertia = 8.333333333333333e-05
position = [0.05, 0.0]
velocity = [0.0, 1.0]
angular_velocity = 20.0
[[body]]
name = "journal"
mass = 0.05
inertia = 1e-06
position = [0.1000971242816097, -2.3809114259050462e-05]
velocity = [0.02857093711086055, 2.116549137931635]
angular_velocity = 20.0
[[joint]]
name = "O"
bodies = ["ground", "crank"]
points = [[0.0, 0.0], [-0.05, 0.0]]
[[joint]]
name = "B"
bodies = ["crank", "journal"]
points = [[0.05, 0.0], [0.0, 0.0]]
clearance = 1e-4
eccentricity = -0.2404
model = "auto"
[joint.contact]
law = "lankarani-nikravesh"
restitution = 0.9
radius = 0.005
youngs_modulus = 2.07e11
poisson_ratio = 0.3
[[driver]]
body = "crank"
omega = 20.0
"""
"""A 0.1 m crank driven at 20 rad/s about an ideal ground pin, carrying at its tip, in a
bearing of 0.1 mm clearance, a 50 g journal (model auto, Lankarani–Nikravesh): the four-bar's
joint kinds, driver and contact model on two bodies (this test's CPU with numba's compile of
the rk45 module 35 s, the four-bar's 45 s). The journal sits on the wall opposite the
bearing's force (m (a − g), ``eccentricity``) and slides along it at 0.12 m/s relative to the
bearing: like a pendulum on a string with too little speed to loop, the link's force reaches
0 at 2.4 ms, then the journal flies and impacts (34 times in 50 ms)."""


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scene", "settings"),
    [
        # By default one whole lane module (rk4's) beside the translator's rules one by one
        # (the random programs and the risks below); numba's compile of each further module
        # costs 10-45 s of CPU, so the other templates are long references:
        ("double_pendulum", {"t_end": 0.2, "dt": 1e-3, "output_dt": 1e-2, "method": "rk4"}),
        pytest.param(
            "double_pendulum",
            {"t_end": 0.2, "dt": 1e-3, "output_dt": 1e-2, "method": "rk4-projection"},
            marks=pytest.mark.long,
        ),
        # rk45's module with ideal joints, the driver and a contact-law joint that separates
        # and impacts (the double pendulum's rk45 module, ideal joints only, added a compile,
        # not a path); the four-bar's (3 bodies) makes the same check on a larger module
        pytest.param("crank-journal", CONTACT_RK45, marks=pytest.mark.long),
        pytest.param("fourbar-contact", CONTACT_RK45, marks=pytest.mark.long),
        # last: the Radau stepper itself is compiled by the other tests' worker meanwhile
        ("double_pendulum", {"t_end": 0.05, "dt": 1e-3, "output_dt": 1e-2, "method": "radau"}),
    ],
    ids=["rk4", "rk4-projection", "crank-journal-rk45", "fourbar-contact-rk45", "radau-accel"],
)
def test_lanes__bit_identical_to_numba(scene, settings, monkeypatch, tmp_path):
    if scene == "fourbar-contact":
        from pathlib import Path

        text = (Path(__file__).parents[1] / "configs" / "fourbar-clearance.toml").read_text()
        model = model_of(text, nsample=8, name="fourbar-clearance")
    elif scene == "crank-journal":
        model = model_of(CRANK_JOURNAL, nsample=8, name="crank-journal")
    else:
        model = scene_model(scene, nsample=8)
    native = _histories(model, settings, "native", monkeypatch)
    numba = _histories(model, settings, "numba", monkeypatch, fresh=tmp_path / "cache")
    _assert_bit_identical(native, numba)
    if scene in ("crank-journal", "fourbar-contact"):  # the link lets go, then impacts
        law = native["impact_count"] >= 0  # the clearance joint (-1: ideal joints)
        assert law.any() and (native["first_separation_time"][law] > 0.0).all()
        assert (native["impact_count"][law] > 0).all()


# -- the translator's risks (issue 29): each as numba and Python have it ------------------------

RISKS = """
import numpy as np


def touch(out, k):
    out[k] += 1.0
    return True


def short_circuit(a, t, out):
    if a > 0 and touch(out, 0):
        out[2] += 1.0
    if a > 0 or touch(out, 1):
        out[3] += 1.0
    n = t.shape[0]
    while 0 <= a < n and t[a] > 0.0:
        a += 1
    out[4] = a
    out[5] = 1.0 if a < 0 or a >= n or not t[a] < 0.0 else -1.0
    flag = a > 0 and touch(out, 6) and a < 0
    out[7] = flag


def widened(n, out):
    x = 0
    for i in range(n):
        x = x + 0.5
    out[0] = x
    y = 1
    if n > 2:
        y = 2.5
    out[1] = y
    z = True
    z = z + 1.25
    out[2] = z


def big_local(n, out):
    work = np.zeros(300000)
    small = np.zeros(8)
    for i in range(work.shape[0]):
        work[i] = i * 0.5
    for i in range(8):
        small[i] = work[n + i]
    out[0] = small[0] + small[7]


def fill(out, value):
    out[0] = value


def reads(x, out):
    out[0] = x[0] * 2.0


def writes_through(x, out):
    out[0] = x[1]
    fill(x, 3.0)
"""


@pytest.fixture(scope="module")
def risks() -> NativeModule:
    return NativeModule(RISKS, "mcchain_test_risks", contract=False)


def _numba(source: str, name: str) -> Any:
    from numba import njit

    from mcchain.kernels.config import LANE_JIT

    namespace: dict[str, Any] = {}
    exec(source, namespace)
    options = {k: v for k, v in LANE_JIT.items() if k != "cache"}
    for fn in [k for k, v in namespace.items() if callable(v) and hasattr(v, "__code__")]:
        namespace[fn] = njit(**options)(namespace[fn])  # the callees too, by name
    return namespace[name]


@pytest.mark.parametrize("a", [-1, 0, 1, 3])
def test_and_or__short_circuit_as_python(risks, a):
    """The right operand runs only where the left does not decide: ``touch`` counts its
    calls, and ``t[a]`` is never read past the end (before: both sides, always)."""
    t = np.array([1.0, 2.0, -1.0])
    mine, ref = np.zeros(8), np.zeros(8)
    risks.short_circuit(a, t, mine)
    namespace: dict[str, Any] = {}
    exec(RISKS, namespace)
    namespace["short_circuit"](a, t, ref)
    _assert_same_bits(mine, ref)


@pytest.mark.parametrize("n", [0, 2, 5])
def test_int_then_float__widened_as_numba(risks, n):
    """A variable first an int (or bool), then a float: numba unifies it to float64; the
    translator did refuse it (TranslationError) at the user's first run."""
    mine, ref = np.zeros(3), np.zeros(3)
    risks.widened(n, mine)
    _numba(RISKS, "widened")(n, ref)
    _assert_same_bits(mine, ref)
    assert mine.tolist() == [0.5 * n, 2.5 if n > 2 else 1.0, 2.25]


def test_local_arrays__above_the_limit_on_the_heap_small_ones_on_the_stack():
    from mcchain.codegen.native import _codegen, _target_data
    from mcchain.codegen.native_expressions import STACK_ARRAY_MAX_BYTES, Array
    from mcchain.codegen.native_translate import ModuleTranslator

    argtypes = ("i64", Array("f64", 1, True))
    translator = ModuleTranslator(RISKS, "mcchain_test_heap", _target_data(_codegen()))
    translator.entry("big_local", argtypes, "mcchain_test_heap_entry")
    text = str(translator.ir_module)
    assert 300000 * 8 > STACK_ARRAY_MAX_BYTES >= 8 * 8
    assert "alloca double, i64 300000" not in text and "alloca double, i64 8" in text
    assert text.count('call i8* @"aligned_alloc"(') == 1
    assert text.count('call void @"free"(') == 1


def test_local_arrays__a_large_one_runs_on_a_thread_with_a_small_stack(tmp_path):
    """2.4 MB of work array on a thread with a 256 KiB stack: on the stack it crashed the
    process (SIGSEGV); on the heap it runs. In a process of its own, for that crash."""
    import subprocess
    import sys
    from pathlib import Path

    script = f"""
import threading
import numpy as np
from mcchain.codegen.native import NativeModule
module = NativeModule({RISKS!r}, "mcchain_test_small_stack", contract=False)
out = np.zeros(1)
threading.stack_size(256 << 10)
thread = threading.Thread(target=module.big_local, args=(5, out))
thread.start()
thread.join()
print(out[0])
"""
    repo = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(repo), "MCCHAIN_CACHE_DIR": str(tmp_path)}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env)
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert float(done.stdout) == 5 * 0.5 + 12 * 0.5


def test_read_only_arrays__refused_where_written_read_where_only_read(risks):
    """numba refuses a read-only array where the function writes it (here through a callee);
    the entry did write it."""
    frozen = np.arange(3.0)
    frozen.flags.writeable = False
    out = np.zeros(1)
    with pytest.raises(ValueError, match="writes_through: argument 0 is a read-only array"):
        risks.writes_through(frozen, out)
    assert frozen.tolist() == [0.0, 1.0, 2.0] and out[0] == 0.0
    risks.reads(frozen, out)
    assert out[0] == 0.0 * 2.0
    risks.writes_through(frozen.copy(), out)
    assert out[0] == 1.0


def test_machine_code__keyed_by_every_version_that_changes_it(tmp_path, monkeypatch):
    """Another numba, llvmlite, LLVM, Python or NumPy version (here: a patched numba) is
    another file: the old machine code is not loaded. A load counts as one, not a compile."""
    import numba

    from mcchain.codegen import native

    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path))
    versions = native.key_versions()
    assert {v.split()[0] for v in versions} >= {"numba", "llvmlite", "llvm", "python", "numpy"}
    out = np.zeros(10, np.int64)
    before = dict(native.COUNTS)
    NativeModule(SOURCE, "mcchain_test_versions").integers(7, 3, out)
    NativeModule(SOURCE, "mcchain_test_versions").integers(7, 3, out)
    assert native.COUNTS["compiled"] - before["compiled"] == 1
    assert native.COUNTS["loaded"] - before["loaded"] == 1
    monkeypatch.setattr(numba, "__version__", numba.__version__ + ".post1")
    native.key_versions.cache_clear()
    try:
        NativeModule(SOURCE, "mcchain_test_versions").integers(7, 3, out)
        assert native.COUNTS["compiled"] - before["compiled"] == 2
    finally:
        native.key_versions.cache_clear()
    assert len(list((tmp_path / "native").glob("*.bin"))) == 2


def test_machine_code__the_folder_keeps_the_most_recently_used_within_its_bound(tmp_path):
    from mcchain.codegen.native import evict_oldest

    for k, when in enumerate([30, 10, 40, 20]):
        path = tmp_path / f"f{k}.bin"
        path.write_bytes(b"x" * 100)
        os.utime(path, (when, when))
    (tmp_path / "other.txt").write_bytes(b"y" * 1000)
    removed = evict_oldest(tmp_path, 250, keep=tmp_path / "f1.bin")
    assert sorted(p.name for p in removed) == ["f0.bin", "f3.bin"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f1.bin", "f2.bin", "other.txt"]


def test_target__numbas_cpu_settings_not_the_hosts_flags(monkeypatch):
    """The lane width (in the generated text) follows the CPU numba compiles for:
    NUMBA_CPU_FEATURES, or none for NUMBA_CPU_NAME=generic; the host's only otherwise."""
    from mcchain.codegen import layout

    monkeypatch.setenv("NUMBA_CPU_NAME", "generic")
    monkeypatch.delenv("NUMBA_CPU_FEATURES", raising=False)
    assert layout.target_cpu() == ("generic", "")
    monkeypatch.setenv("NUMBA_CPU_NAME", "skylake-avx512")
    monkeypatch.setenv("NUMBA_CPU_FEATURES", "+avx2,+avx512f,+fma")
    assert layout.target_cpu() == ("skylake-avx512", "+avx2,+avx512f,+fma")
    assert layout.simd_doubles(layout.target_cpu()[1]) == 8
    assert layout.simd_doubles("+avx2,-avx512f,+fma") == 4


# -- random programs of the generator's subset, against numba ---------------------------------

NFLOAT, NINT, NOUT = 3, 3, 6


@st.composite
def _float_expr(draw: Any, depth: int = 0) -> str:
    leaves = [
        *(f"f{k}" for k in range(NFLOAT)),
        *(f"x[{k}]" for k in range(4)),
        *(f"i{k}" for k in range(NINT)),
        "m",
        "0.5", "-1.25", "3.0", "1e-3",
    ]  # fmt: skip
    if depth >= 3 or draw(st.booleans()):
        return draw(st.sampled_from(leaves))
    kind = draw(st.sampled_from(["bin", "bin", "call", "neg", "ifexp"]))
    a = draw(_float_expr(depth + 1))
    if kind == "neg":
        return f"(-{a})"
    if kind == "call":
        fn = draw(st.sampled_from(["max", "min", "abs", "sqrt"]))
        if fn == "abs":
            return f"abs({a})"
        if fn == "sqrt":
            return f"math.sqrt(abs({a}))"
        return f"{fn}({a}, {draw(_float_expr(depth + 1))})"
    b = draw(_float_expr(depth + 1))
    if kind == "ifexp":
        return f"({a} if {draw(_condition(depth + 1))} else {b})"
    return f"({a} {draw(st.sampled_from(['+', '-', '*', '/']))} {b})"


@st.composite
def _int_expr(draw: Any, depth: int = 0) -> str:
    leaves = [*(f"i{k}" for k in range(NINT)), *(f"k[{j}]" for j in range(4)), "0", "3", "-7"]
    if depth >= 3 or draw(st.booleans()):
        return draw(st.sampled_from(leaves))
    a, b = draw(_int_expr(depth + 1)), draw(_int_expr(depth + 1))
    op = draw(st.sampled_from(["+", "-", "*", "//", "%", "max", "min"]))
    if op in ("//", "%"):
        return f"({a} {op} (abs({b}) + 1))"
    if op in ("max", "min"):
        return f"{op}({a}, {b})"
    return f"({a} {op} {b})"


@st.composite
def _condition(draw: Any, depth: int = 0) -> str:
    kind = draw(st.sampled_from(["cmp", "cmp", "int", "and", "or", "not", "guard"]))
    if depth >= 2:
        kind = "cmp"
    op = draw(st.sampled_from(["<", "<=", ">", ">=", "==", "!="]))
    if kind == "cmp":
        return f"{draw(_float_expr(2))} {op} {draw(_float_expr(2))}"
    if kind == "int":
        return f"{draw(_int_expr(2))} {op} {draw(_int_expr(2))}"
    if kind == "not":
        return f"not ({draw(_condition(depth + 1))})"
    if kind == "guard":  # the read is valid only where the index check holds
        i = draw(st.sampled_from([f"i{k}" for k in range(NINT)]))
        return f"0 <= {i} < 4 and x[{i}] {op} {draw(_float_expr(2))}"
    word = "and" if kind == "and" else "or"
    return f"({draw(_condition(depth + 1))}) {word} ({draw(_condition(depth + 1))})"


@st.composite
def _statements(draw: Any, indent: str, depth: int = 0) -> list[str]:
    lines: list[str] = []
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["float", "int", "out", "mix", "if", "for"]))
        if depth >= 2 and kind in ("if", "for"):
            kind = "out"
        if kind == "float":
            lines.append(f"{indent}f{draw(st.integers(0, NFLOAT - 1))} = {draw(_float_expr())}")
        elif kind == "int":
            lines.append(f"{indent}i{draw(st.integers(0, NINT - 1))} = {draw(_int_expr())}")
        elif kind == "out":
            lines.append(f"{indent}out[{draw(st.integers(0, NOUT - 1))}] += {draw(_float_expr())}")
        elif kind == "mix":  # m is an int until this runs: numba's promotion to float64
            lines.append(f"{indent}m = m + {draw(_float_expr())}")
        elif kind == "if":
            lines.append(f"{indent}if {draw(_condition())}:")
            lines += draw(_statements(indent + "    ", depth + 1))
            if draw(st.booleans()):
                lines.append(f"{indent}else:")
                lines += draw(_statements(indent + "    ", depth + 1))
        else:
            lines.append(f"{indent}for j in range(min(abs({draw(_int_expr(1))}), 4)):")
            lines += draw(_statements(indent + "    ", depth + 1))
    return lines


@st.composite
def programs(draw: Any) -> str:
    """A function ``prog(x, k, out)`` of the translated subset: float and int variables,
    arithmetic of both, numba's promotion of an int to float64 (``m``), comparisons, short-
    circuit ``and``/``or``/``not`` guarding array reads, ``… if … else …``, ``if``/``else``,
    counted loops, ``max``/``min``/``abs``/``math.sqrt``."""
    head = [f"    f{j} = x[{j}]" for j in range(NFLOAT)]
    head += [f"    i{j} = k[{j}]" for j in range(NINT)]
    head.append("    m = 0")
    body = draw(_statements("    "))
    tail = [f"    out[{NOUT - 1}] += m"]
    return "import math\n\n\ndef prog(x, k, out):\n" + "\n".join(head + body + tail) + "\n"


finite = st.floats(-1e3, 1e3, allow_nan=False)


@pytest.mark.slow
@settings(max_examples=15, deadline=None)  # a numba compile each (1-3 s)
@given(
    source=programs(),
    x=st.lists(finite | st.sampled_from([0.0, -0.0, math.inf, math.nan]), min_size=4, max_size=4),
    k=st.lists(st.integers(-5, 6), min_size=4, max_size=4),
)
def test_random_programs__the_bits_of_numba(source, x, k):
    """The translator against numba's compile of the same text (the lane kernels' options,
    ``contract`` included), bit for bit (a NaN only at the same place: module docstring)."""
    xs, ks = np.array(x), np.array(k, dtype=np.int64)
    mine, ref = np.zeros(NOUT), np.zeros(NOUT)
    NativeModule(source, "mcchain_test_random").prog(xs, ks, mine)
    _numba(source, "prog")(xs, ks, ref)
    _assert_same_bits(mine, ref)


def test_lane_kernels__a_warm_process_reads_the_text_without_generating_it(
    tmp_path, monkeypatch
) -> None:
    """The first process generates the text (and keeps it); the next one (an empty
    ``_MODULES``) reads that text — exactly what the generator gives — and generates none."""
    from mcchain.codegen.topology import Topology

    monkeypatch.setenv("MCCHAIN_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(generate, "_MODULES", {})
    topo = Topology.from_model(scene_model("double_pendulum"))
    first = generate.lane_kernels(topo, "rk4")
    assert first.source == generate.generate_source(topo, "rk4")

    def generated(*args: Any, **kwargs: Any) -> str:
        raise AssertionError("a warm process generated the lane text again")

    monkeypatch.setattr(generate, "_MODULES", {})
    monkeypatch.setattr(generate, "generate_source", generated)
    again = generate.lane_kernels(topo, "rk4")
    assert again is not first and again.source == first.source
    assert [p.suffix for p in (tmp_path / "lane-text").iterdir()] == [".txt"]


# -- branches in lane loops: selects, never masked stores ----------------------------------

KEEPS = """
import numpy as np


def keeps(X, nl, t, out):
    W = np.zeros(64)
    for k in range(64):
        W[k] = X[k]
    for l in range(nl):  # lanes: independent
        fresh = W[0 + l] == 0.0 or t > W[8 + l]
        W[16 + l] = W[24 + l] if fresh else W[16 + l]
        W[24 + l] = max(W[24 + l], W[32 + l]) if fresh else W[24 + l]
        W[32 + l] = W[32 + l] if W[40 + l] > 0.0 else 0.0
        W[40 + l] = (W[0 + l] + 2.0) if fresh and W[48 + l] < 1.0 else -W[40 + l]
        out[l] = W[56 + l] if not fresh else out[l]
    for l in range(nl):
        W[48 + l] = W[48 + l] if W[48 + l] > 0.5 else t
    for k in range(64):
        X[k] = W[k]
"""


def _keeps_machine_code() -> str:
    """The assembly of ``KEEPS``'s entry as the lane kernels are compiled
    (:meth:`NativeModule._compile`)."""
    from numba.core.compiler_lock import global_compiler_lock

    from mcchain.codegen.native import _codegen
    from mcchain.codegen.native_expressions import Array

    vector = Array("f64", 1, True)
    module = NativeModule(KEEPS, "mcchain_test_keeps_code")
    with global_compiler_lock:  # numba's codegen asserts it
        library = module._compile(
            _codegen(), "keeps", (vector, "i64", "f64", vector), "mcchain_test_keeps_entry"
        )
        return library.get_asm_str()


values = st.one_of(st.floats(-2.0, 2.0), st.just(0.0), st.just(math.nan))


@pytest.fixture(scope="module")
def keeps() -> NativeModule:
    return NativeModule(KEEPS, "mcchain_test_keeps")


@settings(max_examples=60, deadline=None)
@given(data=st.lists(values, min_size=64, max_size=64), nl=st.integers(0, 8), t=values)
def test_lane_branches__selects_give_python_s_values(keeps, data, nl, t):
    """The conditional expressions and ``or``/``and`` of a lane loop, evaluated eagerly and
    selected (its reads are in bounds whatever the branch), and ``a[i] = x if c else a[i]``
    anywhere: the values are Python's, NaN comparisons included."""
    X, out = np.array(data), np.arange(8.0)
    ref_X, ref_out = X.copy(), out.copy()
    keeps.keeps(X, nl, t, out)
    namespace: dict[str, Any] = {}
    exec(KEEPS, namespace)
    namespace["keeps"](ref_X, nl, t, ref_out)
    _assert_same_bits(X, ref_X)
    _assert_same_bits(out, ref_out)


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="x86 code")
def test_lane_branches__no_masked_store_in_the_machine_code():
    """Neither the lane loop's branches nor ``a[i] = x if c else a[i]`` become masked
    stores: ``vmaskmovpd`` (AVX2) is microcoded on AMD Zen 1-3, where the rk4 step's
    tracking, all such stores, took 16 % of the step; LLVM 22 folds a select between a
    value and the element just read, stored back, into one (llvm/llvm-project#213195).
    (A masked load is harmless: the unmarked loop's may be one.)"""
    code = _keeps_machine_code()
    stores = [
        line for line in code.splitlines()
        if ("maskmov" in line and line.rstrip().endswith(")"))  # a masked store's target
        or ("{%k" in line and "mov" in line and line.rstrip().endswith("}"))
    ]  # fmt: skip
    assert stores == [], stores
