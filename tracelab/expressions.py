"""Expressions in an environment spec: a value written as a string over the spec's params
(`"(1 - success_rate) / 2"`, `"desc if desc else maps[map_name]"`).

A spec comes from a stranger, so an expression is never run: it is parsed by Python's parser into a syntax
tree (parsing runs no code) and this module walks the few node kinds it allows, computing the value
itself. Anything else (calls, attributes, lambdas, comprehensions, ...) is an ExpressionError naming the
construct.

Its cost is bounded before it is paid. Every value has a size (`_Sizes`: a string's characters, a list's
items counted through every nesting, shared or not), and an operation that builds a value (`*`, `+`, `%`
formatting, a list) computes the size of the result from its operands and refuses past MAX_VALUE_ITEMS
before building it; a printf-style width or precision past MAX_FORMAT_WIDTH is refused. Each operation
also spends steps from a budget (one a node, one an item it builds, compares or reads): with no loops in
the language that bounds the time (comparing two big nested lists is paid in items, not refused after)."""
from __future__ import annotations

import ast
import operator
import re
from collections.abc import Mapping
from typing import Any

MAX_EXPRESSION_CHARS = 2000
MAX_VALUE_ITEMS = 100_000  # the largest value an expression may build: characters, or items through nesting
MAX_EXPRESSION_STEPS = 1_000_000  # nodes computed plus items built, compared or read: well under a second
MAX_FORMAT_WIDTH = 100  # a printf-style width or precision (`'%5.2f'`)
MAX_INT_BITS = 4096  # a whole number made by `*` or int(): far past any count a spec needs

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod}
_COMPARE = {ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt, ast.LtE: operator.le,
            ast.Gt: operator.gt, ast.GtE: operator.ge, ast.In: lambda a, b: a in b,
            ast.NotIn: lambda a, b: a not in b, ast.Is: operator.is_, ast.IsNot: operator.is_not}
_FUNCTIONS = {"len": len, "min": min, "max": max, "abs": abs, "float": float, "int": int}
_RANGE = "range"  # range(stop) / range(start, stop[, step]): a list of whole numbers, its size checked first
_SCALARS = (int, float, str, bool, type(None))
# a printf conversion as str % reads it: %[(key)][flags][width][.precision][length]type
_CONVERSION = re.compile(r"%(?:\((?P<key>[^()]*)\))?[-#0 +]*(?P<width>\*|\d+)?(?:\.(?P<precision>\*|\d*))?"
                         r"[hlL]?(?P<type>.?)", re.DOTALL)
_NUMBER_CHARS = 330  # the longest plain text of a float (`'%f' % 1e308`: 309 digits and the decimals)


class ExpressionError(ValueError):
    """An expression that is not allowed or cannot be computed; the message is one line."""


def evaluate(text: str, names: Mapping[str, Any], *, max_steps: int = MAX_EXPRESSION_STEPS) -> Any:
    """The value of `text` with `names` (the params, and tables such as `maps`) in scope, computed in at
    most `max_steps` steps."""
    return Evaluation(names, max_steps).run(text)


