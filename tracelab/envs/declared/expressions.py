"""Expressions in an environment spec: a value written as a string over the spec's params
(`"(1 - success_rate) / 2"`, `"desc if desc else maps[map_name]"`).

A spec comes from a stranger, so an expression is never run: it is parsed by Python's parser into a syntax
tree (parsing runs no code) and this module walks the few node kinds it allows, computing the value
itself. Anything else (calls, attributes, lambdas, comprehensions, ...) is an ExpressionError naming the
construct. The text is bounded in length, so the tree and the values it can build are small."""
from __future__ import annotations

import ast
import operator
from collections.abc import Mapping
from typing import Any

MAX_EXPRESSION_CHARS = 2000
MAX_VALUE_ITEMS = 100_000  # the longest list or string a `*` may build

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod}
_COMPARE = {ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
            ast.Gt: operator.gt, ast.GtE: operator.ge, ast.In: lambda a, b: a in b,
            ast.NotIn: lambda a, b: a not in b, ast.Is: operator.is_, ast.IsNot: operator.is_not}
_FUNCTIONS = {"len": len, "min": min, "max": max, "abs": abs, "float": float, "int": int}


class ExpressionError(ValueError):
    """An expression that is not allowed or cannot be computed; the message is one line."""


def evaluate(text: str, names: Mapping[str, Any]) -> Any:
    """The value of `text` with `names` (the params, and tables such as `maps`) in scope."""
    if len(text) > MAX_EXPRESSION_CHARS:
        raise ExpressionError(f"expression longer than {MAX_EXPRESSION_CHARS} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as e:
        raise ExpressionError(f"not an expression ({e.msg}, column {e.offset}): {text!r}") from None
    except (RecursionError, MemoryError, ValueError):
        raise ExpressionError(f"expression nested too deeply: {text[:60]!r}") from None
    try:
        return _Evaluator(names).value(tree.body)
    except RecursionError:
        raise ExpressionError(f"expression nested too deeply: {text[:60]!r}") from None
    except ExpressionError:
        raise
    except (TypeError, ValueError, KeyError, IndexError, ZeroDivisionError, OverflowError) as e:
        raise ExpressionError(f"{text!r} cannot be computed: {type(e).__name__}: {e}") from None


class _Evaluator:
    def __init__(self, names: Mapping[str, Any]) -> None:
        self.names = names

    def value(self, node: ast.AST) -> Any:
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool, type(None))):
            return node.value
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id in ("true", "false"):  # TOML spelling
                return node.id == "true"
            raise ExpressionError(f"unknown name {node.id!r} (known: {', '.join(sorted(self.names)) or 'none'})")
        if isinstance(node, (ast.List, ast.Tuple)):
            return [self.value(e) for e in node.elts]
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            left, right = self.value(node.left), self.value(node.right)
            sequences = isinstance(left, (list, str)) or isinstance(right, (list, str))
            size = _size(left) * _size(right) if isinstance(node.op, ast.Mult) else _size(left) + _size(right)
            if sequences and size > MAX_VALUE_ITEMS:
                raise ExpressionError(f"a list or string of more than {MAX_VALUE_ITEMS} items")
            return _BINARY[type(node.op)](left, right)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd, ast.Not)):
            v = self.value(node.operand)
            return -v if isinstance(node.op, ast.USub) else (+v if isinstance(node.op, ast.UAdd) else not v)
        if isinstance(node, ast.BoolOp):
            result = None
            for e in node.values:  # short-circuit, as Python's and/or
                result = self.value(e)
                if bool(result) == isinstance(node.op, ast.Or):
                    return result
            return result
        if isinstance(node, ast.IfExp):
            return self.value(node.body) if self.value(node.test) else self.value(node.orelse)
        if isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
            left = self.value(node.left)
            for op, comp in zip(node.ops, node.comparators):
                right = self.value(comp)
                if not _COMPARE[type(op)](left, right):
                    return False
                left = right
            return True
        if isinstance(node, ast.Subscript) and not isinstance(node.slice, ast.Slice):
            return self.value(node.value)[self.value(node.slice)]
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS \
                and not node.keywords:
            return _FUNCTIONS[node.func.id](*(self.value(a) for a in node.args))
        raise ExpressionError(f"{type(node).__name__} is not allowed in a spec expression "
                              "(numbers, names, lists, + - * / // %, comparisons, and/or/not, "
                              "x if c else y, x[i], len/min/max/abs/float/int)")


def _size(v: Any) -> int:
    """How many items a sequence operand stands for (an int: the repeat count of `[x] * n`)."""
    if isinstance(v, (list, str)):
        return len(v)
    return abs(v) if isinstance(v, int) and not isinstance(v, bool) else 1
