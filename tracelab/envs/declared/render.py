"""A declared board as an RGB image (render_mode="rgb_array"), drawn with numpy alone (gymnasium's
RecordVideo, `utils.save_video` and GIF writers work without a new dependency): each cell CELL pixels
square, top row first, filled with its character's colour (`[board] colors`, hex; a grey of the character's rank in the legend otherwise) with a thin grid,
a disc on each cell where a `marks` predicate holds (`[board] mark_colors`, red by default), and the
`[board] pieces` where they stand: a disc in the thing's colour, a small one for a piece with a heading (a
bullet), a small grey one for a dead thing; a living thing's disc has a dark outline."""
from __future__ import annotations

import numpy as np

from tracelab.board import Board

CELL = 24  # pixels per cell: a 16x16 board is 384x384, small enough for a video of many episodes
GRID = (45, 45, 45)
DEFAULT_MARK = (230, 57, 70)
DEAD = (150, 150, 150)
OUTLINE = (25, 25, 25)  # around a piece's disc: a red agent on the red base stays visible


def _disc(size: int, radius: float) -> np.ndarray:
    """bool [size, size]: the pixels whose centres lie within `radius` of the square's centre."""
    c = np.arange(size) + 0.5 - size / 2
    return c[:, None] ** 2 + c[None, :] ** 2 <= radius ** 2


class DeclaredPainter:
    def __init__(self, board: Board, cell: int = CELL) -> None:
        self.board, self.cell = board, cell
        chars = sorted({ch for row in board.rows for ch in row})
        h, w = board.height, board.width
        img = np.zeros((h * cell, w * cell, 3), np.uint8)
        for r, row in enumerate(board.rows):
            for c, ch in enumerate(row):
                grey = 70 + 120 * chars.index(ch) // max(1, len(chars) - 1)
                img[r * cell:(r + 1) * cell, c * cell:(c + 1) * cell] = board.colors.get(ch, (grey,) * 3)
        img[::cell, :] = GRID
        img[:, ::cell] = GRID
        self.background = img
        self._disc = _disc(cell, cell * 0.36)
        self._small = _disc(cell, cell * 0.2)
        self._ring = _disc(cell, cell * 0.44) & ~self._disc
        self._cells = {name: divmod(i, w) for i, name in enumerate(board.cells)}

    def __call__(self, marked: dict[str, str], mark_colors: dict[str, tuple[int, int, int]],
                 pieces: list[tuple[str, str, int, int, bool, str]] = ()) -> np.ndarray:
        """The image with a disc on each marked cell (`marked`: cell -> the predicate that marks it), then
        the pieces (DeclaredWorld.pieces_now: kind, thing, row, col, alive, heading)."""
        img = self.background.copy()
        for cell_name, pred in marked.items():
            r, c = self._cells[cell_name]
            self._tile(img, r, c)[self._disc] = mark_colors.get(pred, DEFAULT_MARK)
        for kind, thing, r, c, alive, heading in pieces:
            color = self.board.pieces[kind].color(thing) or (255, 255, 255)
            tile = self._tile(img, r, c)
            if alive and not heading:
                tile[self._ring] = OUTLINE
            tile[self._disc if alive and not heading else self._small] = color if alive else DEAD
        return img

    def _tile(self, img: np.ndarray, r: int, c: int) -> np.ndarray:
        return img[r * self.cell:(r + 1) * self.cell, c * self.cell:(c + 1) * self.cell]