class Evaluation:
    """One expression's computation: its names, the steps it has spent, the sizes of the values it saw."""

    def __init__(self, names: Mapping[str, Any], max_steps: int = MAX_EXPRESSION_STEPS) -> None:
        self.names = names
        self.max_steps = max_steps
        self.steps = 0
        self.sizes = _Sizes()

    def run(self, text: str) -> Any:
        if len(text) > MAX_EXPRESSION_CHARS:
            raise ExpressionError(f"expression longer than {MAX_EXPRESSION_CHARS} characters")
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except SyntaxError as e:
            raise ExpressionError(f"not an expression ({e.msg}, column {e.offset}): {text!r}") from None
        except (RecursionError, MemoryError, ValueError):
            raise ExpressionError(f"expression nested too deeply: {text[:60]!r}") from None
        try:
            return self.value(tree.body)
        except RecursionError:
            raise ExpressionError(f"expression nested too deeply: {text[:60]!r}") from None
        except ExpressionError:
            raise
        except (TypeError, ValueError, KeyError, IndexError, ZeroDivisionError, OverflowError) as e:
            raise ExpressionError(f"{text[:60]!r} cannot be computed: {type(e).__name__}: {e}") from None

    def spend(self, steps: int) -> None:
        self.steps += steps
        if self.steps > self.max_steps:
            raise ExpressionError(f"expression takes more than {self.max_steps:,} steps (items built, compared "
                                  "or read)")

    def value(self, node: ast.AST) -> Any:
        self.spend(1)
        if isinstance(node, ast.Constant) and isinstance(node.value, _SCALARS):
            return node.value
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id in ("true", "false"):  # TOML spelling
                return node.id == "true"
            raise ExpressionError(f"unknown name {node.id!r} (known: {', '.join(sorted(self.names)) or 'none'})")
        if isinstance(node, (ast.List, ast.Tuple)):
            items = [self.value(e) for e in node.elts]
            size = 1 + sum(self.sizes.of(v) for v in items)
            self.reserve(size)
            return self.sizes.remember(items, size)
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return self.binary(node.op, self.value(node.left), self.value(node.right))
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
                if not isinstance(op, (ast.Is, ast.IsNot)):  # == < in walk both values, item by item
                    self.spend(self.sizes.of(left) + self.sizes.of(right))
                if not _COMPARE[type(op)](left, right):
                    return False
                left = right
            return True
        if isinstance(node, ast.Subscript) and not isinstance(node.slice, ast.Slice):
            container, key = self.value(node.value), self.value(node.slice)
            self.spend(self.sizes.of(key))  # a table's key is hashed and compared
            return container[key]
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS \
                and not node.keywords:
            args = [self.value(a) for a in node.args]
            self.spend(sum(self.sizes.of(a) for a in args))  # min and max compare items, int reads digits
            result = _FUNCTIONS[node.func.id](*args)
            if _is_int(result) and result.bit_length() > MAX_INT_BITS:
                raise ExpressionError(f"a number of more than {MAX_INT_BITS} bits")
            return result
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == _RANGE \
                and not node.keywords and 1 <= len(node.args) <= 3:
            return self.range([self.value(a) for a in node.args])
        raise ExpressionError(f"{type(node).__name__} is not allowed in a spec expression "
                              "(numbers, names, lists, + - * / // %, comparisons, and/or/not, "
                              "x if c else y, x[i], len/min/max/abs/float/int/range)")

    def range(self, args: list[Any]) -> list[int]:
        """Python's range as a list, refused past MAX_VALUE_ITEMS before it is built."""
        if not all(_is_int(a) for a in args):
            raise ExpressionError(f"range takes whole numbers, got {', '.join(repr(a)[:20] for a in args)}")
        numbers = range(*args)  # lazy: its length is known before any item is made
        self.reserve(1 + len(numbers))
        return self.sizes.remember(list(numbers), 1 + len(numbers))

    def binary(self, op: ast.operator, left: Any, right: Any) -> Any:
        """`left op right`, the size of a string, list or number it builds checked before it is built."""
        compute = _BINARY[type(op)]
        if isinstance(op, ast.Mod) and isinstance(left, str):
            size = _formatted_size(left, right, self.sizes)
        elif isinstance(op, ast.Add) and (isinstance(left, (list, str)) or isinstance(right, (list, str))):
            size = self.sizes.of(left) + self.sizes.of(right)
        elif isinstance(op, ast.Mult) and (repeat := _repeated(left, right)) is not None:
            seq, count = repeat
            size = len(seq) * count if isinstance(seq, str) else 1 + (self.sizes.of(seq) - 1) * count
            size = max(size, 1)
        else:
            if isinstance(op, ast.Mult) and _is_int(left) and _is_int(right) \
                    and left.bit_length() + right.bit_length() > MAX_INT_BITS:
                raise ExpressionError(f"a product of more than {MAX_INT_BITS} bits")
            return compute(left, right)  # a number, or Python's own TypeError
        self.reserve(size)
        return self.sizes.remember(compute(left, right), size)

    def reserve(self, size: int) -> None:
        """Steps for a value of `size` about to be built; refused past MAX_VALUE_ITEMS."""
        if size > MAX_VALUE_ITEMS:
            raise ExpressionError(f"would build a value of {size:,} items (characters, or list items through "
                                  f"every nesting); at most {MAX_VALUE_ITEMS:,}")
        self.spend(size)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _repeated(left: Any, right: Any) -> tuple[list[Any] | str, int] | None:
    """(seq, n) of `seq * n` or `n * seq` (a string or a list repeated), else None."""
    if isinstance(left, (list, str)) and _is_int(right):
        return left, right
    if isinstance(right, (list, str)) and _is_int(left):
        return right, left
    return None


