"""Straight-line lane text from the kernels' own numba functions: one definition of the physics.

A law of :mod:`mcchain.kernels` (say :func:`mcchain.kernels.contact.contact_law`) is the
only place its formulas are written. The loop kernels call it; the lane generator asks
:func:`inline` for its text, specialised to one joint: the function's syntax tree is read
from its module's source file (parsed, not imported: the generator never imports numba),
its parameters replaced by the lane's expressions, its locals renamed with the joint's
suffix, module constants written as literals, and calls of the module's other functions
(and of functions it imports from another kernel module) inlined in turn. The text is the
function's arithmetic operation for operation, so the lanes and the loop kernels round
alike.

The kernels' ``hypot(x, y)`` (libm's, robust to overflow) is written √(x² + y²) in the lanes,
which vectorises; the two differ by at most an ulp, as the lanes' own sine and cosine
(:func:`mcchain.codegen.sincos.sincos_code`) differ from libm's.

The functions it takes are the straight-line subset both targets share: a docstring,
assignments to plain names (one name or a tuple of names from an inlined call), and a
``return`` of one expression or a tuple; the only branching is a leading chain of
``if test: return value`` (a table of cases, written as nested selects), or ``x if c else y``
inside an expression. Anything else is refused with :class:`TypeError` at generation time.

Literal arguments specialise the text (:func:`_fold_binary`): a ground body's θ̇ = 0.0 or
(cos, sin) = (1.0, 0.0), a constant load's factor 1.0, a ``guarded`` flag. Operations on
literals only are evaluated, a case whose test is a literal keeps its one branch, and
x·1 → x, x·(−1) → −x, x/1 → x, x ± 0 → x, 0 − x → −x (exact), x·0 → 0, 0/x → 0 (for finite
x). The folded text gives the kernel's values for finite operands; only the sign of a zero
result may differ (−0.0 + 0.0 is +0.0 in the kernel, −0.0 folded), which no comparison sees.
"""

from __future__ import annotations

import ast
import functools
import importlib
import importlib.util
import math
from collections.abc import Sequence
from pathlib import Path

_BUILTINS = frozenset({"abs", "max", "min", "fma"})
"""Calls kept as written: the lane text's own functions (mcchain.codegen.native; ``fma`` is
:func:`mcchain.kernels.config.fma`, imported by the generated module's header)."""


@functools.cache
def _module(name: str) -> tuple[dict[str, ast.FunctionDef], dict[str, ast.expr], dict[str, str]]:
    """The top level of module ``name``'s source, parsed without importing it: its functions,
    its constant assignments and the module each ``from … import`` name comes from."""
    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        raise TypeError(f"{name}: no source")
    tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
    functions: dict[str, ast.FunctionDef] = {}
    constants: dict[str, ast.expr] = {}
    imported: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            functions[node.name] = node
        elif isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
            if isinstance(target, ast.Name):
                constants[target.id] = node.value
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                imported[alias.asname or alias.name] = node.module
    return functions, constants, imported


def _constant(module: str, name: str, where: str) -> float:
    """The value of module constant ``name``: a numeric assignment of the module (evaluated
    over its other constants) or a number imported from a module free of numba."""
    _functions, constants, imported = _module(module)
    if name in constants:
        node = constants[name]
        names = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}
        scope = {n: _constant(module, n, where) for n in names}
        value = eval(compile(ast.Expression(node), module, "eval"), {"__builtins__": {}}, scope)
    elif name in imported:
        value = getattr(importlib.import_module(imported[name]), name)
    else:
        raise TypeError(f"{where}: unknown name {name}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{where}: only numeric module constants can be inlined")
    return float(value)


