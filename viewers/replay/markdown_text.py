"""A run's strings inside the replay's markdown documents, shown as the text they are. A run is a
stranger's file: an atom named `![x](https://...)` must not become an image the viewer fetches, a rule
name must not become a link or HTML, and a why-tree holding ``` must not end its code block early."""
from __future__ import annotations

import re

# what can open inline markup mid-line (emphasis, code, links, images, HTML, strikethrough); `(`, `-`,
# `.` and the like only mean something after one of these or at a line's start, which a run's string
# never is here
_MARKUP = re.compile(r"([\\`*_\[\]<>!~])")
_BACKTICKS = re.compile(r"`+")


def literal(text: str) -> str:
    """`text` escaped so that markdown shows it character for character."""
    return _MARKUP.sub(r"\\\1", text)


def code_block(text: str, info: str = "text") -> list[str]:
    """The lines of a fenced code block holding `text`, its fence longer than any run of backticks in it."""
    longest = max((len(m) for m in _BACKTICKS.findall(text)), default=0)
    fence = "`" * max(3, longest + 1)
    return [fence + info, text, fence]
