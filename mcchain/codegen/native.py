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

Semantics follow numba's: Python's integer floor division and modulo, ``max``/``min`` as
``select(b > a, b, a)``, bool and integer operands promoted to float64 or int64, an array
index without wrap-around (the generated text never indexes from the end).
"""

from __future__ import annotations

import ast
import contextlib
import ctypes
import functools
import hashlib
import math
import os
import pickle
import re
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from llvmlite import ir

from mcchain.caches import mcchain_cache
from mcchain.codegen.schedule import INDEPENDENT_MARK

F64, I64, U32, BOOL = "f64", "i64", "u32", "bool"
"""Scalar types of the translated text."""
F32 = "f32"
"""An element type of arrays only (outputs stored in single precision): read as float64."""

_DOUBLE = ir.DoubleType()
_I64 = ir.IntType(64)
_I32 = ir.IntType(32)
_I8 = ir.IntType(8)
_I1 = ir.IntType(1)
_VALUE_TYPE = {F64: _DOUBLE, I64: _I64, U32: _I32, BOOL: _I1}
_MEMORY_TYPE = {F64: _DOUBLE, F32: ir.FloatType(), I64: _I64, U32: _I32, BOOL: _I8}
_DTYPES = {"float64": F64, "float32": F32, "int64": I64, "uint32": U32, "bool": BOOL}
_NUMPY_DTYPES = {"np.float64": F64, "np.int64": I64, "np.uint32": U32, "np.bool_": BOOL}
_CONSTANTS = {
    "np.nan": math.nan,
    "math.nan": math.nan,
    "np.inf": math.inf,
    "math.inf": math.inf,
    "math.pi": math.pi,
}


@dataclass(frozen=True)
class Array:
    """An array argument or local: element type, dimensions, C-contiguous or strided."""

    dtype: str
    ndim: int
    contiguous: bool


@dataclass(frozen=True)
class Tuple:
    """A tuple of scalars (what a function such as ``contact_crossing`` returns)."""

    items: tuple[str, ...]


Type = str | Array | Tuple
Returned = str | Tuple | None
"""What a function returns: a scalar, a tuple of scalars, or nothing."""


class TranslationError(Exception):
    """The generated text uses something outside the translated subset (a bug of the
    generator, never of a scene)."""


class _Widen(Exception):
    """A variable first assigned an integer (or bool) is assigned a float later: the function
    is translated again with the variable a float from its first assignment, as numba's type
    unification makes it where the two meet (a loop, a branch)."""

    def __init__(self, name: str, ty: str) -> None:
        super().__init__(name, ty)
        self.name = name
        self.ty = ty


def type_of_value(value: Any) -> Type:
    """The translated type of an argument passed from Python."""
    if isinstance(value, np.ndarray):
        dtype = _DTYPES.get(value.dtype.name)
        if dtype is None:
            raise TypeError(f"arrays of {value.dtype} are not supported")
        return Array(dtype, value.ndim, bool(value.flags.c_contiguous))
    if isinstance(value, (bool, np.bool_)):
        return BOOL
    if isinstance(value, (int, np.integer)):
        return I64
    if isinstance(value, (float, np.floating)):
        return F64
    raise TypeError(f"arguments of type {type(value).__name__} are not supported")


def _unify(a: str, b: str) -> str:
    """numba's promotion of two scalar operands: float64 if either is, else int64."""
    if a == b and a != U32:
        return a
    return F64 if F64 in (a, b) else I64


@dataclass
class _ArrayValue:
    ty: Array
    data: ir.Value  # pointer to the first element (memory type)
    shape: list[ir.Value]
    strides: list[ir.Value]  # bytes


@dataclass
class _Loop:
    head: ir.Block  # continue
    exit: ir.Block  # break


