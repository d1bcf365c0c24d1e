"""Strings from files a stranger may hand over (a run's meta.json, rule names and texts, atom names, a
spec, a graph) as text that is safe to show on a terminal or in a viewer: every control character is
written as a Python-style escape, so no escape sequence (ESC[2J, an OSC title or OSC-8 link, a C1 CSI),
no bidi override and no stray carriage return reaches the screen raw. The CLI, the TUI and the replay
all escape through `printable`, so a name reads the same everywhere."""
from __future__ import annotations

import re

# C0 controls (but tab and newline, which `keep` may let through), DEL, C1 controls, and the Unicode
# format characters that reorder or hide text: bidi embeddings, overrides and isolates, the
# marks, and the line and paragraph separators a terminal may treat as newlines.
_UNSAFE = re.compile("[\x00-\x08\x0a-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069]"
                     "|\t")


def _escape(m: re.Match[str]) -> str:
    c = m.group()
    code = ord(c)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}"


def printable(text: str, keep: str = "") -> str:
    """`text` with every control and bidi character escaped (`\\x1b`, `\\u202e`); the characters in
    `keep` (tab and newline only, for text that is laid out in lines) pass as they are."""
    if keep:
        return _UNSAFE.sub(lambda m: m.group() if m.group() in keep else _escape(m), text)
    return _UNSAFE.sub(_escape, text)


def has_unsafe(text: str) -> bool:
    """Whether `printable` would change `text` (tab and newline count: a one-line cell has neither)."""
    return _UNSAFE.search(text) is not None
