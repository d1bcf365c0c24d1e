"""The board as an RGB image (render_mode="rgb_array"), drawn with numpy alone so that gymnasium's
RecordVideo, `utils.save_video` and GIF writers work without a new dependency.

Each cell is `CELL` pixels square, the game's top row (highest y) first, as `render_text` prints it:
free cells dark grey with a thin grid, mountains brown, each base tinted in its team's colour, living
agents as discs in their team's colour (smaller, one per quarter, when agents share a cell; a health bar
under the disc when it takes more than one hit to kill), dead agents as a small grey cross, bullets as small
squares in their team's lighter colour. The
colours are the replay's (viewers/replay/style.py), so a video and a replay read the same. The image
depends on the state alone: the same state gives the same bytes."""
from __future__ import annotations

import numpy as np

from tracelab.game.scenario import Scenario
from tracelab.game.state import GameState

CELL = 24  # pixels per cell: a 16x16 map is 384x384, small enough for a video of many episodes

FREE = (60, 60, 60)
GRID = (45, 45, 45)
MOUNTAIN = (121, 85, 61)
BASE = np.array([(120, 30, 36), (28, 62, 128)], np.uint8)      # red's base, blue's base
AGENT = np.array([(230, 57, 70), (52, 120, 246)], np.uint8)     # red, blue
BULLET = np.array([(255, 150, 120), (130, 200, 255)], np.uint8)
DEAD = (140, 140, 140)
HEALTH_LEFT, HEALTH_LOST = (120, 220, 120), (20, 20, 20)


def _disc(size: int, radius: float) -> np.ndarray:
    """bool [size, size]: the pixels whose centres lie within `radius` of the square's centre."""
    c = np.arange(size) + 0.5 - size / 2
    return c[:, None] ** 2 + c[None, :] ** 2 <= radius ** 2


def _cross(size: int, half_width: float, margin: int) -> np.ndarray:
    """bool [size, size]: an X from corner to corner, `margin` pixels in from the edges."""
    i = np.arange(size)[:, None] + 0.5
    j = np.arange(size)[None, :] + 0.5
    inner = (i > margin) & (i < size - margin) & (j > margin) & (j < size - margin)
    return inner & ((np.abs(i - j) <= half_width) | (np.abs(i + j - size) <= half_width))


class BoardPainter:
    """Draws one world of a scenario's state; the map (terrain and bases) is drawn once."""

    def __init__(self, scenario: Scenario, cell: int = CELL) -> None:
        self.scenario = scenario
        self.cell = cell
        self._disc = _disc(cell, cell * 0.36)
        self._small_disc = _disc(cell // 2, cell * 0.2)  # agents sharing a cell: one per quarter
        self._cross = _cross(cell, cell * 0.06 + 0.5, cell // 4)
        self._bullet = _disc(cell, cell * 0.14)
        self._multi_hit = scenario.hits_to_kill > 1
        self.background = self._draw_map()

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.background.shape  # type: ignore[return-value]

    def _draw_map(self) -> np.ndarray:
        sc, c = self.scenario, self.cell
        img = np.empty((sc.height * c, sc.width * c, 3), np.uint8)
        img[:] = FREE
        for x, y in sc.mountains:
            self._block(img, x, y)[:] = MOUNTAIN
        for team, (x, y) in enumerate(sc.bases):
            self._block(img, x, y)[:] = BASE[team]
        img[::c, :] = GRID   # a one-pixel line on each cell's top and left edge, and the board's bottom and right
        img[:, ::c] = GRID
        img[-1, :] = GRID
        img[:, -1] = GRID
        return img

    def _block(self, img: np.ndarray, x: int, y: int) -> np.ndarray:
        """The view of cell (x, y) in `img` (game y grows upwards, image rows downwards)."""
        row, col = (self.scenario.height - 1 - int(y)) * self.cell, int(x) * self.cell
        return img[row: row + self.cell, col: col + self.cell]

    def __call__(self, state: GameState, world: int = 0) -> np.ndarray:
        """uint8 [height * cell, width * cell, 3] of `world` in `state`."""
        img = self.background.copy()
        for (x, y), d, team in zip(state.bullet_pos[world], state.bullet_dir[world], state.bullet_team):
            if d >= 0:
                self._block(img, x, y)[self._bullet] = BULLET[team]
        # the dead first, so that a living agent on the same cell is drawn over them
        alive = state.alive[world]
        for team in range(2):
            for (x, y), living in zip(state.pos[world, team], alive[team]):
                if not living:
                    self._block(img, x, y)[self._cross] = DEAD
        living = [(team, (int(x), int(y)), h) for team in range(2)
                  for (x, y), a, h in zip(state.pos[world, team], alive[team], state.health[world, team]) if a]
        sharing: dict[tuple[int, int], int] = {}
        for _, xy, _ in living:
            sharing[xy] = sharing.get(xy, 0) + 1
        seen: dict[tuple[int, int], int] = {}
        half = self.cell // 2
        for team, xy, health in living:
            block = self._block(img, *xy)
            if sharing[xy] > 1:  # a smaller disc in the next quarter (top left, top right, ...)
                k = seen.get(xy, 0) % 4
                seen[xy] = k + 1
                block = block[(k // 2) * half: (k // 2 + 1) * half, (k % 2) * half: (k % 2 + 1) * half]
                block[self._small_disc] = AGENT[team]
            else:
                block[self._disc] = AGENT[team]
            if self._multi_hit:
                self._health_bar(block, health / self.scenario.health)
        return img

    def _health_bar(self, block: np.ndarray, share: float) -> None:
        """A bar along the cell's bottom: green for the health left, black for the health lost."""
        c = block.shape[0]
        left, right = c // 6, c - c // 6
        filled = left + int(round(float(np.clip(share, 0.0, 1.0)) * (right - left)))
        rows = slice(c - max(2, c // 8) - 1, c - 1)
        block[rows, left:right] = HEALTH_LOST
        block[rows, left:filled] = HEALTH_LEFT