class _Sizes:
    """A value's size: 1 for a number or None, a string's length (at least 1), a list's or table's 1
    plus its items' sizes, through every nesting. A list built by `*` holds one item many times: sizes
    are remembered by identity (with the value, so the identity is not reused) and a value is walked once."""

    def __init__(self) -> None:
        self._known: dict[int, tuple[Any, int]] = {}

    def remember(self, value: Any, size: int) -> Any:
        if isinstance(value, (list, dict)):
            self._known[id(value)] = (value, size)
        return value

    def of(self, value: Any) -> int:
        if isinstance(value, str):
            return max(len(value), 1)
        if not isinstance(value, (list, dict)):
            return 1
        known = self._known.get(id(value))
        if known is not None:
            return known[1]
        items = value if isinstance(value, list) else [*value.keys(), *value.values()]
        size = 1 + sum(self.of(v) for v in items)
        self.remember(value, size)
        return size


def _formatted_size(fmt: str, args: Any, sizes: _Sizes) -> int:
    """The most characters `fmt % args` makes, computed before it is made: each conversion's width and
    precision at most MAX_FORMAT_WIDTH, none taken from the arguments (`%*d`), and each argument a number
    or a string whose text is bounded by its size."""
    total = len(fmt)
    for m in _CONVERSION.finditer(fmt):
        if m.group(0) == "%%":
            continue
        if m.group("type") == "(":
            raise ExpressionError("a '%(key)' with parentheses in the key")
        width, precision = m.group("width") or "", m.group("precision") or ""
        if "*" in (width, precision):
            raise ExpressionError(f"'%*' takes a width from the arguments: write the width in the format "
                                  f"(at most {MAX_FORMAT_WIDTH})")
        for digits in (width, precision):
            if len(digits) > 3 or (digits and int(digits) > MAX_FORMAT_WIDTH):
                raise ExpressionError(f"a format width or precision of {digits[:12]}{'...' * (len(digits) > 12)}"
                                      f"; at most {MAX_FORMAT_WIDTH}")
        key = m.group("key")
        arg = args.get(key) if key is not None and isinstance(args, dict) else args
        if isinstance(arg, (list, dict)):
            raise ExpressionError("'%' formats numbers and strings, not lists or tables")
        text = sizes.of(arg) if isinstance(arg, str) else _NUMBER_CHARS
        if _is_int(arg):
            text += arg.bit_length() // 3  # its decimal digits (%d, %s) or octal ones (%o)
        if m.group("type") in ("r", "a") and isinstance(arg, str):
            text = 10 * text + 2  # repr escapes a character in up to 10 ('\U000e0000')
        total += text + int(width or 0) + int(precision or 0)
    if total > MAX_VALUE_ITEMS:
        raise ExpressionError(f"'%' would build a string of up to {total:,} characters; at most "
                              f"{MAX_VALUE_ITEMS:,}")
    return total
