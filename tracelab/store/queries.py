"""The library of saved queries: tracelab/queries/<name>.sql, run with `tracelab sql RUN --query NAME`.

A query file starts with comment lines: the first is its description; each parameter is declared as
    -- param NAME TYPE = DEFAULT : help
with TYPE int, float or str and DEFAULT a literal or `null`. The SQL refers to it as $NAME (cast it,
e.g. CAST($episode AS BIGINT), where DuckDB cannot infer its type from the context). A query about games
says so with a line
    -- needs games : why        (agents' steps, outcomes: any run of games, a spec world's too)
    -- needs board : why        (a board: the grid game's or a spec world's `[board]`)
and is refused, with that reason, on a run that is not one (a reasoning run; tracelab.store.kind)."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

QUERIES_DIR = Path(__file__).resolve().parent.parent / "queries"
_PARAM = re.compile(r"^--\s*param\s+(\w+)\s+(int|float|str)\s*=\s*(.*?)\s*(?::\s*(.*))?$")
_NEEDS = re.compile(r"^--\s*needs\s+(board|games)\s*(?::\s*(.*))?$")
_TYPES = {"int": int, "float": float, "str": str}


@dataclass
class Param:
    name: str
    type: str
    default: Any
    help: str = ""

    def convert(self, text: str) -> Any:
        if text.lower() == "null":
            return None
        try:
            return _TYPES[self.type](text)
        except ValueError:
            raise ValueError(f"parameter {self.name} must be {self.type}, got {text!r}") from None


@dataclass
class SavedQuery:
    name: str
    description: str
    sql: str
    params: list[Param] = field(default_factory=list)
    needs_board: str | None = None     # why it reads only game runs (None: it reads any run)
    needs: str | None = None           # "games" (any game run) or "board" (a run with a board), as kind.can_read

    def bind(self, given: dict[str, str]) -> dict[str, Any]:
        """Parameter values: the given ones (text, converted) over the defaults."""
        known = {p.name: p for p in self.params}
        unknown = set(given) - set(known)
        if unknown:
            raise KeyError(f"query {self.name} has no parameter(s) {sorted(unknown)}; its parameters: "
                           f"{', '.join(known) or 'none'}")
        return {name: p.convert(given[name]) if name in given else p.default for name, p in known.items()}


def _literal(p: Param, text: str) -> Any:
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        text = text[1:-1]
    return p.convert(text)


def load_query(path: Path) -> SavedQuery:
    lines = path.read_text().splitlines()
    description, params, needs_board, needs = "", [], None, None
    for line in lines:
        if not line.startswith("--"):
            break
        m = _PARAM.match(line)
        board = _NEEDS.match(line)
        if board:
            needs, needs_board = board[1], (board[2] or "it reads games").strip()
        elif m:
            p = Param(m[1], m[2], None, (m[4] or "").strip())
            p.default = _literal(p, m[3])
            params.append(p)
        elif not description:
            description = line.lstrip("-").strip()
    sql = "\n".join(lines)
    for p in params:
        if f"${p.name}" not in sql:
            raise ValueError(f"{path}: parameter {p.name} is declared but the SQL never uses ${p.name}")
    return SavedQuery(path.stem, description, sql, params, needs_board, needs)


def list_queries(directory: Path = QUERIES_DIR) -> list[SavedQuery]:
    return [load_query(p) for p in sorted(directory.glob("*.sql"))]


def get_query(name: str, directory: Path = QUERIES_DIR) -> SavedQuery:
    """The saved query called `name`: a name from the library, never a path."""
    names = [p.stem for p in sorted(directory.glob("*.sql"))]
    if name not in names:
        raise KeyError(f"no saved query {name!r}; saved queries: {', '.join(names)}")
    return load_query(directory / f"{name}.sql")