class _FunctionTranslator:
    """One specialisation of one function of the module: its IR function."""

    def __init__(
        self,
        module: ModuleTranslator,
        fn: ast.FunctionDef,
        argtypes: tuple[Type, ...],
        name: str,
        return_type: Returned,
        widened: dict[str, str] | None = None,
    ) -> None:
        self.module = module
        self.fn = fn
        self.widened = widened or {}  # variables that are float64 from their first assignment
        self.written: set[str] = set()  # array arguments stored into, here or by a callee
        self.heap: list[ir.Value] = []  # local arrays allocated with aligned_alloc
        self.argtypes = argtypes
        self.return_type = return_type
        self.returned: list[Type] = []
        params: list[ir.Type] = []
        for ty in argtypes:
            if isinstance(ty, Array):
                params += [_MEMORY_TYPE[ty.dtype].as_pointer()] + [_I64] * (2 * ty.ndim)
            elif isinstance(ty, Tuple):
                raise TranslationError(f"{fn.name}: tuple arguments are not supported")
            else:
                params.append(_VALUE_TYPE[ty])
        ret = ir.VoidType() if return_type is None else _llvm_type(return_type)
        self.function = ir.Function(module.ir_module, ir.FunctionType(ret, params), name)
        self.function.linkage = "internal"  # names repeat between libraries
        entry = self.function.append_basic_block("entry")
        self.alloca_builder = ir.IRBuilder(entry)
        body = self.function.append_basic_block("body")
        self.builder = ir.IRBuilder(body)
        self.exit = self.function.append_basic_block("exit")
        self.ret_slot = None if return_type is None else self._alloca(_llvm_type(return_type))
        self.vars: dict[str, tuple[ir.Value, str]] = {}  # scalar name: (slot, type)
        self.arrays: dict[str, _ArrayValue] = {}
        self.tuples: dict[str, tuple[ir.Value, Tuple]] = {}
        self.loops: list[_Loop] = []
        args = iter(self.function.args)
        for arg, ty in zip(fn.args.args, argtypes, strict=True):
            if isinstance(ty, Array):
                data = next(args)
                shape = [next(args) for _ in range(ty.ndim)]
                strides = [next(args) for _ in range(ty.ndim)]
                self.arrays[arg.arg] = _ArrayValue(ty, data, shape, strides)
            elif isinstance(ty, str):
                self._store_var(arg.arg, next(args), ty)

    # -- the function ---------------------------------------------------------------------

    def translate(self) -> ir.Function:
        self._statements(self.fn.body)
        if not self.builder.block.is_terminated:
            self.builder.branch(self.exit)
        self.alloca_builder.branch(self.function.blocks[1])
        b = ir.IRBuilder(self.exit)
        for raw in self.heap:  # every return goes through this block
            b.call(self.module.libc("free"), [raw])
        if self.ret_slot is None:
            b.ret_void()
        else:
            b.ret(b.load(self.ret_slot))
        return self.function

    def _alloca(self, ty: ir.Type, count: int | None = None) -> ir.Value:
        size = None if count is None else ir.Constant(_I64, count)
        return self.alloca_builder.alloca(ty, size=size)

    def _store_var(self, name: str, value: ir.Value, ty: str) -> None:
        if name in self.arrays or name in self.tuples:
            raise TranslationError(f"{self.fn.name}: {name} changes kind")
        slot = self.vars.get(name)
        if slot is None:
            slot_ty = self.widened.get(name, ty)
            slot = (self._alloca(_VALUE_TYPE[slot_ty]), slot_ty)
            self.vars[name] = slot
        if slot[1] != ty:
            wider = _unify(slot[1], ty)
            if wider != slot[1]:
                raise _Widen(name, wider)
            value = self._cast(value, ty, slot[1])
        self.builder.store(value, slot[0])

    # -- statements -----------------------------------------------------------------------

    def _statements(self, body: list[ast.stmt]) -> None:
        for stmt in body:
            if self.builder.block.is_terminated:
                return  # code after break/continue/return
            self._statement(stmt)

    def _statement(self, stmt: ast.stmt) -> None:
        b = self.builder
        if isinstance(stmt, ast.Assign):
            if len(stmt.targets) != 1:
                raise TranslationError("chained assignment")
            self._assign(stmt.targets[0], stmt.value)
        elif isinstance(stmt, ast.AugAssign):
            load = _as_load(stmt.target)
            self._assign(stmt.target, ast.BinOp(load, stmt.op, stmt.value))
        elif isinstance(stmt, ast.Expr):
            if isinstance(stmt.value, ast.Constant):
                return  # a docstring
            if not isinstance(stmt.value, ast.Call):
                raise TranslationError(f"expression statement {ast.unparse(stmt)}")
            self._call(stmt.value)
        elif isinstance(stmt, ast.For):
            self._for(stmt)
        elif isinstance(stmt, ast.While):
            self._while(stmt)
        elif isinstance(stmt, ast.If):
            cond = self._condition(stmt.test)
            then = self.function.append_basic_block()
            orelse = self.function.append_basic_block() if stmt.orelse else None
            after = self.function.append_basic_block()
            b.cbranch(cond, then, orelse or after)
            b.position_at_end(then)
            self._statements(stmt.body)
            if not b.block.is_terminated:
                b.branch(after)
            if orelse is not None:
                b.position_at_end(orelse)
                self._statements(stmt.orelse)
                if not b.block.is_terminated:
                    b.branch(after)
            b.position_at_end(after)
        elif isinstance(stmt, ast.Break):
            b.branch(self.loops[-1].exit)
        elif isinstance(stmt, ast.Continue):
            b.branch(self.loops[-1].head)
        elif isinstance(stmt, ast.Pass):
            pass
        elif isinstance(stmt, ast.Return):
            if stmt.value is not None:
                value, ty = self._expr(stmt.value)
                self.returned.append(ty)
                if self.ret_slot is not None:
                    if ty != self.return_type:
                        if not (isinstance(ty, str) and isinstance(self.return_type, str)):
                            raise TranslationError(f"{self.fn.name} returns {ty}, not that")
                        value = self._cast(value, ty, self.return_type)
                    b.store(value, self.ret_slot)
            b.branch(self.exit)
        else:
            raise TranslationError(f"statement {ast.unparse(stmt)}")

    def _assign(self, target: ast.expr, value_node: ast.expr) -> None:
        if isinstance(target, ast.Name):
            if isinstance(value_node, ast.Call) and _name(value_node.func) in (
                "np.zeros",
                "np.full",
            ):
                self._local_array(target.id, value_node)
                return
            value, ty = self._expr(value_node)
            if isinstance(ty, Tuple):
                self.tuples[target.id] = (value, ty)
            elif isinstance(ty, Array):
                raise TranslationError(f"array assignment {ast.unparse(target)}")
            else:
                self._store_var(target.id, value, ty)
        elif isinstance(target, ast.Tuple):
            value, ty = self._expr(value_node)
            if not isinstance(ty, Tuple) or len(ty.items) != len(target.elts):
                raise TranslationError(f"unpacking {ast.unparse(value_node)}")
            for k, elt in enumerate(target.elts):
                if not isinstance(elt, ast.Name):
                    raise TranslationError("nested unpacking")
                self._store_var(elt.id, self.builder.extract_value(value, k), ty.items[k])
        elif isinstance(target, ast.Subscript):
            arr = self._array(target.value)
            if isinstance(target.value, ast.Name):
                self.written.add(target.value.id)
            value, ty = self._scalar(value_node)
            indices = _index_nodes(target.slice)
            if any(isinstance(i, ast.Slice) for i in indices):
                self._fill_slice(arr, indices, value, ty)
                return
            ptr = self._element_ptr(arr, [self._index(i) for i in indices])
            self._store_element(ptr, value, ty, arr.ty.dtype)
        else:
            raise TranslationError(f"assignment to {ast.unparse(target)}")

    def _store_element(self, ptr: ir.Value, value: ir.Value, ty: Type, dtype: str) -> None:
        if isinstance(ty, (Array, Tuple)):
            raise TranslationError("storing a non-scalar into an array")
        if dtype == F32:
            value = self.builder.fptrunc(self._cast(value, ty, F64), _MEMORY_TYPE[F32])
        else:
            value = self._cast(value, ty, dtype)
        if dtype == BOOL:
            value = self.builder.zext(value, _I8)
        self.builder.store(value, ptr)

    def _local_array(self, name: str, call: ast.Call) -> None:
        """``np.zeros(n[, dtype])`` or ``np.full(n, value)`` with a constant ``n``: stack
        storage allocated once, filled where the statement stands."""
        if name in self.arrays:
            raise TranslationError(f"{self.fn.name}: array {name} assigned twice")
        size = self.module.constant_int(call.args[0])
        if _name(call.func) == "np.zeros":
            dtype = _NUMPY_DTYPES[_name(call.args[1])] if len(call.args) > 1 else F64
            fill: tuple[ir.Value, Type] = (ir.Constant(_I64, 0), I64)
        else:
            fill = self._scalar(call.args[1])
            dtype = fill[1] if isinstance(fill[1], str) else F64
        itemsize = _MEMORY_TYPE[dtype].get_abi_size(self.module.target_data)
        if size * itemsize <= STACK_ARRAY_MAX_BYTES:
            data = self._alloca(_MEMORY_TYPE[dtype], size)
            data.align = LOCAL_ARRAY_ALIGN
        else:  # on the heap: a thread's stack may be small (512 KiB on macOS, 128 KiB musl)
            nbytes = -(-size * itemsize // LOCAL_ARRAY_ALIGN) * LOCAL_ARRAY_ALIGN
            align = ir.Constant(_I64, LOCAL_ARRAY_ALIGN)
            size_arg = ir.Constant(_I64, nbytes)
            raw = self.alloca_builder.call(self.module.libc("aligned_alloc"), [align, size_arg])
            self.heap.append(raw)
            data = self.alloca_builder.bitcast(raw, _MEMORY_TYPE[dtype].as_pointer())
        arr = _ArrayValue(
            Array(dtype, 1, True),
            data,
            [ir.Constant(_I64, size)],
            [ir.Constant(_I64, _MEMORY_TYPE[dtype].get_abi_size(self.module.target_data))],
        )
        self.arrays[name] = arr
        self._fill_slice(arr, [ast.Slice()], *fill)

    def _fill_slice(self, arr: _ArrayValue, indices: list[ast.expr], value: ir.Value, ty: Type):
        """``a[i, j, :] = value``: a loop over every ``:`` axis."""
        fixed = [None if isinstance(i, ast.Slice) else self._index(i) for i in indices]
        if any(isinstance(i, ast.Slice) and (i.lower or i.upper or i.step) for i in indices):
            raise TranslationError("only whole-axis slices are supported")

        def nest(axis: int, index: list[ir.Value]) -> None:
            if axis == len(fixed):
                ptr = self._element_ptr(arr, index)
                self._store_element(ptr, value, ty, arr.ty.dtype)
                return
            if fixed[axis] is not None:
                nest(axis + 1, [*index, fixed[axis]])
                return
            self._counted_loop(
                ir.Constant(_I64, 0),
                arr.shape[axis],
                ir.Constant(_I64, 1),
                lambda i: nest(axis + 1, [*index, i]),
            )

        nest(0, [])

    def _counted_loop(
        self,
        start: ir.Value,
        stop: ir.Value,
        step: ir.Value,
        body: Callable[[ir.Value], None],
        var: str | None = None,
        positive: bool = True,
        independent: bool = False,
    ) -> None:
        """``for i in range(start, stop, step)``: ``body(i)`` builds the body; with
        ``var``, ``i`` is also stored in that variable. ``independent``: the iterations
        touch disjoint memory (:data:`INDEPENDENT_MARK`), said to LLVM as
        ``llvm.loop.parallel_accesses``."""
        b = self.builder
        if not isinstance(stop, ir.Constant):
            # A run-time bound LLVM can also bound from above (nl <= LMAXV lanes) would make
            # it fold the loop's tail into masked loads and stores, slow on AMD CPUs; numba's
            # range loops hide that bound, and so does this (an empty asm: "some int64").
            stop = b.asm(ir.FunctionType(_I64, [_I64]), "", "=r,0", [stop], side_effect=False)
        counter = self._alloca(_I64)
        b.store(start, counter)
        head = self.function.append_basic_block()
        loop = self.function.append_basic_block()
        latch = self.function.append_basic_block()
        after = self.function.append_basic_block()
        b.branch(head)
        b.position_at_end(head)
        i = b.load(counter)
        more = b.icmp_signed("<" if positive else ">", i, stop)
        b.cbranch(more, loop, after)
        b.position_at_end(loop)
        if var is not None:
            self._store_var(var, i, I64)
        self.loops.append(_Loop(latch, after))
        first_new = len(self.function.blocks)
        body(i)
        self.loops.pop()
        if not b.block.is_terminated:
            b.branch(latch)
        b.position_at_end(latch)
        b.store(b.add(b.load(counter), step), counter)
        back = b.branch(head)
        if independent:
            self._mark_parallel([loop, *self.function.blocks[first_new:]], back)
        b.position_at_end(after)

    def _mark_parallel(self, blocks: list[ir.Block], back: ir.Instruction) -> None:
        """Every load and store of ``blocks`` (a loop's body) in one access group, and the
        loop's latch branch ``back`` naming that group parallel: LLVM's loop vectoriser and
        load elimination then skip their dependence checks, which compare each pair of the
        body's accesses. An access already in an inner loop's group stays in that one only
        (the outer loop is then analysed as any other: slower to compile, never wrong)."""
        module = self.module.ir_module
        group = _DistinctNode(module, [])
        for block in blocks:
            for instr in block.instructions:
                if isinstance(instr, (ir.LoadInstr, ir.StoreInstr)):
                    instr.metadata.setdefault("llvm.access.group", group)
        parallel = module.add_metadata(
            [ir.MetaDataString(module, "llvm.loop.parallel_accesses"), group]
        )
        back.set_metadata("llvm.loop", _DistinctNode(module, [parallel], self_reference=True))

    def _for(self, stmt: ast.For) -> None:
        call = stmt.iter
        if not (
            isinstance(call, ast.Call)
            and _name(call.func) == "range"
            and isinstance(stmt.target, ast.Name)
            and not stmt.orelse
        ):
            raise TranslationError(f"loop {ast.unparse(stmt.iter)}")
        args = [self._cast(*self._scalar(a), I64) for a in call.args]
        one = ir.Constant(_I64, 1)
        start, stop, step = (
            (ir.Constant(_I64, 0), args[0], one) if len(args) == 1 else (*args[:2], one)
        )
        positive = True
        if len(args) == 3:
            step = args[2]
            positive = self.module.constant_int(call.args[2]) > 0
        target = stmt.target.id
        independent = self.module.lines[stmt.lineno - 1].rstrip().endswith(INDEPENDENT_MARK)
        self._counted_loop(
            start, stop, step, lambda _i: self._statements(stmt.body), target, positive,
            independent,
        )  # fmt: skip

    def _while(self, stmt: ast.While) -> None:
        if stmt.orelse:
            raise TranslationError("while … else")
        b = self.builder
        head = self.function.append_basic_block()
        loop = self.function.append_basic_block()
        after = self.function.append_basic_block()
        b.branch(head)
        b.position_at_end(head)
        b.cbranch(self._condition(stmt.test), loop, after)
        b.position_at_end(loop)
        self.loops.append(_Loop(head, after))
        self._statements(stmt.body)
        self.loops.pop()
        if not b.block.is_terminated:
            b.branch(head)
        b.position_at_end(after)

    # -- expressions ----------------------------------------------------------------------

    def _expr(self, node: ast.expr) -> tuple[ir.Value, Type]:
        b = self.builder
        if isinstance(node, ast.Constant):
            v = node.value
            if isinstance(v, bool):
                return ir.Constant(_I1, int(v)), BOOL
            if isinstance(v, int):
                return ir.Constant(_I64, v), I64
            if isinstance(v, float):
                return ir.Constant(_DOUBLE, v), F64
            raise TranslationError(f"constant {v!r}")
        if isinstance(node, ast.Name):
            if node.id in self.vars:
                slot, ty = self.vars[node.id]
                return b.load(slot), ty
            if node.id in self.tuples:
                return self.tuples[node.id]
            if node.id in self.module.scalars:
                return self._expr(ast.Constant(self.module.scalars[node.id]))
            raise TranslationError(f"{self.fn.name}: {node.id} used before it is assigned")
        if isinstance(node, ast.Attribute):
            name = _name(node)
            if name in _CONSTANTS:
                return ir.Constant(_DOUBLE, _CONSTANTS[name]), F64
            raise TranslationError(f"attribute {name}")
        if isinstance(node, ast.BinOp):
            return self._binop(node.op, self._scalar(node.left), self._scalar(node.right))
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.Not):
                return b.not_(self._condition(node.operand)), BOOL
            value, ty = self._scalar(node.operand)
            if isinstance(node.op, ast.UAdd):
                return value, ty
            if isinstance(node.op, ast.USub):
                if ty == F64:  # as numba: -0.0 - x (a NaN keeps its sign bit)
                    return b.fsub(ir.Constant(_DOUBLE, -0.0), value), F64
                return b.neg(self._cast(value, ty, I64)), I64
            raise TranslationError(f"unary {ast.unparse(node)}")
        if isinstance(node, ast.Compare):
            result = None
            left = self._scalar(node.left)
            for op, right_node in zip(node.ops, node.comparators, strict=True):
                right = self._scalar(right_node)
                one = self._compare(op, left, right)
                result = one if result is None else b.and_(result, one)
                left = right
            return result, BOOL
        if isinstance(node, ast.BoolOp):
            return self._short_circuit(node, truth_only=False), BOOL
        if isinstance(node, ast.IfExp):
            return self._ifexp(node)
        if isinstance(node, ast.Tuple):
            items = [self._scalar(e) for e in node.elts]
            tup = Tuple(tuple(t for _, t in items))
            struct = ir.Constant(_llvm_type(tup), ir.Undefined)
            for k, (value, _t) in enumerate(items):
                struct = b.insert_value(struct, value, k)
            return struct, tup
        if isinstance(node, ast.Call):
            result = self._call(node)
            if result is None:
                raise TranslationError(f"{ast.unparse(node)} returns nothing")
            return result
        if isinstance(node, ast.Subscript):
            return self._subscript(node)
        raise TranslationError(f"expression {ast.unparse(node)}")

    def _condition(self, node: ast.expr) -> ir.Value:
        """The truth (i1) of a test: of ``if``, ``while``, ``… if … else …``, ``not``."""
        if isinstance(node, ast.BoolOp):
            return self._short_circuit(node, truth_only=True)
        return self._truth(*self._scalar(node))

    def _short_circuit(self, node: ast.BoolOp, truth_only: bool) -> ir.Value:
        """``a and b`` / ``a or b`` as Python and numba evaluate them: an operand only where
        the ones before do not decide (``i < n and t[i] > 0`` reads ``t[i]`` only if
        ``i < n``), with branches and a phi. As a value (``truth_only`` False) the operands
        must be bools: Python's ``x and y`` is then ``x`` or ``y``, any other type would be
        one of theirs (refused, never met in the generated text)."""
        b = self.builder
        decides = 0 if isinstance(node.op, ast.And) else 1  # the operand truth that ends it
        after = self.function.append_basic_block()
        incoming: list[tuple[ir.Value, ir.Block]] = []
        for k, operand in enumerate(node.values):
            if isinstance(operand, ast.BoolOp):
                truth = self._short_circuit(operand, truth_only)
            else:
                value, ty = self._scalar(operand)
                if not truth_only and ty != BOOL:
                    raise TranslationError(f"{ast.unparse(node)}: a value of non-bool operands")
                truth = self._truth(value, ty)
            if k == len(node.values) - 1:
                incoming.append((truth, b.block))
                b.branch(after)
                break
            incoming.append((ir.Constant(_I1, decides), b.block))
            rest = self.function.append_basic_block()
            b.cbranch(truth, after, rest) if decides else b.cbranch(truth, rest, after)
            b.position_at_end(rest)
        b.position_at_end(after)
        phi = b.phi(_I1)
        for value, block in incoming:
            phi.add_incoming(value, block)
        return phi

    def _scalar(self, node: ast.expr) -> tuple[ir.Value, str]:
        value, ty = self._expr(node)
        if not isinstance(ty, str):
            raise TranslationError(f"{ast.unparse(node)} is not a scalar")
        return value, ty

    def _ifexp(self, node: ast.IfExp) -> tuple[ir.Value, str]:
        """``a if c else b`` with branches (an array read in the branch not taken may be
        out of bounds); LLVM makes it a select where it can."""
        b = self.builder
        cond = self._condition(node.test)
        then = self.function.append_basic_block()
        orelse = self.function.append_basic_block()
        after = self.function.append_basic_block()
        b.cbranch(cond, then, orelse)
        b.position_at_end(then)
        v1, t1 = self._scalar(node.body)
        then_end = b.block
        b.position_at_end(orelse)
        v2, t2 = self._scalar(node.orelse)
        orelse_end = b.block
        ty = t1 if t1 == t2 else _unify(t1, t2)
        v2 = self._cast(v2, t2, ty)
        b.branch(after)
        b.position_at_end(then_end)
        v1 = self._cast(v1, t1, ty)
        b.branch(after)
        b.position_at_end(after)
        phi = b.phi(_VALUE_TYPE[ty])
        phi.add_incoming(v1, then_end)
        phi.add_incoming(v2, orelse_end)
        return phi, ty

    def _binop(
        self, op: ast.operator, left: tuple[ir.Value, str], right: tuple[ir.Value, str]
    ) -> tuple[ir.Value, str]:
        b = self.builder
        (lv, lt), (rv, rt) = left, right
        if isinstance(op, (ast.BitAnd, ast.BitOr, ast.BitXor)):
            if lt == BOOL and rt == BOOL:
                ty, lc, rc = BOOL, lv, rv
            else:
                ty, lc, rc = I64, self._cast(lv, lt, I64), self._cast(rv, rt, I64)
            fn = {ast.BitAnd: b.and_, ast.BitOr: b.or_, ast.BitXor: b.xor}[type(op)]
            return fn(lc, rc), ty
        ty = F64 if isinstance(op, ast.Div) else _unify(lt, rt)
        if isinstance(op, ast.Pow):
            if ty != F64:
                raise TranslationError("integer power")
            fn = self.module.intrinsic("llvm.pow", _DOUBLE, 2)
            return b.call(fn, [self._cast(lv, lt, F64), self._cast(rv, rt, F64)]), F64
        x, y = self._cast(lv, lt, ty), self._cast(rv, rt, ty)
        if ty == F64:
            fn = {ast.Add: b.fadd, ast.Sub: b.fsub, ast.Mult: b.fmul, ast.Div: b.fdiv}
            if type(op) not in fn:
                raise TranslationError(f"float operator {type(op).__name__}")
            return fn[type(op)](x, y), F64
        if isinstance(op, (ast.Add, ast.Sub, ast.Mult)):
            fn = {ast.Add: b.add, ast.Sub: b.sub, ast.Mult: b.mul}
            return fn[type(op)](x, y), I64
        if isinstance(op, (ast.FloorDiv, ast.Mod)):
            # Python's rounding toward -inf: fix C's truncation where the signs differ.
            q, r = b.sdiv(x, y), b.srem(x, y)
            zero = ir.Constant(_I64, 0)
            fix = b.and_(b.icmp_signed("!=", r, zero), b.icmp_signed("<", b.xor(r, y), zero))
            if isinstance(op, ast.FloorDiv):
                return b.sub(q, b.zext(fix, _I64)), I64
            return b.select(fix, b.add(r, y), r), I64
        raise TranslationError(f"operator {type(op).__name__}")

    def _compare(
        self, op: ast.cmpop, left: tuple[ir.Value, str], right: tuple[ir.Value, str]
    ) -> ir.Value:
        (lv, lt), (rv, rt) = left, right
        symbol = {
            ast.Lt: "<",
            ast.LtE: "<=",
            ast.Gt: ">",
            ast.GtE: ">=",
            ast.Eq: "==",
            ast.NotEq: "!=",
        }[type(op)]
        ty = _unify(lt, rt)
        x, y = self._cast(lv, lt, ty), self._cast(rv, rt, ty)
        if ty == F64:
            if symbol == "!=":
                return self.builder.fcmp_unordered("!=", x, y)
            return self.builder.fcmp_ordered(symbol, x, y)
        return self.builder.icmp_signed(symbol, x, y)

    def _call(self, node: ast.Call) -> tuple[ir.Value, str | Tuple] | None:
        """A call's value and type; None for a function that returns nothing."""
        b = self.builder
        name = _name(node.func)
        if name in ("max", "min"):
            acc = self._scalar(node.args[0])
            for arg in node.args[1:]:
                v = self._scalar(arg)
                ty = _unify(acc[1], v[1])
                a, x = self._cast(acc[0], acc[1], ty), self._cast(v[0], v[1], ty)
                take = self._compare(ast.Gt() if name == "max" else ast.Lt(), (x, ty), (a, ty))
                acc = (b.select(take, x, a), ty)
            return acc
        if name == "abs":
            value, ty = self._scalar(node.args[0])
            if ty == F64:
                return b.call(self.module.intrinsic("llvm.fabs", _DOUBLE, 1), [value]), F64
            value = self._cast(value, ty, I64)
            return b.select(
                b.icmp_signed("<", value, ir.Constant(_I64, 0)), b.neg(value), value
            ), I64
        if name == "math.sqrt":
            value = self._cast(*self._scalar(node.args[0]), F64)
            return b.call(self.module.intrinsic("llvm.sqrt", _DOUBLE, 1), [value]), F64
        if name in ("np.int64", "int"):
            return self._cast(*self._scalar(node.args[0]), I64), I64
        if name in ("np.float64", "float"):
            return self._cast(*self._scalar(node.args[0]), F64), F64
        if name in self.module.functions:
            values: list[ir.Value] = []
            types: list[Type] = []
            for arg in node.args:
                if isinstance(arg, ast.Name) and (
                    arg.id in self.arrays or arg.id in self.module.tables
                ):
                    arr = self._array(arg)
                    values += [arr.data, *arr.shape, *arr.strides]
                    types.append(arr.ty)
                else:
                    value, ty = self._scalar(arg)
                    values.append(value)
                    types.append(ty)
            callee, ret = self.module.specialize(name, tuple(types))
            for k in self.module.written.get((name, tuple(types)), ()):
                arg = node.args[k]
                if isinstance(arg, ast.Name):
                    self.written.add(arg.id)
            result = b.call(callee, values)
            return None if ret is None else (result, ret)
        raise TranslationError(f"call of {name}")

    def _subscript(self, node: ast.Subscript) -> tuple[ir.Value, Type]:
        base = node.value
        if isinstance(base, ast.Attribute) and base.attr == "shape":
            arr = self._array(base.value)
            return arr.shape[self.module.constant_int(node.slice)], I64
        if isinstance(base, ast.Name) and base.id in self.tuples:
            value, ty = self.tuples[base.id]
            k = self.module.constant_int(node.slice)
            return self.builder.extract_value(value, k), ty.items[k]
        arr = self._array(base)
        ptr = self._element_ptr(arr, [self._index(i) for i in _index_nodes(node.slice)])
        value = self.builder.load(ptr)
        if arr.ty.dtype == BOOL:
            value = self.builder.icmp_unsigned("!=", value, ir.Constant(_I8, 0))
        if arr.ty.dtype == F32:
            return self.builder.fpext(value, _DOUBLE), F64
        return value, arr.ty.dtype

    def _array(self, node: ast.expr) -> _ArrayValue:
        if isinstance(node, ast.Name):
            if node.id in self.arrays:
                return self.arrays[node.id]
            if node.id in self.module.tables:
                return self.module.table(node.id)
        raise TranslationError(f"{ast.unparse(node)} is not an array")

    def _index(self, node: ast.expr) -> ir.Value:
        value, ty = self._scalar(node)
        if ty not in (I64, U32, BOOL):
            raise TranslationError(f"index {ast.unparse(node)} is {ty}")
        return self._cast(value, ty, I64)

    def _element_ptr(self, arr: _ArrayValue, index: list[ir.Value]) -> ir.Value:
        b = self.builder
        if len(index) != arr.ty.ndim:
            raise TranslationError("an array indexed with fewer indices than dimensions")
        if arr.ty.contiguous:
            linear = index[0]
            for k in range(1, arr.ty.ndim):
                linear = b.add(b.mul(linear, arr.shape[k]), index[k])
            return b.gep(arr.data, [linear], inbounds=True)
        offset = b.mul(index[0], arr.strides[0])
        for k in range(1, arr.ty.ndim):
            offset = b.add(offset, b.mul(index[k], arr.strides[k]))
        raw = b.gep(b.bitcast(arr.data, _I8.as_pointer()), [offset], inbounds=True)
        return b.bitcast(raw, arr.data.type)

    # -- values ---------------------------------------------------------------------------

    def _truth(self, value: ir.Value, ty: Type) -> ir.Value:
        if ty == BOOL:
            return value
        if ty == F64:
            return self.builder.fcmp_unordered("!=", value, ir.Constant(_DOUBLE, 0.0))
        if ty in (I64, U32):
            return self.builder.icmp_signed("!=", value, ir.Constant(value.type, 0))
        raise TranslationError("truth of a non-scalar")

    def _cast(self, value: ir.Value, src: str, dst: str) -> ir.Value:
        """numba's conversion between scalar types."""
        b = self.builder
        if src == dst:
            return value
        if dst == BOOL:
            return self._truth(value, src)
        if dst == F64:
            if src == BOOL or src == U32:
                return b.uitofp(value, _DOUBLE)
            return b.sitofp(value, _DOUBLE)
        if src == F64:
            return b.fptosi(value, _VALUE_TYPE[dst])
        if dst == I64:
            return b.zext(value, _I64)  # from bool or uint32
        if dst == U32:
            return b.trunc(value, _I32) if src == I64 else b.zext(value, _I32)
        raise TranslationError(f"conversion {src} → {dst}")


