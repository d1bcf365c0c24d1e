"""A spec's board: rows of characters, one cell each, turned into facts the rules read.

Each cell is a constant (`cell` format, default `c{row}_{col}`); the legend gives, per character, the
unary predicates true of the cell (`H = ["hole"]` -> `hole(c1_1)`); each neighbour direction gives a binary
predicate from a cell to the cell that way (`left = [0, -1]` -> `left(c1_1, c1_0)`), which at the edge
of the board is the cell itself (`edge = "stay"`, gymnasium's toy-text games clamp moves) or nothing
(`edge = "none"`); a direction may list several offsets (`next = [[0, 1], [0, -1]]`: one predicate for
each of them). Each ray gives a binary predicate from a cell to every cell 1, 2, ... steps that way up
to the edge (`up = [-1, 0]` -> the cells straight above: what is "in line"); each edge gives a unary
predicate true of the cells whose step that way leaves the board. Cells are listed row by row, top row
first: that order is the domain `cells`.

What the viewers draw on it (no rule reads these): `marks` (a character on each cell where a predicate of
one argument holds), `pieces` (things standing on cells: an agent, a bullet; `Pieces`) and `annotate` (the
predicates whose rule firings the replay outlines on the board, labelled with the rules).

A run of the world's games records its board in its config (`board_config`); the viewers (the TUI, the
replay) read it back from there (`board_of_config`), checked, as a run's config comes from anywhere."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

MAX_BOARD_CELLS = 65_536  # 256 x 256: with a legend and four neighbours, ~330k facts built in Python
MAX_BOARD_FACTS = 2_000_000  # rays make a row or a column per cell: refused before they are built
# only {row} and {col} between name characters: str.format is never given a field or format spec of a
# stranger's ({row.__class__}, {row:>999999999})
CELL_FORMAT = re.compile(r"(?:[A-Za-z0-9_-]|\{row\}|\{col\})+")
RUN_CONFIG_KEY = "declared_board"  # where a run's config holds the board (board_config)
MAX_RECORDED_SIDE = 256  # rows and columns of a board read from a run (the spec's own limit is 65,536 cells)


DIRECTION_ARROWS = {"up": "↑", "down": "↓", "left": "←", "right": "→", "north": "↑", "south": "↓",
                    "west": "←", "east": "→"}
MAX_PIECE_KINDS = 16


@dataclass(frozen=True)
class Pieces:
    """One kind of thing drawn on the board where it stands: the things an atom of `things` names
    (`agent(red-agent-1)`), each on the cell where `at(Thing, Cell)` holds, in the colour of the longest
    `colors` key its name starts with ("red-" -> red); with `alive`, drawn dead (grey, a cross) where
    `alive(Thing)` does not hold; with `heading`, drawn as an arrow the way `heading(Thing, D)` names
    (up, down, left, right)."""
    at: str
    things: str
    colors: dict[str, tuple[int, int, int]] = field(default_factory=dict)
    alive: str | None = None
    heading: str | None = None

    def color(self, thing: str) -> tuple[int, int, int] | None:
        keys = [k for k in self.colors if thing.startswith(k)]
        return self.colors[max(keys, key=len)] if keys else None

    @property
    def predicates(self) -> list[str]:
        return [p for p in (self.at, self.alive, self.heading) if p]


def piece_label(thing: str) -> str:
    """Two characters for a thing on a cell: its name's first letter and its first number
    (red-agent-1 -> R1)."""
    digits = next((p for p in thing.split("-")[1:] if p.isdigit()), "")
    return (thing[:1].upper() + digits)[:2]


@dataclass(frozen=True)
class Board:
    rows: tuple[str, ...]
    cell_format: str
    legend: dict[str, tuple[str, ...]]
    neighbours: dict[str, tuple[tuple[int, int], ...]]  # predicate -> its offsets (row step, column step)
    edge: str  # "stay" | "none"
    marks: dict[str, str]  # unary predicate -> the character drawn on a cell where it holds (ansi)
    colors: dict[str, tuple[int, int, int]]  # character -> its cells' colour (rgb_array)
    mark_colors: dict[str, tuple[int, int, int]]  # marks' predicate -> its disc's colour (rgb_array)
    rays: dict[str, tuple[int, int]] = field(default_factory=dict)  # predicate -> the offset repeated
    edges: dict[str, tuple[int, int]] = field(default_factory=dict)  # predicate -> the offset leaving the board
    pieces: dict[str, Pieces] = field(default_factory=dict)  # a kind's name -> its things (drawn only)
    annotate: tuple[str, ...] = ()  # predicates whose rule firings the replay outlines (drawn only)

    @property
    def height(self) -> int:
        return len(self.rows)

    @property
    def width(self) -> int:
        return len(self.rows[0]) if self.rows else 0

    def cell(self, row: int, col: int) -> str:
        return self.cell_format.format(row=row, col=col)

    @property
    def cells(self) -> list[str]:
        """Every cell's constant, row by row from the top: the domain `cells` and the order of an index."""
        return [self.cell(r, c) for r in range(self.height) for c in range(self.width)]

    def facts(self) -> list[tuple[str, tuple[str, ...]]]:
        """The board's facts as (predicate, arguments): legend facts cell by cell, then neighbours."""
        out: list[tuple[str, tuple[str, ...]]] = []
        for r, line in enumerate(self.rows):
            for c, ch in enumerate(line):
                out.extend((pred, (self.cell(r, c),)) for pred in self.legend.get(ch, ()))
        for pred, offsets in self.neighbours.items():
            for dr, dc in offsets:
                for r in range(self.height):
                    for c in range(self.width):
                        r2, c2 = r + dr, c + dc
                        if self.on_board(r2, c2):
                            out.append((pred, (self.cell(r, c), self.cell(r2, c2))))
                        elif self.edge == "stay":
                            out.append((pred, (self.cell(r, c), self.cell(r, c))))
        for pred, (dr, dc) in self.rays.items():
            for r in range(self.height):
                for c in range(self.width):
                    r2, c2 = r + dr, c + dc
                    while self.on_board(r2, c2):
                        out.append((pred, (self.cell(r, c), self.cell(r2, c2))))
                        r2, c2 = r2 + dr, c2 + dc
        for pred, (dr, dc) in self.edges.items():
            out.extend((pred, (self.cell(r, c),)) for r in range(self.height) for c in range(self.width)
                       if not self.on_board(r + dr, c + dc))
        return out

    def on_board(self, row: int, col: int) -> bool:
        return 0 <= row < self.height and 0 <= col < self.width

    def fact_count(self) -> int:
        """How many facts `facts()` makes, counted before they are built (rays make up to a cell's row
        and column per cell)."""
        h, w = self.height, self.width
        cells = h * w
        n = sum(len(self.legend.get(ch, ())) for line in self.rows for ch in line)
        n += cells * sum(len(o) for o in self.neighbours.values())
        n += sum(cells * max(h, w) for _ in self.rays) + cells * len(self.edges)
        return n

    def text(self, marked: dict[str, str]) -> str:
        """The board as text, a cell's character replaced by the mark of the predicate holding there
        (`marked`: cell constant -> predicate)."""
        return "\n".join("".join(self.marks[marked[name]] if (name := self.cell(r, c)) in marked else ch
                                 for c, ch in enumerate(line))
                         for r, line in enumerate(self.rows)) + "\n"


