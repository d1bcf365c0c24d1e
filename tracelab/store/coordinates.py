"""Where a run's nodes are: the (x, y) of the cells a run declares, shown beside their ids in traces and
why trees (`free(30)` reads `free(30@(6,3))`, `leftOf(29,30)` reads `leftOf(29@(5,3),30@(6,3))`).

A run declares a grid in its metadata's config: `"grid": {"width": W, "height": H}` says that the nodes
named by the whole numbers 0 .. W·H-1 are the cells of a W x H grid, cell id = y·W + x (x right, y up).
A run written before runs declared their board may have its grid from its world's registration instead
(world_extras.old_run_grid: the war game's RuleSim runs, their scenario's size; asked of those runs only, so
that reading any other run loads no registration). A run with neither (a reasoning run, a declared world's,
whose board names its cells) has no coordinates: its nodes read as their ids."""
from __future__ import annotations

import re
from typing import Any, NamedTuple

from tracelab.store.kind import run_config
from tracelab.store.schema import BOARD_BEFORE_DECLARED
from tracelab.world_extras import old_run_grid

GRID_KEY = "grid"
_MAX_CELLS = 2**31 - 1            # cell ids are int32 node names
_CELL_ARG = re.compile(r"(?<=[(,])(\d+)(?=[,)])")  # a whole-number argument of an atom or an edge


class Grid(NamedTuple):
    width: int
    height: int

    def xy(self, node: str) -> tuple[int, int] | None:
        """(x, y) of a node named by a cell id of this grid, else None."""
        if not node.isdigit():
            return None
        cell = int(node)
        if cell >= self.width * self.height:
            return None
        return cell % self.width, cell // self.width

    def node_text(self, node: str) -> str:
        """`30` -> `30@(6,3)`; other names unchanged."""
        xy = self.xy(node)
        return node if xy is None else f"{node}@({xy[0]},{xy[1]})"

    def with_coordinates(self, text: str | None) -> str | None:
        """An atom (`free(30)`), an edge (`(29,30)`) or a node (`30`) with each cell's (x, y) after its id."""
        if text is None:
            return None
        if "(" not in text:
            return self.node_text(text)
        return _CELL_ARG.sub(lambda m: self.node_text(m.group(1)), text)


def _checked(width: Any, height: Any) -> Grid | None:
    ok = all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (width, height))
    return Grid(width, height) if ok and width * height <= _MAX_CELLS else None


def grid_from_config(config: dict[str, Any], board: str | None = BOARD_BEFORE_DECLARED) -> Grid | None:
    """The grid a run's config declares (or, for a run whose `board` says it was written before runs
    declared theirs, its world's registration gives), or None (nothing declared, or a declaration that does
    not hold two positive sizes: then the run reads as ids, never as wrong places)."""
    declared = config.get(GRID_KEY)
    if isinstance(declared, dict):
        return _checked(declared.get("width"), declared.get("height"))
    sizes = old_run_grid(config) if board == BOARD_BEFORE_DECLARED else None
    return None if sizes is None else _checked(*sizes)


def run_grid(con: Any) -> Grid | None:
    """The grid the run open on `con` (tracelab.store.open_run) declares, or None."""
    board = con.execute("SELECT board FROM run").fetchall()
    return grid_from_config(run_config(con), board[0][0] if board else None)