class _Inliner:
    """Inlines one call: ``names`` maps each parameter and renamed local to its expression."""

    def __init__(
        self,
        module: str,
        function: str,
        suffix: str,
        out: list[str],
        owners: dict[str, _Inliner] | None = None,
    ) -> None:
        self.module = module
        functions, _constants, _imported = _module(module)
        if function not in functions:
            raise TypeError(f"{module}.{function}: no such function")
        self.tree = functions[function]
        self.suffix = suffix
        self.out = out
        self.names: dict[str, ast.expr] = {}
        # Which call wrote each local of the text: a callee's local named like one of its
        # caller's (both take the call's suffix) gets a name of its own instead of
        # overwriting the caller's value.
        self.owners: dict[str, _Inliner] = {} if owners is None else owners

    def where(self, node: ast.AST) -> str:
        return f"{self.module}.{self.tree.name} line {getattr(node, 'lineno', '?')}"

    def run(self, arguments: Sequence[str]) -> list[ast.expr]:
        params = [a.arg for a in self.tree.args.args]
        defaults = self.tree.args.defaults
        if len(arguments) > len(params) or len(arguments) < len(params) - len(defaults):
            raise TypeError(f"{self.where(self.tree)}: {len(arguments)} arguments")
        for name, text in zip(params, arguments, strict=False):
            self.names[name] = _fold_constant(ast.parse(text, mode="eval").body)  # "-1.0"
        for name, default in zip(params[::-1], defaults[::-1], strict=False):
            self.names.setdefault(name, self.expr(default))
        body = list(self.tree.body)
        if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
            body = body[1:]  # the docstring
        return self.block(body)

    def block(self, body: list[ast.stmt]) -> list[ast.expr]:
        for i, stmt in enumerate(body):
            if isinstance(stmt, ast.Return) and stmt.value is not None:
                if isinstance(stmt.value, ast.Tuple):
                    return [self.expr(e) for e in stmt.value.elts]
                if isinstance(stmt.value, ast.Call):  # a tail call passes all its values on
                    return self.call(stmt.value)
                return [self.expr(stmt.value)]
            if isinstance(stmt, ast.If) and self._is_case(stmt):
                # A table of cases: ``if c: return a`` … then the rest → a if c else (rest).
                test = self.expr(stmt.test)
                if isinstance(test, ast.Constant):  # decided by literal arguments: one case
                    return self.block((stmt.body if test.value else stmt.orelse) + body[i + 1 :])
                chosen = self.block(stmt.body)
                other = self.block(stmt.orelse + body[i + 1 :])
                if len(chosen) != len(other):
                    raise TypeError(f"{self.where(stmt)}: branches return different counts")
                return [
                    ast.IfExp(test=test, body=a, orelse=b)
                    for a, b in zip(chosen, other, strict=True)
                ]
            if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1:
                self.assign(stmt.targets[0], stmt.value)
                continue
            raise TypeError(f"{self.where(stmt)}: not straight-line code")
        raise TypeError(f"{self.where(self.tree)}: no return")

    def _is_case(self, stmt: ast.If) -> bool:
        def returns(body: list[ast.stmt]) -> bool:
            return len(body) == 1 and (
                isinstance(body[0], ast.Return)
                or (isinstance(body[0], ast.If) and self._is_case(body[0]))
            )

        return returns(stmt.body) and (not stmt.orelse or returns(stmt.orelse))

    def assign(self, target: ast.expr, value: ast.expr) -> None:
        if isinstance(target, ast.Name):
            results = [self.expr(value)]
            targets = [target.id]
        elif isinstance(target, ast.Tuple) and all(isinstance(e, ast.Name) for e in target.elts):
            if not isinstance(value, ast.Call):
                raise TypeError(f"{self.where(target)}: unpack only an inlined call")
            results = self.call(value)
            targets = [e.id for e in target.elts]  # type: ignore[attr-defined]
        else:
            raise TypeError(f"{self.where(target)}: assign plain names only")
        if len(results) != len(targets):
            raise TypeError(f"{self.where(target)}: {len(results)} values for {len(targets)}")
        for name, result in zip(targets, results, strict=True):
            if isinstance(result, (ast.Name, ast.Constant)):
                self.names[name] = result  # no new line for a plain name or literal
                continue
            local = self._local(f"{name}{self.suffix}")
            self.out.append(f"{local} = {ast.unparse(result)}")
            self.names[name] = ast.Name(local, ast.Load())

    def _local(self, wanted: str) -> str:
        """``wanted``, or ``wanted_2``, ``wanted_3``, … where another call of the text
        already wrote ``wanted`` (this call reassigning its own local keeps the name)."""
        local, k = wanted, 1
        while self.owners.setdefault(local, self) is not self:
            k += 1
            local = f"{wanted}_{k}"
        return local

    def call(self, node: ast.Call) -> list[ast.expr]:
        if node.keywords:
            raise TypeError(f"{self.where(node)}: keyword arguments")
        func = node.func
        if isinstance(func, ast.Name) and func.id in _BUILTINS:
            return [ast.Call(func, [self.expr(a) for a in node.args], [])]
        if isinstance(func, ast.Attribute) and ast.unparse(func) == "math.sqrt":
            return [ast.Call(func, [self.expr(a) for a in node.args], [])]
        if isinstance(func, ast.Name) and func.id == "hypot" and len(node.args) == 2:
            # libm's hypot → √(x² + y²), which vectorises in the lanes (≤ 1 ulp apart)
            x, y = (self.expr(a) for a in node.args)
            squares = ast.BinOp(ast.BinOp(x, ast.Mult(), x), ast.Add(), ast.BinOp(y, ast.Mult(), y))
            return [ast.Call(ast.parse("math.sqrt", mode="eval").body, [squares], [])]
        functions, _constants, imported = _module(self.module)
        module = self.module
        if isinstance(func, ast.Name) and func.id not in functions and func.id in imported:
            module = imported[func.id]  # a kernel imported from another kernel module
        if not isinstance(func, ast.Name) or func.id not in _module(module)[0]:
            raise TypeError(f"{self.where(node)}: cannot inline {ast.unparse(func)}")
        arguments = [ast.unparse(self.expr(a)) for a in node.args]
        return _Inliner(module, func.id, self.suffix, self.out, self.owners).run(arguments)

    def expr(self, node: ast.expr) -> ast.expr:
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            # a module constant (a law code, a friction speed) as a float literal: the lane
            # text holds every parameter, law codes included, as float64
            return ast.Constant(_constant(self.module, node.id, self.where(node)))
        if isinstance(node, ast.Constant):
            return ast.Constant(float(node.value)) if type(node.value) is int else node
        if isinstance(node, ast.Attribute):
            text = ast.unparse(node)
            if text in ("math.nan", "math.inf", "math.pi"):
                return node
            raise TypeError(f"{self.where(node)}: attribute {text}")
        if isinstance(node, ast.Call):
            results = self.call(node)
            if len(results) != 1:
                raise TypeError(f"{self.where(node)}: a call of several values in an expression")
            return results[0]
        if isinstance(node, ast.BinOp):
            return _fold_binary(self.expr(node.left), node.op, self.expr(node.right))
        if isinstance(node, ast.UnaryOp):
            operand = self.expr(node.operand)
            if isinstance(node.op, ast.USub):
                return _negate(operand)
            return _fold_constant(ast.UnaryOp(node.op, operand))
        if isinstance(node, ast.Compare):
            return _fold_constant(
                ast.Compare(
                    self.expr(node.left), node.ops, [self.expr(c) for c in node.comparators]
                )
            )
        if isinstance(node, ast.BoolOp):
            # an operand that cannot decide (False in an "or", True in an "and") drops out
            neutral = isinstance(node.op, ast.And)
            values = [self.expr(v) for v in node.values]
            kept = [v for v in values if not (isinstance(v, ast.Constant) and v.value is neutral)]
            if not all(_is_truth(v) for v in kept):  # a float operand is the result: kept
                kept = values
            if len(kept) <= 1:
                return kept[0] if kept else ast.Constant(neutral)
            return _fold_constant(ast.BoolOp(node.op, kept))
        if isinstance(node, ast.IfExp):
            test = self.expr(node.test)
            if isinstance(test, ast.Constant):  # a case fixed by the lane's structure
                return self.expr(node.body if test.value else node.orelse)
            return ast.IfExp(test, self.expr(node.body), self.expr(node.orelse))
        raise TypeError(f"{self.where(node)}: {type(node).__name__} is not lane text")


