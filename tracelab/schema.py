"""Checking a decoded file (a JSON document, a checkpoint's dict) against the shape the code reads, at the
boundary: a file from a stranger with a key missing, a value of the wrong type or out of range fails with
one line naming the key and what was expected, not with a KeyError or a TypeError deep inside the code
that uses it.

A schema is
- a type: `str`, `int`, `float` (an int is a number too), `bool` (neither is taken for the other);
- a dict `{key: schema}`: an object holding those keys (more are allowed: a later version may add some);
  `OptionalKey(schema)` as a value makes its key optional;
- a `Spec`: `Const`, `IntRange`, `Nullable`, `ListOf`, `MapOf`, `Tuple`, or a subclass that checks
  something else (a tensor's type and shape: tracelab.train.torch_files.Tensor).

The walk follows the schema, not the value, so a value nested deeper than its schema costs nothing."""
from __future__ import annotations

from typing import Any

_TYPE_NAMES = {str: "a string", int: "an integer", float: "a number", bool: "true or false"}


class Mismatch(ValueError):
    """A value that does not match its schema; the message is `key.path: expected ..., got ...`."""

    def __init__(self, where: str, expected: str, got: Any = None, *, missing: bool = False) -> None:
        self.where = where
        found = "nothing (the key is missing)" if missing else describe(got)
        super().__init__(f"{where or 'the top level'}: expected {expected}, got {found}")


def describe(value: Any) -> str:
    """A value as an error message shows it: its kind, and itself when it is short."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        text = repr(value)
        return f"the number {text if len(text) <= 24 else text[:21] + '...'}"
    if isinstance(value, str):
        return f"the string {value!r}" if len(value) <= 40 else f"a string of {len(value):,} characters"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value):,} items" if value else "an empty list"
    if isinstance(value, dict):
        return "an object"
    if hasattr(value, "shape") and hasattr(value, "dtype"):  # a numpy array or a torch tensor
        kind = "tensor" if type(value).__name__ == "Tensor" else "array"
        return f"{with_article(str(value.dtype).removeprefix('torch.'))} {kind} of shape {tuple(value.shape)}"
    return f"a {type(value).__name__}"


def with_article(word: str) -> str:
    return f"{'an' if word[:1] in 'aeio' else 'a'} {word}"  # 'a uint8': a u said 'you'


def _key(where: str, key: Any) -> str:
    return f"{where}.{key}" if where else str(key)


class Spec:
    """A schema that checks a value itself; `expected` says what it takes, for messages."""
    expected = "a value"

    def check(self, value: Any, where: str) -> None:
        raise NotImplementedError


class OptionalKey(Spec):
    """As a value of a dict schema: the key may be absent."""

    def __init__(self, schema: Any) -> None:
        self.schema = schema
        self.expected = expected_of(schema)

    def check(self, value: Any, where: str) -> None:
        check(value, self.schema, where)


class Const(Spec):
    def __init__(self, value: Any) -> None:
        self.value = value
        self.expected = repr(value)

    def check(self, value: Any, where: str) -> None:
        if type(value) is not type(self.value) or value != self.value:
            raise Mismatch(where, self.expected, value)


class IntRange(Spec):
    def __init__(self, lo: int | None = None, hi: int | None = None) -> None:
        self.lo, self.hi = lo, hi
        if lo is not None and hi is not None:
            self.expected = f"an integer from {lo} to {hi}"
        elif lo is not None:
            self.expected = f"an integer >= {lo}"
        else:
            self.expected = "an integer" if hi is None else f"an integer <= {hi}"

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, int) or isinstance(value, bool) or \
                (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            raise Mismatch(where, self.expected, value)


class Nullable(Spec):
    def __init__(self, schema: Any) -> None:
        self.schema = schema
        self.expected = f"null or {expected_of(schema)}"

    def check(self, value: Any, where: str) -> None:
        if value is not None:
            check(value, self.schema, where)


class ListOf(Spec):
    def __init__(self, item: Any, min_len: int = 0) -> None:
        self.item, self.min_len = item, min_len
        self.expected = "a list" if not min_len else f"a list of at least {min_len} item{'s' * (min_len > 1)}"

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, list) or len(value) < self.min_len:
            raise Mismatch(where, self.expected, value)
        for i, item in enumerate(value):
            check(item, self.item, f"{where}[{i}]")


class MapOf(Spec):
    """An object with any string keys, each value matching `value`."""

    def __init__(self, value: Any, min_len: int = 0) -> None:
        self.value, self.min_len = value, min_len
        self.expected = "an object" if not min_len else f"an object of at least {min_len} key{'s' * (min_len > 1)}"

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, dict) or len(value) < self.min_len:
            raise Mismatch(where, self.expected, value)
        for k, v in value.items():
            if not isinstance(k, str):
                raise Mismatch(where, "an object with string keys", k)
            check(v, self.value, _key(where, k))


class Tuple(Spec):
    """A fixed-length list (or tuple) whose items match `items` in order."""

    def __init__(self, *items: Any) -> None:
        self.items = items
        self.expected = f"a list of {len(items)} items ({', '.join(expected_of(s) for s in items)})"

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, (list, tuple)) or len(value) != len(self.items):
            raise Mismatch(where, self.expected, value)
        for i, (item, schema) in enumerate(zip(value, self.items)):
            check(item, schema, f"{where}[{i}]")


def expected_of(schema: Any) -> str:
    if isinstance(schema, Spec):
        return schema.expected
    if isinstance(schema, dict):
        return "an object"
    return _TYPE_NAMES[schema]


def check(value: Any, schema: Any, where: str = "") -> None:
    """Raise Mismatch at the first part of `value` that does not match `schema` (`where`: its key path)."""
    if isinstance(schema, Spec):
        schema.check(value, where)
    elif isinstance(schema, dict):
        if not isinstance(value, dict):
            raise Mismatch(where, "an object", value)
        for key, sub in schema.items():
            if key in value:
                check(value[key], sub, _key(where, key))
            elif not isinstance(sub, OptionalKey):
                raise Mismatch(_key(where, key), expected_of(sub), missing=True)
    elif schema is float:
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise Mismatch(where, _TYPE_NAMES[float], value)
    elif schema is int:
        IntRange().check(value, where)
    elif not isinstance(value, schema):
        raise Mismatch(where, _TYPE_NAMES[schema], value)
