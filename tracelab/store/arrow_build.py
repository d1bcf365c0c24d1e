"""Arrow arrays and tables built from numpy arrays and Python values straight from their buffers, for the
path that writes a run.

pyarrow's own converter (pa.array, pa.scalar, Table.from_pylist, Schema.empty_table, a compute call given
a Python value) imports pandas on its first call, to ask whether the values are pandas objects: ~30 MB
resident for good in a process that has none (`tracelab play --run`: docs/benchmarks/history.md, "Memory of long
runs"). These build the same arrays (value for value, nulls included) from buffers, which never asks.
Readers may use pyarrow's converter freely."""
from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

_EPOCH = _dt.datetime(1970, 1, 1)
_MICROSECOND = _dt.timedelta(microseconds=1)


def _bitmap(flags: np.ndarray) -> pa.Buffer:
    return pa.py_buffer(np.packbits(flags, bitorder="little"))


def from_numpy(values: np.ndarray, type: pa.DataType | None = None, null: np.ndarray | None = None) -> pa.Array:
    """A 1-D numpy array of numbers or booleans as an Arrow array (zero-copy when contiguous: the
    array must not change afterwards); `type` (default: the dtype's) must have the dtype's width;
    `null`: True where the value is NULL."""
    values = np.ascontiguousarray(values)
    if values.ndim != 1:
        raise ValueError(f"expected a 1-D array, got shape {values.shape}")
    if type is None:
        type = pa.from_numpy_dtype(values.dtype)
    elif pa.types.is_boolean(type) != (values.dtype == np.bool_) or (
            not pa.types.is_boolean(type) and type.bit_width != 8 * values.dtype.itemsize):
        raise TypeError(f"a {values.dtype} array cannot be stored as {type}")
    return _array(type, values, null)


def _array(type: pa.DataType, values: np.ndarray, null: np.ndarray | None) -> pa.Array:
    """from_numpy once `values` is contiguous and of `type`'s width."""
    data = _bitmap(values) if values.dtype == np.bool_ else pa.py_buffer(values)
    if null is None or not null.any():
        return pa.Array.from_buffers(type, len(values), [None, data], null_count=0)
    return pa.Array.from_buffers(type, len(values), [_bitmap(~null), data], null_count=int(null.sum()))


def bools_to_numpy(values: pa.BooleanArray) -> np.ndarray:
    """A boolean Arrow array without NULLs as a numpy array (Array.to_numpy goes through pandas' check)."""
    if values.null_count:
        raise ValueError("a boolean array with NULLs")
    bits = np.frombuffer(values.buffers()[1], dtype=np.uint8)
    return np.unpackbits(bits, bitorder="little", count=values.offset + len(values))[values.offset:].astype(np.bool_)


def strings(values: Sequence[str | None]) -> pa.StringArray:
    """Python strings (None: NULL) as an Arrow string array (TypeError for anything else)."""
    values = list(values)
    null = None
    if None in values:
        null = np.fromiter((v is None for v in values), dtype=np.bool_, count=len(values))
        values = ["" if v is None else v for v in values]
    text = "".join(values)  # TypeError unless every value is a str
    data = text.encode()
    if len(data) == len(text):  # all ASCII: a character is a byte
        lengths = np.fromiter(map(len, values), dtype=np.int64, count=len(values))
    else:
        lengths = np.fromiter((len(v.encode()) for v in values), dtype=np.int64, count=len(values))
    if len(data) >= 2**31:
        raise ValueError(f"string column too large for int32 offsets: {len(data)} bytes")
    offsets = np.zeros(len(values) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    if null is None:
        return pa.Array.from_buffers(pa.string(), len(values), [None, pa.py_buffer(offsets), pa.py_buffer(data)],
                                     null_count=0)
    return pa.Array.from_buffers(pa.string(), len(values), [_bitmap(~null), pa.py_buffer(offsets),
                                                            pa.py_buffer(data)], null_count=int(null.sum()))


def coded_strings(codes: np.ndarray, names: Sequence[str]) -> pa.StringArray:
    """names[codes] as an Arrow string array, its bytes gathered by numpy (a Python string per row costs
    more; Arrow's dictionary_decode loads pyarrow.compute, which a writing process does without)."""
    if len(names) == 1:  # a constant column (one agent, one output kind): its bytes repeated
        return _repeated_string(names[0].encode(), len(codes))
    encoded = [n.encode() for n in names]
    name_len = np.array([len(b) for b in encoded], dtype=np.int64)
    name_start = np.cumsum(name_len) - name_len
    lengths = name_len[codes]
    offsets = np.zeros(len(codes) + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    if offsets[-1] >= 2**31:
        raise ValueError(f"string column too large for int32 offsets: {offsets[-1]} bytes")
    pool = np.frombuffer(b"".join(encoded), dtype=np.uint8)
    at = np.repeat(name_start[codes] - offsets[:-1], lengths) + np.arange(offsets[-1])
    return pa.Array.from_buffers(pa.string(), len(codes), [None, pa.py_buffer(offsets.astype(np.int32)),
                                                           pa.py_buffer(pool[at].tobytes())], null_count=0)


def _repeated_string(value: bytes, n: int) -> pa.StringArray:
    """`value` n times as an Arrow string array."""
    if n * len(value) >= 2**31:
        raise ValueError(f"string column too large for int32 offsets: {n * len(value)} bytes")
    offsets = np.arange(n + 1, dtype=np.int32) * np.int32(len(value))
    return pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(offsets), pa.py_buffer(value * n)], null_count=0)