def _is_number(node: ast.expr, value: float) -> bool:
    return (
        isinstance(node, ast.Constant)
        and type(node.value) is float
        and node.value == value
        and math.copysign(1.0, node.value) == math.copysign(1.0, value)
    )


def _is_truth(node: ast.expr) -> bool:
    """A comparison or a logical operation: a bool, not a float."""
    return isinstance(node, (ast.Compare, ast.BoolOp)) or (
        isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not)
    )


def _negate(node: ast.expr) -> ast.expr:
    """−node, the sign moved onto the leftmost factor of a product or quotient (exact:
    (−a) b = −(a b) in IEEE arithmetic), so ``0.0 - a * b`` reads ``-a * b``."""
    if isinstance(node, ast.Constant) and type(node.value) is float:
        return ast.Constant(-node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return node.operand
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Mult, ast.Div)):
        return ast.BinOp(_negate(node.left), node.op, node.right)
    return ast.UnaryOp(ast.USub(), node)


def _fold_constant(node: ast.expr) -> ast.expr:
    """An operation on literals only, evaluated (IEEE double, as the kernels round it);
    anything else (or a division by zero) unchanged."""
    operation = (ast.BinOp, ast.UnaryOp, ast.Compare, ast.BoolOp)
    literal = (ast.Constant, ast.operator, ast.unaryop, ast.cmpop, ast.boolop, ast.expr_context)
    parts = ast.walk(node)
    if isinstance(node, operation) and all(isinstance(n, literal) or n is node for n in parts):
        try:
            tree = ast.fix_missing_locations(ast.Expression(node))
            value = eval(compile(tree, "<fold>", "eval"), {"__builtins__": {}})
        except ArithmeticError:
            return node
        return ast.Constant(float(value) if type(value) is int else value)
    return node


