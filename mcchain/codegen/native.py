"""Generated lane-kernel modules compiled to machine code without numba's type inference.

The generated text (``generate.py``) is plain Python over a small subset: scalars
(float64, int64, uint32, bool), arrays indexed element by element, ``for … in range``,
``while``, ``if``, calls of the module's own functions, ``max``/``min``/``abs``/
``math.sqrt``/``**``. numba types every operation of that text against its operator
templates, about 1 ms a site, and lowers it in Python: 20-30 s for a four-bar with a
contact joint (benchmarks/results/startup/breakdown.md). Here each function is translated
to LLVM IR in one pass over its syntax tree, with the types the text implies, and handed
to numba's own code generator (the same LLVM passes, target machine and fast-math flag
``contract`` as ``@njit``), so the machine code is that of the numba-compiled text.

The entry points are called from Python through ``ctypes`` (which releases the GIL, so the
thread blocks of :mod:`mcchain.solvers.threads` run side by side): an array is passed as its
``PyArrayObject *``, whose data pointer, shape and strides the entry reads, a float as a
double, an integer as an int64; the arguments' types are keyed as numba's dispatcher keys
them. Machine code is cached on disk per (text, entry, argument types, target CPU and its
features, and the versions that can change it: :func:`key_versions`), in a folder of bounded
size (:data:`CACHE_MAX_BYTES`).

The translation: :mod:`mcchain.codegen.native_translate` (statements, modules) over
:mod:`mcchain.codegen.native_expressions` (types, expressions); this module compiles, caches
and calls.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import hashlib
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from llvmlite import ir

from mcchain.codegen.native_expressions import (
    ARRAY_FIELDS,
    F64,
    NPY_ARRAY_WRITEABLE,
    Array,
    Tuple,
    Type,
    type_of_value,
)
from mcchain.compiled.caches import compile_turn, evict_oldest, mcchain_cache, write_atomically


def ctypes_argument(ty: Type) -> Any:
    """The ``ctypes`` type an entry point takes for an argument of type ``ty``."""
    if isinstance(ty, Array):
        return ctypes.py_object
    if isinstance(ty, Tuple):
        raise TypeError("tuple arguments are not supported")
    return ctypes.c_double if ty == F64 else ctypes.c_int64


@functools.cache
def array_layout_ok() -> bool:
    """Whether :data:`ARRAY_FIELDS` hold for this NumPy (the entries would read garbage
    otherwise; :func:`mcchain.codegen.generate.lane_kernels` then compiles with numba). The
    shape and strides pointers are followed only once the data pointer and the dimension
    count, read inside the array object itself, are right."""
    probe = np.zeros((3, 5))[:, ::2]
    base = id(probe)

    def read(address: int, ctype: Any = ctypes.c_int64) -> int:
        return int(ctype.from_address(address).value)

    if read(base + ARRAY_FIELDS["data"]) != probe.ctypes.data:
        return False
    if read(base + ARRAY_FIELDS["nd"], ctypes.c_int32) != probe.ndim:
        return False
    shape = tuple(read(read(base + ARRAY_FIELDS["shape"]) + 8 * k) for k in (0, 1))
    strides = tuple(read(read(base + ARRAY_FIELDS["strides"]) + 8 * k) for k in (0, 1))
    if (shape, strides) != (probe.shape, probe.strides):
        return False
    frozen = probe.view()
    frozen.flags.writeable = False
    writeable = [
        read(id(a) + ARRAY_FIELDS["flags"], ctypes.c_int32) & NPY_ARRAY_WRITEABLE
        for a in (probe, frozen)
    ]
    return bool(writeable[0]) and not writeable[1]


def lane_compiler() -> str:
    """What compiles the generated lane kernels in this process
    (:func:`mcchain.codegen.generate.lane_kernels`): ``"native"`` (this module), or
    ``"numba"`` with ``MCCHAIN_LANE_COMPILER=numba`` or where this NumPy's array layout is
    not the one the entries read."""
    if os.environ.get("MCCHAIN_LANE_COMPILER") == "numba" or not array_layout_ok():
        return "numba"
    return "native"


_BACKEND_HASH = hashlib.sha256(
    b"".join(
        (Path(__file__).parent / name).read_bytes()
        for name in ("native.py", "native_expressions.py", "native_translate.py")
    )
).hexdigest()[:16]
"""The translator's and this module's sources: machine code they made is keyed by them."""

COUNTS = {"compiled": 0, "loaded": 0}
"""Entry points compiled, and loaded from the disk cache, by this process (for tests and
``mcchain cache warm``)."""

CACHE_MAX_BYTES = 256 << 20
"""Bound of the ``native`` cache folder: beyond it, the files used least recently are removed
when one is written (an entry's machine code is 0.1-1 MB: hundreds of scenes' kernels)."""


@functools.cache
def key_versions() -> tuple[str, ...]:
    """Everything besides the text, the entry, its argument types, the contract flag and the
    target CPU (numba's ``magic_tuple``) that can change the machine code of an entry: this
    file, the generator's sources, and the versions of numba, llvmlite, LLVM, Python and
    NumPy (a patch release of any of them may change the code or the ABI it assumes)."""
    import sys

    import llvmlite
    import numba
    from llvmlite import binding

    from mcchain.codegen.cache import generator_hash

    llvm = ".".join(map(str, binding.llvm_version_info))
    return (
        f"native {_BACKEND_HASH}",
        f"generator {generator_hash()}",
        f"numba {numba.__version__}",
        f"llvmlite {llvmlite.__version__}",
        f"llvm {llvm}",
        f"python {sys.version.split()[0]} {sys.implementation.cache_tag}",
        f"numpy {np.__version__}",
    )


def _fingerprint_function() -> Callable[[Any], Any]:
    """The key of an argument's type as numba's dispatcher computes it (C, ~0.2 µs an
    argument; radau calls ``accel`` from Python at every evaluation); where numba's C
    helper moved, the same key built in Python (slower)."""
    try:
        from numba._dispatcher import compute_fingerprint

        return compute_fingerprint  # type: ignore[no-any-return]
    except ImportError:
        return type_of_value


def _codegen() -> Any:
    from numba.core.registry import cpu_target

    return cpu_target.target_context.codegen()


class NativeModule:
    """The entry points of a generated module, compiled on first call per argument types
    (as numba's dispatcher does) and cached on disk. ``contract``: float operations may fuse
    into multiply-adds (the lane kernels' ``fastmath={"contract"}``); without it, every
    operation rounds as in Python."""

    def __init__(self, source: str, name: str, contract: bool = True) -> None:
        self.source = source
        self.name = name
        self.contract = contract
        self._digest = hashlib.sha256(source.encode()).hexdigest()[:20]
        # by entry point, then by the arguments' type keys: (C function, its library)
        self._entries: dict[str, dict[tuple[Any, ...], tuple[Any, Any]]] = {}
        self._fingerprint = _fingerprint_function()
        # The module's functions, by their `def` at column 0: parsing the text would cost
        # 0.15 s for a 32-bar chain on each warm run (it is parsed only to compile).
        self._functions = set(re.findall(r"^def (\w+)\(", source, flags=re.MULTILINE))

    def __getattr__(self, name: str) -> Callable[..., None]:
        if name.startswith("_") or name not in self.__dict__.get("_functions", ()):
            raise AttributeError(name)

        fingerprint = self._fingerprint
        entries = self._entries.setdefault(name, {})

        def call(*args: Any) -> None:
            key = tuple(map(fingerprint, args))
            entry = entries.get(key)
            if entry is None:
                entry = self._entry(name, key, args)
            refused = entry[0](*args)
            if refused:
                raise ValueError(
                    f"{name}: argument {refused - 1} is a read-only array, which it writes"
                )

        call.__name__ = name
        self.__dict__[name] = call  # later lookups skip __getattr__ (radau calls per step)
        return call

    def _entry(self, name: str, key: tuple[Any, ...], args: tuple[Any, ...]) -> tuple[Any, Any]:
        from numba.core.compiler_lock import global_compiler_lock

        argtypes = tuple(type_of_value(a) for a in args)
        with global_compiler_lock:  # one compile at a time, as numba's dispatchers
            entry = self._entries[name].get(key)
            if entry is None:
                if not array_layout_ok():
                    raise RuntimeError("this NumPy's array layout is not the one entries read")
                holder, address = self._load_or_compile(name, argtypes)
                proto = ctypes.CFUNCTYPE(ctypes.c_int32, *map(ctypes_argument, argtypes))
                entry = (proto(address), holder)  # the engine or library holds the code
                self._entries[name][key] = entry
        return entry

    def _load_or_compile(self, name: str, argtypes: tuple[Type, ...]) -> tuple[Any, int]:
        """Entry point ``name`` for ``argtypes``, loaded from the disk cache
        (:data:`CACHE_FORMAT`) or compiled now: what holds its machine code (the engine
        or the compiled library) and the address of its entry function."""
        codegen = _codegen()
        key = repr(
            (self._digest, name, argtypes, self.contract, codegen.magic_tuple(), *key_versions(),
             CACHE_FORMAT)
        )  # fmt: skip
        digest = hashlib.sha256(key.encode()).hexdigest()[:24]
        path = mcchain_cache("native") / f"{self.name}-{name}-{digest}.bin"
        symbol = f"{self.name}.{name}.{digest}"  # unique in the process's JIT engines
        loaded = _load_object(path, symbol)
        if loaded is not None:
            return loaded
        # Another process compiling the same entry (a command started beside this one, a
        # test worker) holds this turn: wait for it, then read what it wrote.
        with compile_turn(path.with_suffix(".lock")):
            loaded = _load_object(path, symbol)
            if loaded is None:
                library = self._compile(codegen, name, argtypes, symbol)
                _name, _kind, (object_code, _bitcode) = library.serialize_using_object_code()
                write_atomically(path, _object_file(object_code))
                address = library.get_pointer_to_function(symbol)
                if not address:
                    raise RuntimeError(f"{symbol} missing from its compiled library")
                loaded = library, address
        evict_oldest(path.parent, CACHE_MAX_BYTES, keep=path)
        return loaded

    def _compile(self, codegen: Any, name: str, argtypes: tuple[Type, ...], symbol: str) -> Any:
        """Entry point ``name`` for ``argtypes`` compiled now, as the library ``symbol``."""
        from mcchain.codegen.native_translate import ModuleTranslator  # only to compile

        COUNTS["compiled"] += 1
        # Symbols unique in the process's JIT engine, which holds every library.
        translator = ModuleTranslator(self.source, symbol, _target_data(codegen))
        translator.entry(name, argtypes, symbol)
        _prefer_register_width(translator.ir_module)
        if self.contract:
            _contract(translator.ir_module)
        library = codegen.create_library(f"{self.name}.{name}")
        library.enable_object_caching()
        library.add_ir_module(translator.ir_module)
        library.finalize()
        library.get_pointer_to_function(symbol)
        return library


CACHE_FORMAT = "object code alone, with its digest"
"""What a cache file holds: the entry's object code (ELF on Linux), loaded as it is, after
:data:`OBJECT_HEADER` and the object code's SHA-256. numba's own format
(:meth:`CodeLibrary.serialize_using_object_code`) adds the module's bitcode, for other
libraries to inline from, and parsing it back cost 80-90 ms an entry on every warm run;
nothing inlines from an entry. Part of the key, so a file of the other format is never read
as this one; the digest is checked before LLVM reads the code (a damaged object file
crashes LLVM's loader, where a damaged pickle raised)."""

OBJECT_HEADER = b"mcchain native object 1\n"
"""The first bytes of a cache file (:data:`CACHE_FORMAT`)."""


def _object_file(object_code: bytes) -> bytes:
    """The bytes of a cache file holding ``object_code`` (:data:`CACHE_FORMAT`)."""
    return OBJECT_HEADER + hashlib.sha256(object_code).digest() + object_code


def _object_code(data: bytes) -> bytes | None:
    """The object code of a cache file's bytes, or None where they are not a whole file of
    :data:`CACHE_FORMAT` (its digest differs: a damaged or partial file)."""
    if not data.startswith(OBJECT_HEADER):
        return None
    start = len(OBJECT_HEADER) + hashlib.sha256().digest_size
    digest, object_code = data[len(OBJECT_HEADER) : start], data[start:]
    return object_code if hashlib.sha256(object_code).digest() == digest else None


@functools.cache
def _object_engine() -> Any:
    """The process's execution engine (MCJIT) of the entries loaded from the cache: their
    object code is linked in as it is (its relocations resolved, its calls of libm's
    functions bound in this process, as numba's own engine binds them), without the
    bitcode numba's libraries parse. Created once; entries stay in it for the process's
    life, as those of numba's engine do."""
    from llvmlite import binding

    _codegen()  # numba's symbols (its C helpers) registered in the process, as for a compile
    target = binding.Target.from_triple(binding.get_process_triple())
    machine = target.create_target_machine(
        cpu=binding.get_host_cpu_name(),
        features=binding.get_host_cpu_features().flatten(),
        codemodel="jitdefault",
        jit=True,
    )
    return binding.create_mcjit_compiler(binding.parse_assembly(""), machine)


def _load_object(path: Path, symbol: str) -> tuple[Any, int] | None:
    """The engine holding entry ``symbol``, cached at ``path``, and its address; None where
    there is no such file, or it cannot be read or does not define ``symbol`` (a stale or
    partial file: compiled again)."""
    from llvmlite import binding

    engine = _object_engine()
    if symbol in _LOADED:  # an engine cannot hold a symbol twice
        return engine, _LOADED[symbol]
    try:
        object_code = _object_code(path.read_bytes())
    except OSError:
        return None
    if object_code is None:
        return None
    try:
        engine.add_object_file(binding.ObjectFileRef.from_data(object_code))
        engine.finalize_object()
        address = engine.get_function_address(symbol)
    except Exception:
        return None
    if not address:
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # recently used: the last to be evicted
    COUNTS["loaded"] += 1
    _LOADED[symbol] = address
    return engine, address


_LOADED: dict[str, int] = {}
"""The entries :func:`_object_engine` holds: symbol -> address."""


def _target_data(codegen: Any) -> Any:
    from llvmlite import binding

    return binding.create_target_data(codegen._data_layout)


def _prefer_register_width(module: ir.Module) -> None:
    """Vectorise every function for the target's whole SIMD register (LLVM's own preference
    on AVX-512 CPUs is 256 bits, half of one: the lanes' vector bodies took twice the
    instructions)."""
    from mcchain.codegen.layout import LMAX

    attribute = f'"prefer-vector-width"="{64 * LMAX}"'
    for function in module.functions:
        if not function.is_declaration:
            # llvmlite's attribute set admits LLVM's keyword attributes only; a string
            # attribute is written as its text, so it goes into the set as that text.
            set.add(function.attributes, attribute)


def _contract(module: ir.Module) -> None:
    """The fast-math flag ``contract`` on every float operation, as numba sets it for the
    lane kernels (``LANE_JIT``)."""
    from numba.core.cpu_options import FastMathOptions
    from numba.core.fastmathpass import rewrite_module

    rewrite_module(module, FastMathOptions({"contract"}))