def scalar(value: str) -> pa.Scalar:
    """A string as an Arrow scalar (for a compute function's argument)."""
    return strings([value])[0]


def list_array(offsets: np.ndarray, values: pa.Array, null: np.ndarray | None = None) -> pa.ListArray:
    """A list array: row i holds values[offsets[i]:offsets[i + 1]]; `null`: True where the row is NULL
    (from buffers: ListArray.from_arrays's mask loads pyarrow.compute)."""
    if len(values) >= 2**31:
        raise ValueError(f"list column too large for int32 offsets: {len(values)} values")
    offsets = np.ascontiguousarray(offsets, dtype=np.int32)
    if null is None or not null.any():
        return pa.ListArray.from_arrays(from_numpy(offsets), values)
    return pa.Array.from_buffers(pa.list_(values.type), len(offsets) - 1, [_bitmap(~null), pa.py_buffer(offsets)],
                                 null_count=int(null.sum()), children=[values])


def column(values: Sequence[Any], type: pa.DataType) -> pa.Array:
    """Python values (None: NULL) as an Arrow array of `type`: integers, floats, booleans, strings,
    naive UTC datetimes as timestamp('us'), and lists of those."""
    if pa.types.is_string(type):
        return strings(values)
    null = np.fromiter((v is None for v in values), dtype=np.bool_, count=len(values)) if None in values else None
    if pa.types.is_list(type):
        if null is not None:
            raise ValueError("a NULL list is not supported here")
        offsets = np.zeros(len(values) + 1, dtype=np.int64)
        np.cumsum(np.fromiter(map(len, values), dtype=np.int64, count=len(values)), out=offsets[1:])
        return list_array(offsets, column([x for v in values for x in v], type.value_type))
    if pa.types.is_timestamp(type):
        if type.unit != "us" or type.tz is not None:
            raise TypeError(f"only naive timestamp('us') columns are supported, not {type}")
        micros = [0 if v is None else (v - _EPOCH) // _MICROSECOND for v in values]
        return _array(type, np.array(micros, dtype=np.int64), null)
    dtype = np.bool_ if pa.types.is_boolean(type) else type.to_pandas_dtype()
    filled = np.array(values if null is None else [0 if v is None else v for v in values], dtype=dtype)
    return _array(type, filled, null)


def table(columns: Mapping[str, pa.Array], schema: pa.Schema) -> pa.Table:
    """A table of `schema` from arrays by column name."""
    return pa.Table.from_arrays([columns[f.name] for f in schema], schema=schema)


def table_from_rows(rows: Sequence[Mapping[str, Any]], schema: pa.Schema) -> pa.Table:
    """Table.from_pylist(rows, schema): a missing key is NULL."""
    return table({f.name: column([r.get(f.name) for r in rows], f.type) for f in schema}, schema)


def empty_table(schema: pa.Schema) -> pa.Table:
    """schema.empty_table(): no rows (one empty chunk per column, as Parquet writers expect)."""
    return table({f.name: pa.nulls(0, f.type) for f in schema}, schema)
