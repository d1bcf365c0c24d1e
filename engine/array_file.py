"""Named numpy arrays in one plain file (a cache's), written by this module and read back as a file from a
stranger: no pickle, nothing read past the file's own bytes, every array's dtype and number of dimensions
the reader's, never the file's.

The file: MAGIC, the header's length (8 bytes, little-endian), the header (JSON: the caller's own fields
and, per array, its dtype, shape and offset), then the arrays' bytes. The whole file is read at once under
a size cap (safe_files.read_bytes), so a declared shape larger than the file is refused, not allocated.
"""
from __future__ import annotations

import json
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from .safe_files import FileRefused, read_bytes, replacing

MAGIC = b"TLARRAYS"
HEADER_CAP = 1 << 20  # a header names a few arrays and a few scalars


def write_arrays(path: str | os.PathLike[str], fields: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> int:
    """Write `arrays` (little-endian, C order) and the JSON-able `fields` to `path` (replaced as a whole:
    a reader never sees half a file). Returns the file's size."""
    described, blobs, offset = {}, [], 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a, a.dtype.newbyteorder("<"))
        described[name] = {"dtype": a.dtype.str, "shape": list(a.shape), "offset": offset}
        blobs.append(a.tobytes())
        offset += len(blobs[-1])
    header = json.dumps({"fields": dict(fields), "arrays": described}).encode()
    with replacing(path, mode=0o600) as f:
        f.write(MAGIC + len(header).to_bytes(8, "little") + header)
        for blob in blobs:
            f.write(blob)
    return len(MAGIC) + 8 + len(header) + offset


def read_arrays(path: str | os.PathLike[str], max_bytes: int, expected: Mapping[str, tuple[str, int]]
                ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(the fields, the arrays) of a file write_arrays wrote: exactly the arrays `expected` names, each of
    its dtype (numpy's str, '<i4') and number of dimensions, inside the file. FileRefused, naming the file
    and why, for anything else (larger than `max_bytes`, another format, an array missing, of another
    dtype or shape, past the file's end). The arrays are copies, writable and aligned."""
    data = read_bytes(path, max_bytes, what="cache file", follow_symlinks=False)
    if len(data) < len(MAGIC) + 8 or not data.startswith(MAGIC):
        raise FileRefused(f"{path}: not a tracelab array file")
    size = int.from_bytes(data[len(MAGIC):len(MAGIC) + 8], "little")
    start = len(MAGIC) + 8 + size
    if size > HEADER_CAP or start > len(data):
        raise FileRefused(f"{path}: its header's declared length ({size} bytes) does not fit the file")
    try:
        header = json.loads(data[len(MAGIC) + 8:start])
    except (ValueError, RecursionError):
        raise FileRefused(f"{path}: its header is not valid JSON") from None
    if not isinstance(header, dict) or not isinstance(header.get("fields"), dict) \
            or not isinstance(header.get("arrays"), dict):
        raise FileRefused(f"{path}: its header holds no fields and arrays")
    if set(header["arrays"]) != set(expected):
        raise FileRefused(f"{path}: holds the arrays {sorted(header['arrays'])}, expected {sorted(expected)}")
    body = len(data) - start
    arrays = {}
    for name, (dtype, ndim) in expected.items():
        d = header["arrays"][name]
        shape, offset = (d.get("shape"), d.get("offset")) if isinstance(d, dict) else (None, None)
        if not isinstance(d, dict) or d.get("dtype") != dtype:
            raise FileRefused(f"{path}: array {name!r} is not of dtype {dtype}")
        if not isinstance(shape, list) or len(shape) != ndim \
                or not all(type(n) is int and n >= 0 for n in shape) or type(offset) is not int or offset < 0:
            raise FileRefused(f"{path}: array {name!r} has no valid {ndim}-dimensional shape and offset")
        count = int(np.prod(shape, dtype=object))  # Python ints: a giant declared shape cannot overflow
        if offset + count * np.dtype(dtype).itemsize > body:
            raise FileRefused(f"{path}: array {name!r} (shape {shape}) reaches past the file's end")
        arrays[name] = np.frombuffer(data, dtype, count, start + offset).reshape(shape).copy()
    return header["fields"], arrays
