"""A spec's board: rows of characters, one cell each, turned into facts the rules read.

Each cell is a constant (`cell` format, default `c{row}_{col}`); the legend gives, per character, the
unary predicates true of the cell (`H = ["hole"]` -> `hole(c1_1)`); each neighbour direction gives a binary
predicate from a cell to the cell that way (`left = [0, -1]` -> `left(c1_1, c1_0)`), which at the edge
of the board is the cell itself (`edge = "stay"`, gymnasium's toy-text games clamp moves) or nothing
(`edge = "none"`); a direction may list several offsets (`next = [[0, 1], [0, -1]]`: one predicate for
each of them). Each ray gives a binary predicate from a cell to every cell 1, 2, ... steps that way up
to the edge (`up = [-1, 0]` -> the cells straight above: what is "in line"); each edge gives a unary
predicate true of the cells whose step that way leaves the board. Cells are listed row by row, top row
first: that order is the domain `cells`."""
from __future__ import annotations

from dataclasses import dataclass, field

MAX_BOARD_CELLS = 65_536  # 256 x 256: with a legend and four neighbours, ~330k facts built in Python
MAX_BOARD_FACTS = 2_000_000  # rays make a row or a column per cell: refused before they are built


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
