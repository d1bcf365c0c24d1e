"""Reading an environment spec file: bounded, never run (tomllib only), and every later complaint located.

tomllib gives values without positions, so `KeyLines` scans the text once for table headers (`[a.b]`,
`[[a]]`) and `key = ` lines and maps a key path such as ("reward", "table") or ("actions", 2) to the line
that writes it (a key inside an inline table or an array gets its enclosing key's line).

Reading is linear in the file: the scans use no pattern that can backtrack, and a dotted key of many
parts (`a.a.a...`, whose every prefix tomllib rebuilds: quadratic time and memory) is refused before
tomllib sees it."""
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


class WorldStateError(SpecError, RuntimeError):
    """A world of a spec that reached a state its spec cannot read (no atom of an index part true, no
    start value whose weights hold), found while stepping: located at the key, as a SpecError is (a
    RuntimeError too: the env cannot go on)."""


MAX_KEY_PARTS = 10  # parts of one dotted key or table header; specs use 2 or 3 ([data.maps], a.b = 1)
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
                header = _header(code)
                if header is not None:
                    double, name = header
                    if double:
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


def _header(code: str) -> tuple[bool, tuple[str, ...]] | None:
    """A table header `[a.b]` or `[[a]]` (double: True) and its name's parts; None for any other line."""
    text = code.strip()
    if not (text.startswith("[") and text.endswith("]")) or "=" in text or len(text) < 3:
        return None
    double = text.startswith("[[") and text.endswith("]]") and len(text) >= 5
    inner = text[2:-2] if double else text[1:-1]
    if "]" in inner:
        return None
    return double, _split_dotted(inner)


_KEY_CHAIN_BREAKS = re.compile(r"""["'#\n=,\[\]{}.]""")  # what ends or extends a run of dotted key parts
_BASIC_END = re.compile(r'(?:[^"\\\n]|\\.)*"')  # the rest of a "string" (alternatives never overlap)
_MULTI_BASIC_END = re.compile(r'(?:[^"\\]|\\[\s\S]|"(?!""))*"""')


def check_key_parts(text: str, file: str) -> None:
    """SpecError when a dotted key or table header outside strings and comments has more than
    MAX_KEY_PARTS parts: counted in one pass before tomllib, which is quadratic in them. A value has at
    most one dot (1.5, a time's fraction), so a longer run of dots is a key's."""
    dots, pos = 0, 0
    while True:
        m = _KEY_CHAIN_BREAKS.search(text, pos)
        if m is None:
            return
        c, pos = m.group(), m.end()
        if c == ".":
            dots += 1
            if dots >= MAX_KEY_PARTS:
                line = text.count("\n", 0, pos) + 1
                raise SpecError(f"{file}:{line}: a dotted key or table name of more than {MAX_KEY_PARTS} parts; "
                                "refused")
            continue
        if c == "#":
            end = text.find("\n", pos)
            pos = len(text) if end < 0 else end
        elif c in "\"'":  # a string is one part of a key (or a value): the run of dots goes on after it
            pos = _string_end(text, pos, c)
            if pos < 0:
                return  # unterminated: tomllib says where
        else:
            dots = 0


def _string_end(text: str, pos: int, quote: str) -> int:
    """Where the string opened by `quote` just before `pos` ends (-1: it does not)."""
    multi = text.startswith(quote * 2, pos)
    if quote == '"':
        m = (_MULTI_BASIC_END if multi else _BASIC_END).match(text, pos + 2 if multi else pos)
        end = -1 if m is None else m.end()
    else:
        end = text.find(quote * 3 if multi else quote, pos + 2 if multi else pos)
        end = -1 if end < 0 else end + (3 if multi else 1)
    if multi and end >= 0:  # up to two quotes of the content may stand right before the closing three
        for _ in range(2):
            if text.startswith(quote, end):
                end += 1
    return end


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
    # the paths of generated parts (spec_repeat): where their template is written, and with which values
    origins: dict[KeyPath, tuple[KeyPath, str]] = field(default_factory=dict)

    @property
    def folder(self) -> str:
        return os.path.dirname(os.path.abspath(self.path))

    def error(self, path: KeyPath, message: str, kind: type[SpecError] = SpecError, note: str = "") -> SpecError:
        """A located error (`kind`) about the value at `path` (a generated one's: at its template, with the
        `for` variables' values, or `note`)."""
        path, generated = self.written_at(path)
        note = generated or note
        line = self.key_lines.line(path)
        where = f"{self.path}:{line}" if line else self.path
        key = ".".join(str(p) if isinstance(p, str) else f"[{p}]" for p in path).replace(".[", "[")
        key += f" ({note})" if note else ""
        return kind(f"{where}: {key}: {message}" if key else f"{where}: {message}")

    def written_at(self, path: KeyPath) -> tuple[KeyPath, str]:
        """Where `path` is written in the file, and the `for` variables' values that generated it."""
        for i in range(len(path), 0, -1):
            if path[:i] in self.origins:
                orig, note = self.origins[path[:i]]
                return (*orig, *path[i:]), note
        return path, ""


def read_spec_file(path: str | os.PathLike[str]) -> SpecSource:
    """The spec at `path`: a regular UTF-8 file of at most SPEC_FILE_CAP bytes, parsed as TOML."""
    file = os.fspath(path)
    text = read_text(file, SPEC_FILE_CAP, what="spec file")
    return SpecSource(file, parse_toml(text, file), KeyLines.scan(text))


def parse_toml(text: str, file: str) -> dict[str, Any]:
    """A stranger's TOML text (a spec, a sweep file); SpecError at FILE:LINE:COLUMN if it is not TOML, has
    keys of too many parts (tomllib's time grows with their square: check_key_parts), or nests deeper than
    tomllib's recursion can go."""
    check_key_parts(text, file)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(e))
        where = f"{file}:{m.group(1)}:{m.group(2)}" if m else file
        msg = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(e)) if m else str(e)
        raise SpecError(f"{where}: not valid TOML: {msg}") from None
    except RecursionError:
        raise SpecError(f"{file}: TOML nested too deeply; refused") from None
