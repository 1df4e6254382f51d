"""Lowering of the generated text to LLVM IR, part one: the types the text implies, and the
expressions of one function (:class:`FunctionLowering`; its statements and the module are in
:mod:`mcchain.codegen.native_translate`, the compiled entry points in
:mod:`mcchain.codegen.native`).

Semantics follow numba's: Python's integer floor division and modulo, ``max``/``min`` as
``select(b > a, b, a)``, bool and integer operands promoted to float64 or int64, an array
index without wrap-around (the generated text never indexes from the end).
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from llvmlite import ir

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


_SPECULATABLE_CALLS = frozenset({"max", "min", "abs", "float", "fma", "math.sqrt", "math.copysign"})
"""Calls without side effects or undefined values, which :meth:`FunctionLowering._speculatable`
admits in an operand evaluated where Python would skip it."""

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
flags (int32); checked against NumPy before the first call
(:func:`mcchain.codegen.native.array_layout_ok`)."""

NPY_ARRAY_WRITEABLE = 0x0400
"""The flag of a writeable array in ``PyArrayObject.flags`` (NumPy's C API)."""


class LoweringModule(Protocol):
    """What a :class:`FunctionLowering` asks of the module it lowers into
    (:class:`mcchain.codegen.native_translate.ModuleTranslator`, which imports this module:
    named by its members here, so that the two modules form no import circle)."""

    ir_module: ir.Module
    functions: dict[str, ast.FunctionDef]
    scalars: dict[str, float | int | bool]
    tables: dict[str, tuple[float, ...]]
    written: dict[tuple[str, tuple[Type, ...]], set[int]]

    def constant_int(self, node: ast.expr) -> int: ...

    def intrinsic(self, name: str, ty: ir.Type, nargs: int) -> ir.Function: ...

    def prefetch(self) -> ir.Function: ...

    def table(self, name: str) -> _ArrayValue: ...

    def specialize(self, name: str, argtypes: tuple[Type, ...]) -> tuple[ir.Function, Returned]: ...


