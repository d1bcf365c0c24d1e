"""Reading torch files (checkpoints, policy.pt) that may come from a stranger, and checking the tensors in
them.

`torch.save` writes a zip archive holding a pickle and one record per tensor. Unpickling runs whatever
callable the pickle names, so these files are loaded with `weights_only=True` only: torch's restricted
unpickler, which builds tensors, dicts, lists, tuples, strings and numbers and refuses any other global.
Before that, the file must be a regular file (a FIFO would hang the read, /dev/zero never end), at most
a size cap, and a zip archive whose records are stored uncompressed within the same cap (torch writes
them so; a compressed record could unpack to far more than the file's size)."""
from __future__ import annotations

import os
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any

import torch

from tracelab.engine.safe_files import FileRefused, human_bytes, open_regular
from tracelab.errors import one_line
from tracelab.validation import Mismatch, Spec, with_article

_GLOBAL = re.compile(r"GLOBAL ([\w.]+)")  # torch names the callable in several phrasings
_WEIGHTS_ERROR = re.compile(r"WeightsUnpickler error: ([^\n]+)")


class CodeInFile(FileRefused):
    """A torch file whose pickle names a callable outside torch's allowed set: loading it fully would run
    code. `pickled` holds the pickle's bytes (so a caller can tell an older format of its own)."""

    def __init__(self, message: str, pickled: bytes) -> None:
        super().__init__(message)
        self.pickled = pickled


def _pickle_of(archive: zipfile.ZipFile) -> bytes:
    names = [n for n in archive.namelist() if n.endswith("/data.pkl") or n == "data.pkl"]
    return archive.read(names[0]) if names else b""


def _check_archive(f: Any, path: Path, max_bytes: int) -> bytes:
    """Refuse what is not a torch zip archive of stored records within `max_bytes`; returns the pickle."""
    try:
        archive = zipfile.ZipFile(f)
    except (zipfile.BadZipFile, OSError, ValueError):
        raise FileRefused(f"{path}: not a file torch.save writes (no zip archive); refused") from None
    with archive:
        unpacked = 0
        for info in archive.infolist():
            if info.compress_type != zipfile.ZIP_STORED or info.compress_size != info.file_size:
                raise FileRefused(f"{path}: record {info.filename!r} is compressed (torch.save stores them "
                                  f"as they are); refused")
            unpacked += info.file_size
        if unpacked > max_bytes:
            raise FileRefused(f"{path}: holds {human_bytes(unpacked)}, over the {human_bytes(max_bytes)} "
                              f"limit; refused")
        return _pickle_of(archive)


def load_tensors(path: str | os.PathLike[str], max_bytes: int) -> Any:
    """What `torch.save` wrote to `path` (a file in a folder tracelab reads: no symbolic link), loaded
    with weights_only=True onto the CPU. FileRefused (one line) for anything else; CodeInFile for a pickle
    that names a callable torch does not allow."""
    path = Path(path)
    with open_regular(path, follow_symlinks=False) as f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            raise FileRefused(f"{path}: is empty; refused")
        if size > max_bytes:
            raise FileRefused(f"{path}: {human_bytes(size)}, over the {human_bytes(max_bytes)} limit; refused")
        pickled = _check_archive(f, path, max_bytes)
        f.seek(0)
        try:
            return torch.load(f, map_location="cpu", weights_only=True)
        except pickle.UnpicklingError as e:
            text = str(e)
            name = _GLOBAL.search(text)
            if name:
                raise CodeInFile(f"{path}: refers to {name.group(1)}, which loading would call (torch loads "
                                 f"only tensors and plain values here); refused", pickled) from None
            detail = _WEIGHTS_ERROR.search(text)
            raise CodeInFile(f"{path}: holds something other than tensors and plain values"
                             f"{f' ({detail.group(1)[:200]})' if detail else ''}; refused", pickled) from None
        except Exception as e:  # noqa: BLE001 - any failure to read a stranger's file is the file's
            raise FileRefused(f"{path}: torch cannot read it ({type(e).__name__}: "
                              f"{one_line(str(e))[:200]}); refused") from None


class Tensor(Spec):
    """A dense CPU tensor of `dtype` (or any floating type with `dtype=None`) and `shape`, where None
    takes any length."""

    def __init__(self, dtype: torch.dtype | None, shape: tuple[int | None, ...]) -> None:
        self.dtype, self.shape = dtype, shape
        dims = " x ".join("N" if n is None else str(n) for n in shape) or "a scalar"
        kind = "floating" if dtype is None else str(dtype).removeprefix("torch.")
        self.expected = f"{with_article(kind)} tensor of shape {dims}"

    def check(self, value: Any, where: str) -> None:
        ok = isinstance(value, torch.Tensor) and value.layout == torch.strided and value.device.type == "cpu" \
            and (value.dtype.is_floating_point if self.dtype is None else value.dtype == self.dtype) \
            and value.dim() == len(self.shape) \
            and all(want is None or have == want for have, want in zip(value.shape, self.shape))
        if not ok:
            raise Mismatch(where, self.expected, value)