def _llvm_type(ty: Type) -> ir.Type:
    if isinstance(ty, Tuple):
        return ir.LiteralStructType([_VALUE_TYPE[t] for t in ty.items])
    if isinstance(ty, Array):
        raise TranslationError("functions returning arrays are not supported")
    return _VALUE_TYPE[ty]


def _name(node: ast.expr) -> str:
    """``np.zeros`` for the node of ``np.zeros``; "" for anything but names and attributes."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return f"{_name(node.value)}.{node.attr}"
    return ""


def _index_nodes(node: ast.expr) -> list[ast.expr]:
    return list(node.elts) if isinstance(node, ast.Tuple) else [node]


def _as_load(target: ast.expr) -> ast.expr:
    """The target of ``x += …`` read as an expression."""
    node = ast.parse(ast.unparse(target), mode="eval").body
    return node


class _DistinctNode(ir.values.MDValue):
    """``distinct !{...}`` (llvmlite's ``add_metadata`` makes uniqued nodes only), with
    itself as first operand where ``self_reference`` (a loop ID)."""

    def __init__(self, module: ir.Module, operands: list[Any], self_reference: bool = False):
        super().__init__(module, operands, name=str(len(module.metadata)))
        self.self_reference = self_reference

    def descr(self, buf: list[str]) -> None:
        operands = [op.get_reference() for op in self.operands]
        if self.self_reference:
            operands.insert(0, self.get_reference())
        buf += ("distinct !{" + ", ".join(operands) + "}", "\n")

    def __eq__(self, other: object) -> bool:
        return self is other

    def __hash__(self) -> int:
        return id(self)


class ModuleTranslator:
    """The functions of one generated module as one LLVM IR module, each specialised on the
    argument types it is called with."""

    def __init__(self, source: str, symbol_prefix: str, target_data: Any) -> None:
        self.tree = ast.parse(source)
        self.lines = source.split("\n")
        self.prefix = symbol_prefix
        self.target_data = target_data
        self.ir_module = ir.Module(name=symbol_prefix)
        self.functions: dict[str, ast.FunctionDef] = {}
        self.scalars: dict[str, float | int | bool] = {}
        self.tables: dict[str, tuple[float, ...]] = {}
        self._tables: dict[str, _ArrayValue] = {}
        self._specialised: dict[tuple[str, tuple[Type, ...]], tuple[ir.Function, Returned]] = {}
        self._intrinsics: dict[str, ir.Function] = {}
        self.written: dict[tuple[str, tuple[Type, ...]], set[int]] = {}
        """By function and argument types: the array arguments it stores into."""
        for node in self.tree.body:
            if isinstance(node, ast.FunctionDef):
                self.functions[node.name] = node
            elif isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
                name = node.targets[0].id
                try:
                    value = ast.literal_eval(node.value)
                except ValueError:
                    continue  # JIT = dict(...)
                if isinstance(value, (tuple, list)):
                    self.tables[name] = tuple(float(v) for v in value)
                elif isinstance(value, (int, float, bool)):
                    self.scalars[name] = value

    def constant_int(self, node: ast.expr) -> int:
        """The value of an integer expression made of literals and module constants."""
        text = ast.unparse(node)
        try:
            value = eval(compile(ast.Expression(node), "<size>", "eval"), {}, dict(self.scalars))
        except Exception as exc:
            raise TranslationError(f"{text} is not a constant") from exc
        if not isinstance(value, int):
            raise TranslationError(f"{text} is not an integer constant")
        return value

    def libc(self, name: str) -> ir.Function:
        """C's ``aligned_alloc`` or ``free``, declared in the module (the JIT finds them in
        the process)."""
        fn = self._intrinsics.get(name)
        if fn is None:
            ptr = _I8.as_pointer()
            if name == "aligned_alloc":
                fn = ir.Function(self.ir_module, ir.FunctionType(ptr, [_I64, _I64]), name)
                fn.return_value.add_attribute("noalias")
            else:
                fn = ir.Function(self.ir_module, ir.FunctionType(ir.VoidType(), [ptr]), name)
            self._intrinsics[name] = fn
        return fn

    def intrinsic(self, name: str, ty: ir.Type, nargs: int) -> ir.Function:
        fn = self._intrinsics.get(name)
        if fn is None:
            fn = self.ir_module.declare_intrinsic(name, [ty], ir.FunctionType(ty, [ty] * nargs))
            self._intrinsics[name] = fn
        return fn

    def table(self, name: str) -> _ArrayValue:
        """A module constant tuple (a table law's knots or coefficients) as a constant
        array."""
        arr = self._tables.get(name)
        if arr is None:
            values = self.tables[name]
            aty = ir.ArrayType(_DOUBLE, len(values))
            glob = ir.GlobalVariable(self.ir_module, aty, f"{self.prefix}.{name}")
            glob.global_constant = True
            glob.linkage = "internal"
            glob.initializer = ir.Constant(aty, list(values))
            zero = ir.Constant(ir.IntType(32), 0)
            arr = _ArrayValue(
                Array(F64, 1, True),
                glob.gep([zero, zero]),
                [ir.Constant(_I64, len(values))],
                [ir.Constant(_I64, 8)],
            )
            self._tables[name] = arr
        return arr

    def specialize(self, name: str, argtypes: tuple[Type, ...]) -> tuple[ir.Function, Returned]:
        """The IR function of ``name`` for these argument types, translated on first use."""
        key = (name, argtypes)
        done = self._specialised.get(key)
        if done is not None:
            return done
        fn = self.functions[name]
        symbol = f"{self.prefix}.{name}.{len(self._specialised)}"
        ret: Returned = None
        widened: dict[str, str] = {}
        if any(isinstance(n, ast.Return) and n.value is not None for n in ast.walk(fn)):
            # Its return type, from a first translation into a scratch module.
            scratch = ModuleTranslator.__new__(ModuleTranslator)
            scratch.__dict__.update(self.__dict__)
            scratch.ir_module = ir.Module(name="scratch")
            scratch._specialised = dict(self._specialised)
            scratch._intrinsics = {}
            scratch._tables = {}
            probe = scratch.translate(fn, argtypes, symbol, None, widened)
            first = probe.returned[0]
            if isinstance(first, Array):
                raise TranslationError(f"{name} returns an array")
            ret = first
            for other in probe.returned[1:]:
                if other != ret:
                    if isinstance(ret, str) and isinstance(other, str):
                        ret = _unify(ret, other)
                    else:
                        raise TranslationError(f"{name} returns {ret} and {other}")
        translator = self.translate(fn, argtypes, symbol, ret, widened)
        params = [arg.arg for arg in fn.args.args]
        self.written[key] = {k for k, arg in enumerate(params) if arg in translator.written}
        return translator.function, ret

    def translate(
        self,
        fn: ast.FunctionDef,
        argtypes: tuple[Type, ...],
        symbol: str,
        ret: Returned,
        widened: dict[str, str],
    ) -> _FunctionTranslator:
        """The function ``fn`` translated into this module as ``symbol``; again with a
        variable widened to float64 each time one is found assigned an integer, then a
        float (:class:`_Widen`; ``widened`` collects them)."""
        key = (fn.name, argtypes)
        while True:
            translator = _FunctionTranslator(self, fn, argtypes, symbol, ret, widened)
            self._specialised[key] = (translator.function, ret)  # a recursive call finds it
            try:
                translator.translate()
            except _Widen as wider:
                widened[wider.name] = wider.ty
                del self.ir_module.globals[translator.function.name]
                symbol = f"{symbol}.w"  # the name stays registered in the module's scope
                continue
            return translator

    def entry(self, name: str, argtypes: tuple[Type, ...], symbol: str) -> None:
        """An external ``int32 <symbol>(...)`` called through ``ctypes``
        (:func:`ctypes_argument`): an array comes as its ``PyArrayObject *``, whose data,
        shape and strides it reads (:data:`ARRAY_FIELDS`); a float as a double, an integer
        or bool as an int64. It returns 0, or ``k + 1`` without running where argument
        ``k`` is a read-only array that the function writes (as numba refuses to)."""
        callee, ret = self.specialize(name, argtypes)
        if ret is not None:
            raise TranslationError(f"entry point {name} returns a value")
        params: list[ir.Type] = []
        for ty in argtypes:
            if isinstance(ty, Tuple):
                raise TranslationError(f"entry point {name} takes a tuple")
            params.append(_I8.as_pointer() if isinstance(ty, Array) else _ENTRY_TYPE[ty])
        fn = ir.Function(self.ir_module, ir.FunctionType(_I32, params), symbol)
        b = ir.IRBuilder(fn.append_basic_block())
        for k in sorted(self.written[(name, argtypes)]):
            flags = b.load(b.bitcast(
                b.gep(fn.args[k], [ir.Constant(_I64, ARRAY_FIELDS["flags"])], inbounds=True),
                _I32.as_pointer(),
            ))  # fmt: skip
            writeable = b.and_(flags, ir.Constant(_I32, NPY_ARRAY_WRITEABLE))
            read_only = b.icmp_unsigned("==", writeable, ir.Constant(_I32, 0))
            refuse, go_on = fn.append_basic_block(), fn.append_basic_block()
            b.cbranch(read_only, refuse, go_on)
            b.position_at_end(refuse)
            b.ret(ir.Constant(_I32, k + 1))
            b.position_at_end(go_on)

        def field(obj: ir.Value, offset: int, ty: ir.Type) -> ir.Value:
            at = b.gep(obj, [ir.Constant(_I64, offset)], inbounds=True)
            return b.load(b.bitcast(at, ty.as_pointer()))

        values: list[ir.Value] = []
        for ty, arg in zip(argtypes, fn.args, strict=True):
            if isinstance(ty, Array):
                data = field(arg, ARRAY_FIELDS["data"], _I8.as_pointer())
                values.append(b.bitcast(data, _MEMORY_TYPE[ty.dtype].as_pointer()))
                for what in ("shape", "strides"):
                    vector = field(arg, ARRAY_FIELDS[what], _I64.as_pointer())
                    for k in range(ty.ndim):
                        values.append(b.load(b.gep(vector, [ir.Constant(_I64, k)])))
            elif ty in (BOOL, U32):
                values.append(b.trunc(arg, _VALUE_TYPE[ty]))
            else:
                values.append(arg)
        b.call(callee, values)
        b.ret(ir.Constant(_I32, 0))


STACK_ARRAY_MAX_BYTES = 64 << 10
"""Largest local array (``np.zeros``/``np.full`` in the text) kept on the stack; larger ones
(the work array ``W`` of a long chain: 625 KiB for a 128-bar rk45 lane group) are allocated
on the heap at the function's entry and freed at its exit, since a thread's stack may hold
less (512 KiB on macOS, 128 KiB with musl). Small mechanisms' work arrays stay on the
stack."""

LOCAL_ARRAY_ALIGN = 64
"""Bytes a local array is aligned to (a cache line): the lane kernels' work rows are one SIMD
register each, and a row split between two lines costs two loads (numba aligns its arrays
to 32 bytes)."""

_ENTRY_TYPE = {F64: _DOUBLE, I64: _I64, U32: _I64, BOOL: _I64}
"""How an entry point receives a scalar (``ctypes``' double and int64)."""

ARRAY_FIELDS = {"data": 16, "nd": 24, "shape": 32, "strides": 40, "flags": 64}
"""Byte offsets in NumPy's ``PyArrayObject`` (its ABI, NumPy 1 and 2, CPython without free
threading) of the data pointer, the pointers to the shape and the strides (bytes), and the
flags (int32); checked against NumPy before the first call (:func:`array_layout_ok`)."""

NPY_ARRAY_WRITEABLE = 0x0400
"""The flag of a writeable array in ``PyArrayObject.flags`` (NumPy's C API)."""


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


_BACKEND_HASH = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]

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


def evict_oldest(folder: Path, max_bytes: int, keep: Path | None = None) -> list[Path]:
    """Remove the machine-code files of ``folder`` used least recently (modification time,
    touched at every load) until they hold at most ``max_bytes``; never ``keep`` (the file
    just written). Returns the files removed."""
    files = []
    for path in folder.glob("*.bin"):
        with contextlib.suppress(OSError):
            info = path.stat()
            files.append((info.st_mtime, info.st_size, path))
    total = sum(size for _, size, _ in files)
    removed = []
    for _, size, path in sorted(files):
        if total <= max_bytes:
            break
        if path == keep:
            continue
        with contextlib.suppress(OSError):
            path.unlink()
            removed.append(path)
            total -= size
    return removed


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
                library, address = self._load_or_compile(name, argtypes)
                proto = ctypes.CFUNCTYPE(ctypes.c_int32, *map(ctypes_argument, argtypes))
                entry = (proto(address), library)  # the library keeps the code alive
                self._entries[name][key] = entry
        return entry

    def _load_or_compile(self, name: str, argtypes: tuple[Type, ...]) -> tuple[Any, int]:
        """The compiled library of entry point ``name`` for ``argtypes``, from the disk
        cache or compiled now, and the address of its entry function."""
        codegen = _codegen()
        key = repr(
            (self._digest, name, argtypes, self.contract, codegen.magic_tuple(), *key_versions())
        )
        digest = hashlib.sha256(key.encode()).hexdigest()[:24]
        path = mcchain_cache("native") / f"{self.name}-{name}-{digest}.bin"
        symbol = f"{self.name}.{name}.{digest}"  # unique in the process's JIT engine
        library = None
        if path.exists():
            try:
                library = codegen.unserialize_library(pickle.loads(path.read_bytes()))
                with contextlib.suppress(OSError):
                    os.utime(path)  # recently used: the last to be evicted
                COUNTS["loaded"] += 1
            except Exception:
                library = None  # a stale or partial file: compile again
        if library is None:
            COUNTS["compiled"] += 1
            # Symbols unique in the process's JIT engine, which holds every library.
            translator = ModuleTranslator(self.source, symbol, _target_data(codegen))
            translator.entry(name, argtypes, symbol)
            if self.contract:
                _contract(translator.ir_module)
            library = codegen.create_library(f"{self.name}.{name}")
            library.enable_object_caching()
            library.add_ir_module(translator.ir_module)
            library.finalize()
            library.get_pointer_to_function(symbol)
            _write_atomically(path, pickle.dumps(library.serialize_using_object_code()))
            evict_oldest(path.parent, CACHE_MAX_BYTES, keep=path)
        address = library.get_pointer_to_function(symbol)
        if not address:
            raise RuntimeError(f"{symbol} missing from its compiled library")
        return library, address


def _target_data(codegen: Any) -> Any:
    from llvmlite import binding

    return binding.create_target_data(codegen._data_layout)


def _contract(module: ir.Module) -> None:
    """The fast-math flag ``contract`` on every float operation, as numba sets it for the
    lane kernels (``LANE_JIT``)."""
    from numba.core.cpu_options import FastMathOptions
    from numba.core.fastmathpass import rewrite_module

    rewrite_module(module, FastMathOptions({"contract"}))


def _write_atomically(path: Path, data: bytes) -> None:
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError:
        pass  # an unwritable cache: the next process compiles again