def _fold_binary(left: ast.expr, op: ast.operator, right: ast.expr) -> ast.expr:
    """left op right with the literal 0.0 and ±1.0 of a lane's structure folded away (a
    ground body's zero angular speed, a constant load's factor 1): x·1 → x, x·(−1) → −x,
    x/1 → x, x ± 0 → x and 0 − x → −x are exact; x·0 → 0 and 0/x → 0 hold for finite x.
    Folding may change the sign of a zero result (−0.0 + 0.0 is +0.0, −0.0 · 0.0 is −0.0),
    never a non-zero value: the lane's values equal the kernel's for finite operands,
    which compare equal either way."""
    node = _fold_constant(ast.BinOp(left, op, right))
    if isinstance(node, ast.Constant) or _is_truth(left) or _is_truth(right):
        return node  # (a truth value times 1.0 is how it becomes a float: kept)
    zero = ast.Constant(0.0)
    if isinstance(op, ast.Mult):
        if _is_number(left, 0.0) or _is_number(right, 0.0) or _is_number(left, -0.0) or \
                _is_number(right, -0.0):  # fmt: skip
            return zero
        for one, other in ((left, right), (right, left)):
            if _is_number(one, 1.0):
                return other
            if _is_number(one, -1.0):
                return _negate(other)
    elif isinstance(op, ast.Div):
        if _is_number(right, 1.0):
            return left
        if _is_number(left, 0.0):
            return zero
    elif isinstance(op, ast.Add):
        if _is_number(right, 0.0) or _is_number(right, -0.0):
            return left
        if _is_number(left, 0.0) or _is_number(left, -0.0):
            return right
    elif isinstance(op, ast.Sub):
        if _is_number(right, 0.0) or _is_number(right, -0.0):
            return left
        if _is_number(left, 0.0) or _is_number(left, -0.0):
            return _negate(right)
    return node


def inline(
    module: str, function: str, arguments: Sequence[str], suffix: str
) -> tuple[list[str], list[str]]:
    """Lane text of the call ``module.function(*arguments)``.

    Args:
        module: the kernel module's dotted name (its source is parsed, not imported).
        function: a function of that module, of the subset the module docstring names.
        arguments: the lane expression of each positional parameter (text); parameters
            left out take their default.
        suffix: appended to each local's name (e.g. the joint index), so the text of two
            joints does not collide.

    Returns:
        (statements, results): the lines to emit, in order, and the expression text of each
        returned value.
    """
    out: list[str] = []
    results = _Inliner(module, function, suffix, out).run(arguments)
    return out, [ast.unparse(r) for r in results]


__all__ = ["inline"]
