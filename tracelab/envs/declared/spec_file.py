"""Reading an environment spec file: bounded, never run (tomllib only), and every later complaint located.

tomllib gives values without positions, so `KeyLines` scans the text once for table headers (`[a.b]`,
`[[a]]`) and `key = ` lines and maps a key path such as ("reward", "table") or ("actions", 2) to the line
that writes it (a key inside an inline table or an array gets its enclosing key's line)."""
from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from typing import Any

from tracelab.engine.safe_files import MIB, read_text
from tracelab.errors import UserError

SPEC_FILE_CAP = 1 * MIB  # a spec is a page of TOML; a board of 1000x1000 cells still fits

KeyPath = tuple[str | int, ...]


class SpecError(UserError):
    """A mistake in an environment spec: one line, `FILE:LINE: KEY: what was expected`."""


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*("[^"]*"|'[^']*'|[A-Za-z0-9_.-]+)\s*=""")


def _split_dotted(text: str) -> tuple[str, ...]:
    parts = re.findall(r""""([^"]*)"|'([^']*)'|([A-Za-z0-9_-]+)""", text)
    return tuple(a or b or c for a, b, c in parts)


@dataclass
class KeyLines:
    """The line (1-based) of each key path written in the file."""
    lines: dict[KeyPath, int] = field(default_factory=dict)

    @classmethod
    def scan(cls, text: str) -> KeyLines:
        out: dict[KeyPath, int] = {}
        table: KeyPath = ()
        counts: dict[tuple[str, ...], int] = {}
        depth = 0  # open brackets of a multi-line array or inline table: its lines hold no keys of the table
        for n, line in enumerate(text.splitlines(), start=1):
            code = _strip_comment(line)
            if depth == 0:
                m = _HEADER.match(code)
                if m and "=" not in code:
                    name = _split_dotted(m.group(2))
                    if m.group(1) == "[[":
                        i = counts.get(name, 0)
                        counts[name] = i + 1
                        table = (*name, i)
                    else:
                        table = name
                    out.setdefault(table, n)
                    continue
                k = _KEY.match(code)
                if k:
                    out.setdefault((*table, *_split_dotted(k.group(1))), n)
                    code = code[k.end():]
            depth = max(0, depth + _bracket_balance(code))
        return cls(out)

    def line(self, path: KeyPath) -> int:
        """The line of `path`, or of its nearest written ancestor (0: unknown)."""
        for i in range(len(path), 0, -1):
            if path[:i] in self.lines:
                return self.lines[path[:i]]
        return 0


def _bracket_balance(code: str) -> int:
    """Opening minus closing brackets and braces outside quotes."""
    balance, quote = 0, None
    for c in code:
        if quote:
            if c == quote:
                quote = None
        elif c in "\"'":
            quote = c
        elif c in "[{":
            balance += 1
        elif c in "]}":
            balance -= 1
    return balance


def _strip_comment(line: str) -> str:
    """The line without a trailing comment (a `#` outside quotes)."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            if c == quote:
                quote = None
        elif c in "\"'":
            quote = c
        elif c == "#":
            return line[:i]
    return line


@dataclass
class SpecSource:
    """A parsed spec file: its path, its TOML data and where each key is written."""
    path: str
    data: dict[str, Any]
    key_lines: KeyLines

    @property
    def folder(self) -> str:
        return os.path.dirname(os.path.abspath(self.path))

    def error(self, path: KeyPath, message: str) -> SpecError:
        """A located error about the value at `path`."""
        line = self.key_lines.line(path)
        where = f"{self.path}:{line}" if line else self.path
        key = ".".join(str(p) if isinstance(p, str) else f"[{p}]" for p in path).replace(".[", "[")
        return SpecError(f"{where}: {key}: {message}" if key else f"{where}: {message}")


def read_spec_file(path: str | os.PathLike[str]) -> SpecSource:
    """The spec at `path`: a regular UTF-8 file of at most SPEC_FILE_CAP bytes, parsed as TOML."""
    file = os.fspath(path)
    text = read_text(file, SPEC_FILE_CAP, what="spec file")
    return SpecSource(file, parse_toml(text, file), KeyLines.scan(text))


def parse_toml(text: str, file: str) -> dict[str, Any]:
    """A stranger's TOML text (a spec, a sweep file); SpecError at FILE:LINE:COLUMN if it is not TOML, or
    nests deeper than tomllib's recursion can go."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(e))
        where = f"{file}:{m.group(1)}:{m.group(2)}" if m else file
        msg = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(e)) if m else str(e)
        raise SpecError(f"{where}: not valid TOML: {msg}") from None
    except RecursionError:
        raise SpecError(f"{file}: TOML nested too deeply; refused") from None