def hex_color(text: str) -> tuple[int, int, int] | None:
    """(r, g, b) of "#rrggbb", or None when the text is not one."""
    if len(text) != 7 or text[0] != "#":
        return None
    try:
        return int(text[1:3], 16), int(text[3:5], 16), int(text[5:7], 16)
    except ValueError:
        return None


def _hexes(colors: dict[str, tuple[int, int, int]]) -> dict[str, str]:
    return {k: "#{:02x}{:02x}{:02x}".format(*rgb) for k, rgb in colors.items()}


def board_config(board: Board) -> dict[str, Any]:
    """What a run records of the board for the viewers to draw it (its facts are in the run already)."""
    pieces = {name: {"at": p.at, "things": p.things, "colors": _hexes(p.colors),
                     **({"alive": p.alive} if p.alive else {}), **({"heading": p.heading} if p.heading else {})}
              for name, p in board.pieces.items()}
    return {"rows": list(board.rows), "cell": board.cell_format, "marks": dict(board.marks),
            "colors": _hexes(board.colors), "mark_colors": _hexes(board.mark_colors), "pieces": pieces,
            "annotate": list(board.annotate)}


def _is_name(x: Any) -> bool:
    return isinstance(x, str) and len(x) <= 100 and x.isidentifier()


def _colors_ok(c: Any) -> bool:
    return isinstance(c, dict) and len(c) <= 256 and all(
        isinstance(k, str) and len(k) <= 100 and isinstance(v, str) and hex_color(v) for k, v in c.items())


def _pieces_of_config(doc: Any) -> dict[str, Pieces] | None:
    """The recorded pieces (board_config), or None when they do not hold."""
    if not isinstance(doc, dict) or len(doc) > MAX_PIECE_KINDS:
        return None
    out = {}
    for name, p in doc.items():
        if not (isinstance(p, dict) and _is_name(name) and _is_name(p.get("at")) and _is_name(p.get("things"))
                and all(p.get(k) is None or _is_name(p.get(k)) for k in ("alive", "heading"))
                and _colors_ok(p.get("colors", {}))):
            return None
        out[name] = Pieces(p["at"], p["things"], {k: hex_color(v) for k, v in p.get("colors", {}).items()},
                           p.get("alive"), p.get("heading"))
    return out


def board_of_config(config: Any) -> Board | None:
    """The board a run's config declares (under RUN_CONFIG_KEY), or None: none declared, or a declaration
    that does not hold (types, sizes, the cell format, the colours)."""
    doc = config.get(RUN_CONFIG_KEY) if isinstance(config, dict) else None
    if not isinstance(doc, dict):
        return None
    rows, cell, marks = doc.get("rows"), doc.get("cell"), doc.get("marks")
    colors, mark_colors = doc.get("colors", {}), doc.get("mark_colors", {})
    ok = (isinstance(rows, list) and 0 < len(rows) <= MAX_RECORDED_SIDE
          and all(isinstance(r, str) and 0 < len(r) <= MAX_RECORDED_SIDE and len(r) == len(rows[0]) for r in rows)
          and isinstance(cell, str) and len(cell) <= 100 and bool(CELL_FORMAT.fullmatch(cell))
          and isinstance(marks, dict) and len(marks) <= 64
          and all(isinstance(k, str) and k.isidentifier() and isinstance(v, str) and len(v) == 1
                  for k, v in marks.items())
          and all(_colors_ok(c) for c in (colors, mark_colors)))
    pieces = _pieces_of_config(doc.get("pieces", {}))
    annotate = doc.get("annotate", [])
    if not ok or pieces is None or not (isinstance(annotate, list) and len(annotate) <= 64
                                        and all(_is_name(a) for a in annotate)):
        return None
    return Board(tuple(rows), cell, {}, {}, "stay", dict(marks), {k: hex_color(v) for k, v in colors.items()},
                 {k: hex_color(v) for k, v in mark_colors.items() if k in marks}, pieces=pieces,
                 annotate=tuple(annotate))
