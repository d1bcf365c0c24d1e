"""Checking a decoded file (a run's meta.json and parts manifest, a policy.json, a checkpoint's dict)
against the shape the code reads, at the boundary: a file from a stranger with a key missing, a value of
the wrong type or out of range fails with one line naming the file, the key and what was expected, not
with a KeyError or a TypeError deep inside the code that uses it. The one validator of the store and of
training: it imports nothing heavy (no numpy, DuckDB or torch), so the lightest command can use it.

A schema is
- a type: `str`, `int`, `float` (an int is a number too), `bool` (neither is taken for the other);
- a dict `{key: schema}`: an object holding those keys (more are allowed: a later version may add some);
  `OptionalKey(schema)` as a value makes its key optional;
- a `Spec`: `Const`, `OneOf`, `IntRange` (`INT64`), `IsoTime`, `Matches`, `Nullable`, `ListOf`, `MapOf`,
  `ExactKeys`, `Tuple`, or a subclass that checks something else (a tensor's type and shape:
  tracelab.train.torch_files.Tensor).

`check_file` checks a file's decoded contents and raises FileRefused `PATH: key 'a.b[2]': expected ...,
got ...` (the CLI prints it as one line).

The walk follows the schema, not the value, so a value nested deeper than its schema costs nothing."""
from __future__ import annotations

import datetime as _dt
import os
import re
from typing import Any

from tracelab.engine.safe_files import FileRefused

_TYPE_NAMES = {str: "a string", int: "an integer", float: "a number", bool: "true or false"}


class Mismatch(ValueError):
    """A value that does not match its schema; the message is `key 'a.b[2]': expected ..., got ...`
    (`expected ..., got ...` for the top level), or `key 'a.b': <problem>` when `problem` says it."""

    def __init__(self, where: str, expected: str = "", got: Any = None, *, missing: bool = False,
                 problem: str | None = None) -> None:
        self.where = where
        if problem is None:
            problem = f"expected {expected}, got {'nothing (the key is missing)' if missing else describe(got)}"
        super().__init__(f"key {where!r}: {problem}" if where else problem)


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


def _cut(text: str, width: int = 40) -> str:
    return text if len(text) <= width else text[: width - 3] + "..."


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


class OneOf(Spec):
    """One of a few values (of the same type: 1 is not True)."""

    def __init__(self, *values: Any) -> None:
        self.values = values
        self.expected = "one of " + ", ".join(repr(v) for v in values)

    def check(self, value: Any, where: str) -> None:
        if not any(type(value) is type(v) and value == v for v in self.values):
            raise Mismatch(where, self.expected, value)


class IntRange(Spec):
    """An integer (not a bool) from lo to hi; `expected` names the range in messages (`INT64`)."""

    def __init__(self, lo: int | None = None, hi: int | None = None, expected: str | None = None) -> None:
        self.lo, self.hi = lo, hi
        if expected is not None:
            self.expected = expected
        elif lo is not None and hi is not None:
            self.expected = f"an integer from {lo} to {hi}"
        elif lo is not None:
            self.expected = f"an integer >= {lo}"
        else:
            self.expected = "an integer" if hi is None else f"an integer <= {hi}"

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, int) or isinstance(value, bool) or \
                (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            raise Mismatch(where, self.expected, value)


INT64 = IntRange(-(1 << 63), (1 << 63) - 1, "a 64-bit integer")  # what a BIGINT column holds


def utc_time(text: str) -> _dt.datetime:
    """An ISO 8601 time as a naive UTC datetime (no offset: local time); ValueError or OverflowError if it
    is not one, or if its UTC time is outside the years 1-9999."""
    return _dt.datetime.fromisoformat(text).astimezone(_dt.UTC).replace(tzinfo=None)


class IsoTime(Spec):
    """A non-empty string in ISO 8601 (`2024-05-01T12:00:00.123456+00:00`) whose UTC time exists."""
    expected = "an ISO 8601 time"

    def check(self, value: Any, where: str) -> None:
        try:
            if not isinstance(value, str) or not value:
                raise ValueError
            utc_time(value)
        except (ValueError, OverflowError):
            raise Mismatch(where, self.expected, value) from None


class Matches(Spec):
    """A string matching `pattern` whole; `expected` says in words what that is."""

    def __init__(self, pattern: str | re.Pattern[str], expected: str) -> None:
        self.pattern = re.compile(pattern)
        self.expected = expected

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, str) or not self.pattern.fullmatch(value):
            raise Mismatch(where, self.expected, value)


class Nullable(Spec):
    def __init__(self, schema: Any) -> None:
        self.schema = schema
        self.expected = f"null or {expected_of(schema)}"

    def check(self, value: Any, where: str) -> None:
        if value is not None:
            check(value, self.schema, where)


class ListOf(Spec):
    """A list whose items match `item`; `unique`: no item listed twice (items hashable once checked)."""

    def __init__(self, item: Any, min_len: int = 0, unique: bool = False) -> None:
        self.item, self.min_len, self.unique = item, min_len, unique
        self.expected = "a list" if not min_len else f"a list of at least {min_len} item{'s' * (min_len > 1)}"

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, list) or len(value) < self.min_len:
            raise Mismatch(where, self.expected, value)
        seen: set[Any] = set()
        for i, item in enumerate(value):
            check(item, self.item, f"{where}[{i}]")
            if self.unique:
                if item in seen:
                    raise Mismatch(f"{where}[{i}]", problem=f"{item!r} is listed twice")
                seen.add(item)


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


class ExactKeys(Spec):
    """An object holding exactly the keys of the dict schema `fields` (a dict schema alone allows more)."""

    def __init__(self, fields: dict[str, Any]) -> None:
        self.fields = fields
        self.expected = "an object with exactly the keys " + ", ".join(fields)

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, dict):
            raise Mismatch(where, self.expected, value)
        extra = [k for k in value if k not in self.fields]
        if extra:
            raise Mismatch(where, problem=f"expected {self.expected}, got one with the key {_cut(str(extra[0]))!r}")
        check(value, self.fields, where)


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


def check_file(value: Any, schema: Any, path: str | os.PathLike[str]) -> Any:
    """`value` (the decoded contents of the file at `path`) if it matches `schema`; else FileRefused
    `PATH: key 'a.b': expected ..., got ...`."""
    try:
        check(value, schema)
    except Mismatch as e:
        raise FileRefused(f"{os.fspath(path)}: {e}") from None
    return value
