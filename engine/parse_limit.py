"""How much memory parsing a rule program may take: the parser holds every token, statement and source
location of the program at once, so a 22 MB file of 2,000,000 facts (under the 64 MiB file cap) took
3.5 GB and minutes before anything checked it. The program's text is measured first (a count of its lines
and bytes, at the speed of str.count) and refused in one line past the limit, before a token is made.

Measured: `edge(n1, n2) static` (a 28-byte line) costs 2.4 KB parsed (100,000 such facts: 240 MB); a
line is estimated at LINE_BYTES plus TEXT_BYTES per character. The limit is 1 GiB unless
$TRACELAB_PARSE_MEMORY says otherwise (a size: 4G, 500M): about 400,000 short facts. Bigger fact sets go
in a --facts-table (Parquet, read by DuckDB without parsing)."""
from __future__ import annotations

import re

from .safe_files import FileRefused, human_bytes, size_setting

PARSE_MEMORY_ENV = "TRACELAB_PARSE_MEMORY"
DEFAULT_PARSE_MEMORY = 1 << 30
LINE_BYTES = 1536  # a statement's objects: its tokens, literal, terms, location
TEXT_BYTES = 32    # per character: the tokens' strings, the line kept for messages
_CODE_LINE = re.compile(rb"^[ \t]*[^\s#]", re.M)  # a line that is neither blank nor a comment


def parse_memory_limit() -> tuple[int, str]:
    """The limit in bytes and how it was set (for the message)."""
    given = size_setting(PARSE_MEMORY_ENV, FileRefused)
    if given is None:
        return DEFAULT_PARSE_MEMORY, f"the default; ${PARSE_MEMORY_ENV} raises it"
    return given, f"set by ${PARSE_MEMORY_ENV}"


def parse_estimate(text: str) -> tuple[int, int]:
    """(statement lines, estimated bytes) of parsing `text`."""
    lines = len(_CODE_LINE.findall(text.encode("utf-8", "surrogatepass")))
    return lines, lines * LINE_BYTES + len(text) * TEXT_BYTES


class ParseBudget:
    """The memory the files of one program take parsed, refused at the file that crosses the limit."""

    def __init__(self) -> None:
        self.limit, self.source = parse_memory_limit()
        self.lines = self.spent = 0

    def spend(self, file: str, text: str) -> None:
        lines, need = parse_estimate(text)
        self.lines, self.spent = self.lines + lines, self.spent + need
        if self.spent > self.limit:
            raise FileRefused(
                f"{file}: {self.lines:,} lines of rules and facts would take an estimated "
                f"{human_bytes(self.spent)} to parse, over the limit of {human_bytes(self.limit)} ({self.source}; "
                f"a big fact set reads faster as a --facts-table); refused")
