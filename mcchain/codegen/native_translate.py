"""Lowering of the generated text to LLVM IR, part two: the statements of one function
(:class:`FunctionTranslator`, over the expressions of
:class:`mcchain.codegen.native_expressions.FunctionLowering`) and the functions of one generated
module as one LLVM IR module (:class:`ModuleTranslator`). The machine code and its cache are
in :mod:`mcchain.codegen.native`.
"""

from __future__ import annotations

import ast
from collections.abc import Callable
from typing import Any

from llvmlite import ir

from mcchain.codegen.native_expressions import (
    _DOUBLE,
    _ENTRY_TYPE,
    _I8,
    _I32,
    _I64,
    _MEMORY_TYPE,
    _NUMPY_DTYPES,
    _VALUE_TYPE,
    ARRAY_FIELDS,
    BOOL,
    F32,
    F64,
    I64,
    LOCAL_ARRAY_ALIGN,
    NPY_ARRAY_WRITEABLE,
    STACK_ARRAY_MAX_BYTES,
    U32,
    Array,
    FunctionLowering,
    Returned,
    TranslationError,
    Tuple,
    Type,
    _ArrayValue,
    _as_load,
    _index_nodes,
    _Loop,
    _name,
    _unify,
    _Widen,
)
from mcchain.codegen.schedule import INDEPENDENT_MARK, INTERLEAVE_CONSTANT


def _keeps_element(target: ast.Subscript, value: ast.IfExp) -> bool:
    """Whether ``target = value`` (``a[i] = x if c else y``) has ``a[i]`` itself as one of
    the arms (:meth:`FunctionTranslator._kept_select`)."""
    key = ast.unparse(target)
    return any(ast.unparse(arm) == key for arm in (value.body, value.orelse))


class FunctionTranslator(FunctionLowering):
    """One specialisation of one function of the module: its IR function."""

    module: ModuleTranslator

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
            indices = _index_nodes(target.slice)
            if (
                isinstance(value_node, ast.IfExp)
                and _keeps_element(target, value_node)
                and not any(isinstance(i, ast.Slice) for i in indices)
            ):
                ptr = self._element_ptr(arr, [self._index(i) for i in indices])
                value, ty = self._kept_select(target, value_node, ptr, arr)
                self._store_element(ptr, value, ty, arr.ty.dtype)
                return
            value, ty = self._scalar(value_node)
            if any(isinstance(i, ast.Slice) for i in indices):
                self._fill_slice(arr, indices, value, ty)
                return
            ptr = self._element_ptr(arr, [self._index(i) for i in indices])
            self._store_element(ptr, value, ty, arr.ty.dtype)
        else:
            raise TranslationError(f"assignment to {ast.unparse(target)}")

    def _kept_select(
        self, target: ast.Subscript, node: ast.IfExp, ptr: ir.Value, arr: _ArrayValue
    ) -> tuple[ir.Value, Type]:
        """``a[i] = x if c else a[i]`` (:func:`_keeps_element`): the element read once,
        without a branch (it is stored just after, so reading it is safe), then the
        conditional expression with that value for the element (a select where its arms
        allow: :meth:`_speculatable`).

        The read goes through the address plus an offset LLVM cannot see to be zero: the
        same address would let LLVM 22's instruction selection fold the vector select and
        store into a masked store (``vmaskmovpd``), microcoded on AMD Zen 1-3 (an LLVM
        fault, llvm/llvm-project#213195, fixed after LLVM 22; what it cost the lanes'
        per-step tracking: benchmarks/results/roofline/reading.md, ninth stop)."""
        zero = self.opaque_zero
        if zero is None:
            zero = self.alloca_builder.asm(
                ir.FunctionType(_I64, [_I64]), "", "=r,0", [ir.Constant(_I64, 0)],
                side_effect=False,
            )  # fmt: skip
            self.opaque_zero = zero
        old = self._load_element(self.builder.gep(ptr, [zero], inbounds=True), arr)
        self.kept = (ast.unparse(target), *old)
        try:
            return self._ifexp(node)
        finally:
            self.kept = None

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
        self.local_arrays.add(name)
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
        self.lane_depth += independent
        body(i)
        self.lane_depth -= independent
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
        hints = [parallel]
        interleave = self.module.scalars.get(INTERLEAVE_CONSTANT, 1)
        if isinstance(interleave, int) and interleave > 1:
            # Lane loops over several SIMD registers of lanes: their vector bodies run
            # interleaved (independent instructions of two registers side by side: a lane
            # group's stage is a long dependent chain, and one register of lanes waited on
            # its latency).
            count = ir.Constant(ir.IntType(32), interleave)
            key = ir.MetaDataString(module, "llvm.loop.interleave.count")
            hints.append(module.add_metadata([key, count]))
        back.set_metadata("llvm.loop", _DistinctNode(module, hints, self_reference=True))

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

    def prefetch(self) -> ir.Function:
        """``llvm.prefetch`` (address, read 0 / write 1, locality 0-3, data cache 1)."""
        fn = self._intrinsics.get("llvm.prefetch")
        if fn is None:
            i8p, i32 = ir.IntType(8).as_pointer(), ir.IntType(32)
            fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
            fn = self.ir_module.declare_intrinsic("llvm.prefetch", [i8p], fnty)
            self._intrinsics["llvm.prefetch"] = fn
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
    ) -> FunctionTranslator:
        """The function ``fn`` translated into this module as ``symbol``; again with a
        variable widened to float64 each time one is found assigned an integer, then a
        float (:class:`_Widen`; ``widened`` collects them)."""
        key = (fn.name, argtypes)
        while True:
            translator = FunctionTranslator(self, fn, argtypes, symbol, ret, widened)
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
