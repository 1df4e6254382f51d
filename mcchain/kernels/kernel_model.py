"""The kernel model as one numba structure passed by reference.

Kernels read the model as ``km.<field>[...]``. A NamedTuple of 35 arrays did the same, but
numba passes a tuple by value, flattened to about 280 scalar arguments at every call of every
helper, and that IR dominated the compile time (benchmarks/results/startup/breakdown.md). A
StructRef is one pointer, and its fields read the same way, so no kernel changes. The
structure is built once per solve by :func:`as_struct`, a cached kernel whose field types
come from the NamedTuple it is given (:class:`mcchain.model.KernelModel`, which the Model
builds: the kernels import nothing of the Model, only its codes, from :mod:`mcchain.codes`).
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.core.extending import overload
from numba.experimental import structref

from mcchain.kernels.config import JIT, njit


@structref.register
class KernelModelType(types.StructRef):
    """Numba type of the kernel model: one field per :class:`~mcchain.model.KernelModel`
    array, same name, same array type."""


class KernelModelStruct(structref.StructRefProxy):
    """Python handle of a kernel model built by :func:`as_struct` (opaque: read the arrays
    from the :class:`~mcchain.model.KernelModel` it was built from)."""


structref.define_boxing(KernelModelType, KernelModelStruct)


def _from_tuple(arrays):  # pragma: no cover - replaced by the overload in compiled code
    raise NotImplementedError


@overload(_from_tuple, jit_options=dict(JIT, cache=False))  # built inside _as_struct
def _from_tuple_impl(arrays):
    struct_type = KernelModelType(list(zip(arrays.fields, arrays.types, strict=True)))
    lines = ["def build(arrays):", "    km = structref.new(struct_type)"]
    lines += [f"    km.{name} = arrays.{name}" for name in arrays.fields]
    lines += ["    return km"]
    namespace = {"structref": structref, "struct_type": struct_type}
    exec("\n".join(lines), namespace)  # one assignment per field, known only from the type
    return namespace["build"]


@njit(**JIT)
def _as_struct(arrays):
    return _from_tuple(arrays)


def as_struct(arrays: tuple[np.ndarray, ...]) -> KernelModelStruct:
    """The kernel model that every kernel takes as ``km``, sharing the arrays of ``arrays``
    (a :class:`~mcchain.model.KernelModel`: a NamedTuple of arrays, whose names and array
    types become the structure's fields)."""
    return _as_struct(arrays)
