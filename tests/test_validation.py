"""tracelab.validation, the one validator of decoded files (meta.json, the parts manifest, policy.json,
checkpoints): the specs the store needs, its one-line messages, and that importing it stays light."""
from __future__ import annotations

import subprocess
import sys

import pytest

from tracelab.engine.safe_files import FileRefused
from tracelab.validation import INT64, ExactKeys, IsoTime, ListOf, Mismatch, OneOf, OptionalKey, check, check_file


@pytest.mark.parametrize(("value", "schema", "message"), [
    ("2024-05-01T12:00:00+00:00", IsoTime(), None),
    ("yesterday", IsoTime(), "expected an ISO 8601 time, got the string 'yesterday'"),
    ("", IsoTime(), "expected an ISO 8601 time"),
    ("0001-01-01T00:00:00+14:00", IsoTime(), "expected an ISO 8601 time"),  # before year 1 in UTC
    ("bogus", OneOf("running", "finished"), "expected one of 'running', 'finished', got the string 'bogus'"),
    (1, OneOf(True), "expected one of True, got the number 1"),
    (2 ** 63, INT64, "expected a 64-bit integer, got the number 9223372036854775808"),
    (True, INT64, "expected a 64-bit integer, got true"),
    (-(2 ** 63), INT64, None),
    (["a", "b", "a"], ListOf(str, unique=True), "key '[2]': 'a' is listed twice"),
    ({"a": 1, "zz": 2}, ExactKeys({"a": int}), "expected an object with exactly the keys a, got one with the key 'zz'"),
    ({}, ExactKeys({"a": int}), "key 'a': expected an integer, got nothing (the key is missing)"),
    ({"t": {"x": [1, "2"]}}, {"t": {"x": ListOf(int)}}, "key 't.x[1]': expected an integer, got the string '2'"),
    ({}, {"t": OptionalKey(int)}, None),
])
def test_specs_and_their_messages(value: object, schema: object, message: str | None) -> None:
    if message is None:
        check(value, schema)
    else:
        with pytest.raises(Mismatch) as e:
            check(value, schema)
        assert message in str(e.value), str(e.value)


def test_check_file_names_the_file_and_the_key_in_one_line() -> None:
    with pytest.raises(FileRefused) as e:
        check_file({"status": 5}, {"status": OneOf("running")}, "/runs/a/meta.json")
    assert str(e.value) == "/runs/a/meta.json: key 'status': expected one of 'running', got the number 5"
    assert check_file([], ListOf(int), "x.json") == []


def test_importing_the_validator_imports_nothing_heavy() -> None:
    """The store's lightest readers and training both import it: no numpy, pyarrow, DuckDB, torch, numba."""
    code = ("import sys, tracelab.validation; "
            "print(' '.join(m for m in ('numpy', 'pyarrow', 'duckdb', 'torch', 'numba') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == ""