class FunctionLowering:
    """One function of the text as an LLVM function: its arguments, variables and
    expressions (the statements: :class:`mcchain.codegen.native_translate.FunctionTranslator`)."""

    def __init__(
        self,
        module: LoweringModule,
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
        # a[i] = x if c else a[i]: the element's text and value, while its arms are read
        self.kept: tuple[str, ir.Value, Type] | None = None
        self.opaque_zero: ir.Value | None = None  # an i64 zero LLVM cannot see through
        self.local_arrays: set[str] = set()  # np.zeros / np.full of the function
        self.lane_depth = 0  # lane loops (INDEPENDENT_MARK) around the statement
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

    # -- expressions -----------------------------------------------------------------------

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

    def _speculatable(self, nodes: list[ast.expr]) -> bool:
        """Whether ``nodes`` may be evaluated where Python would skip them, giving the same
        values: inside a lane loop (whose reads of the function's own arrays are in bounds
        whatever the branch: :data:`mcchain.codegen.schedule.INDEPENDENT_MARK`), reading
        only those arrays, calling only functions without side effects and dividing
        integers by nonzero constants only. Evaluated so, a branch is a select: a lane loop
        with branches vectorises into masked loads and stores, microcoded on AMD Zen 1-3."""
        if not self.lane_depth:
            return False
        for node in (n for root in nodes for n in ast.walk(root)):
            if isinstance(node, ast.Subscript):
                if self.kept is not None and ast.unparse(node) == self.kept[0]:
                    continue  # read already (FunctionTranslator._kept_select)
                if not (isinstance(node.value, ast.Name) and node.value.id in self.local_arrays):
                    return False
            elif isinstance(node, ast.Call):
                if _name(node.func) not in _SPECULATABLE_CALLS:
                    return False
            elif isinstance(node, ast.BinOp) and isinstance(
                node.op, (ast.FloorDiv, ast.Mod, ast.LShift, ast.RShift)
            ):
                if not (isinstance(node.right, ast.Constant) and node.right.value):
                    return False
            elif isinstance(node, (ast.NamedExpr, ast.Lambda, ast.Await, ast.Yield)):
                return False
        return True

    def _short_circuit(self, node: ast.BoolOp, truth_only: bool) -> ir.Value:
        """``a and b`` / ``a or b`` as Python and numba evaluate them: an operand only where
        the ones before do not decide (``i < n and t[i] > 0`` reads ``t[i]`` only if
        ``i < n``), with branches and a phi; where the operands allow
        (:meth:`_speculatable`), all of them and no branch. As a value (``truth_only``
        False) the operands must be bools: Python's ``x and y`` is then ``x`` or ``y``, any
        other type would be one of theirs (refused, never met in the generated text)."""
        b = self.builder
        if self._speculatable(node.values[1:]):
            truths = [self._operand_truth(node, operand, truth_only) for operand in node.values]
            combine = b.and_ if isinstance(node.op, ast.And) else b.or_
            result = truths[0]
            for truth in truths[1:]:
                result = combine(result, truth)
            return result
        decides = 0 if isinstance(node.op, ast.And) else 1  # the operand truth that ends it
        after = self.function.append_basic_block()
        incoming: list[tuple[ir.Value, ir.Block]] = []
        for k, operand in enumerate(node.values):
            truth = self._operand_truth(node, operand, truth_only)
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

    def _operand_truth(self, node: ast.BoolOp, operand: ast.expr, truth_only: bool) -> ir.Value:
        """The truth (i1) of one operand of ``node``."""
        if isinstance(operand, ast.BoolOp):
            return self._short_circuit(operand, truth_only)
        value, ty = self._scalar(operand)
        if not truth_only and ty != BOOL:
            raise TranslationError(f"{ast.unparse(node)}: a value of non-bool operands")
        return self._truth(value, ty)

    def _scalar(self, node: ast.expr) -> tuple[ir.Value, str]:
        value, ty = self._expr(node)
        if not isinstance(ty, str):
            raise TranslationError(f"{ast.unparse(node)} is not a scalar")
        return value, ty

    def _ifexp(self, node: ast.IfExp) -> tuple[ir.Value, str]:
        """``a if c else b`` with branches (an array read in the branch not taken may be
        out of bounds); LLVM makes it a select where it can. Where the arms allow
        (:meth:`_speculatable`), both evaluated and a select."""
        b = self.builder
        if self._speculatable([node.body, node.orelse]):
            cond = self._condition(node.test)
            v1, t1 = self._scalar(node.body)
            v2, t2 = self._scalar(node.orelse)
            ty = t1 if t1 == t2 else _unify(t1, t2)
            return b.select(cond, self._cast(v1, t1, ty), self._cast(v2, t2, ty)), ty
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
        if name == "fma":  # mcchain.kernels.config.fma: rounded once
            operands = [self._cast(*self._scalar(arg), F64) for arg in node.args]
            return b.call(self.module.intrinsic("llvm.fma", _DOUBLE, 3), operands), F64
        if name == "prefetch":  # mcchain.kernels.config.prefetch: a hint, no value
            arr = self._array(node.args[0])
            index = [self._index(i) for i in node.args[1:]]
            index += [ir.Constant(_I64, 0)] * (arr.ty.ndim - len(index))
            # Not inbounds: the element may lie past the array (a prefetch never faults).
            ptr = b.bitcast(self._element_ptr(arr, index, inbounds=False), _I8.as_pointer())
            hint = [ir.Constant(_I32, k) for k in (1, 3, 1)]  # for a write, keep in all caches
            b.call(self.module.prefetch(), [ptr, *hint])
            return None
        if name == "take_next":  # mcchain.kernels.config.take_next: a queue's next item
            arr = self._array(node.args[0])
            if arr.ty.dtype != I64:
                raise TranslationError(f"{self.fn.name}: take_next's queue is an int64 array")
            one = ir.Constant(_I64, 1)  # each item to one taker; no other memory ordered by it
            return b.atomic_rmw("add", arr.data, one, "monotonic"), I64
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
        if self.kept is not None and ast.unparse(node) == self.kept[0]:
            return self.kept[1], self.kept[2]
        arr = self._array(base)
        ptr = self._element_ptr(arr, [self._index(i) for i in _index_nodes(node.slice)])
        return self._load_element(ptr, arr)

    def _load_element(self, ptr: ir.Value, arr: _ArrayValue) -> tuple[ir.Value, Type]:
        """The element at ``ptr`` of ``arr`` as a value of its scalar type."""
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

    def _element_ptr(
        self, arr: _ArrayValue, index: list[ir.Value], inbounds: bool = True
    ) -> ir.Value:
        b = self.builder
        if len(index) != arr.ty.ndim:
            raise TranslationError("an array indexed with fewer indices than dimensions")
        if arr.ty.contiguous:
            linear = index[0]
            for k in range(1, arr.ty.ndim):
                linear = b.add(b.mul(linear, arr.shape[k]), index[k])
            return b.gep(arr.data, [linear], inbounds=inbounds)
        offset = b.mul(index[0], arr.strides[0])
        for k in range(1, arr.ty.ndim):
            offset = b.add(offset, b.mul(index[k], arr.strides[k]))
        raw = b.gep(b.bitcast(arr.data, _I8.as_pointer()), [offset], inbounds=inbounds)
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
