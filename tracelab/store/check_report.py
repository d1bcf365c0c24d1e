"""What `tracelab check` found (tracelab.store.check for a sealed run, check_parts for a live run's parts)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class DamagedPart:
    table: str
    path: Path          # relative to the run directory
    error: str
    episodes: str       # which episodes it held, in words


@dataclass
class CheckReport:
    run: Path
    sealed: bool
    parts: int = 0
    rows: int = 0
    damaged: list[DamagedPart] = field(default_factory=list)
    error: str | None = None              # a sealed file that does not read
    quarantined: list[Path] = field(default_factory=list)
    unlisted_bytes: int = 0
    temps: int = 0

    @property
    def ok(self) -> bool:
        return self.error is None and (not self.damaged or bool(self.quarantined))


def one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0] if text else ''}"
