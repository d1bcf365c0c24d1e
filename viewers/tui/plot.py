"""A line plot drawn with braille characters (2x4 dots per cell), several coloured series on shared axes,
and bands (a range per x) shaded as the background of the cells they cover, so that a line drawn over a
band stays readable: a title line, the y range on the left, the x range underneath. Small,
dependency-free, redrawn whole."""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from rich.text import Text
from textual.widget import Widget

# braille dot bits by (column, row) within a cell
_DOTS = ((0x01, 0x02, 0x04, 0x40), (0x08, 0x10, 0x20, 0x80))
AXIS_W = 7


@dataclass
class Series:
    name: str
    colour: str
    xs: list[float] = field(default_factory=list)
    ys: list[float] = field(default_factory=list)


@dataclass
class Band:
    """A range at each x (e.g. the min and max of several runs), shaded in a dark tone of `colour` (#rrggbb);
    named in the legend unless `name` is empty."""
    name: str
    colour: str
    xs: list[float] = field(default_factory=list)
    lows: list[float] = field(default_factory=list)
    highs: list[float] = field(default_factory=list)


def shade(colour: str, strength: float = 0.35) -> str:
    """A dark tone of a #rrggbb colour, as a background under lines of that colour."""
    rgb = [int(colour[i:i + 2], 16) for i in (1, 3, 5)]
    return "#" + "".join(f"{round(c * strength):02x}" for c in rgb)


def _fmt(v: float) -> str:
    """A y-axis label that fits AXIS_W - 1 characters: -1.44k, 250, 0.93, 3.2e-04."""
    a = abs(v)
    if a == 0:
        return "0"
    if a >= 1e6:
        return f"{v / 1e6:.3g}M"
    if a >= 999.5:  # :.3g would print 1e+03 and up in exponent form, cut by the axis
        return f"{v / 1e3:.3g}k"
    if a < 0.01:
        short = f"{v:.1e}".replace("e-0", "e-")
        return short if len(short) < AXIS_W else f"{v:.0e}".replace("e-0", "e-")
    return f"{v:.3g}"


def _fmt_step(v: float) -> str:
    """A training step for the x axis: 500, 30k, 1.2M."""
    if abs(v) >= 1e6:
        return f"{v / 1e6:.3g}M"
    if abs(v) >= 1e4:
        return f"{v / 1e3:.3g}k"
    return f"{v:.0f}" if v == int(v) else f"{v:.3g}"


class BraillePlot(Widget):

    def __init__(self, title: str, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.title = title
        self.series: list[Series] = []
        self.bands: list[Band] = []
        self.border_title = title

    def set_series(self, series: list[Series], bands: list[Band] | None = None) -> None:
        self.series, self.bands = series, bands or []
        self.refresh()

    @property
    def points(self) -> int:
        return sum(len(s.xs) for s in self.series)

    def render(self) -> Text:
        width, height = self.content_size.width, self.content_size.height
        shown = [s for s in self.series if s.xs]
        bands = [b for b in self.bands if b.xs]
        if not shown and not bands:
            return Text("no data yet", style="dim italic")
        legend = Text("  ").join([*(Text(f"━ {s.name}", style=s.colour) for s in shown),
                                  *(Text.assemble(("  ", f"on {shade(b.colour)}"), (f" {b.name}", b.colour))
                                    for b in bands if b.name)])
        legend.truncate(width, overflow="ellipsis")  # one line, whatever the names
        rows, cols = max(1, height - 2), max(1, width - AXIS_W)
        xs = [x for s in shown for x in s.xs] + [x for b in bands for x in b.xs]
        ys = [y for s in shown for y in s.ys if not math.isnan(y)] + \
             [y for b in bands for y in (*b.lows, *b.highs) if not math.isnan(y)]
        if not ys:
            return Text("no data yet", style="dim italic")
        x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
        if y1 == y0:
            y0, y1 = y0 - 0.5, y1 + 0.5
        if x1 == x0:
            x1 = x0 + 1
        cells = [[0] * cols for _ in range(rows)]
        colour = [[""] * cols for _ in range(rows)]
        background = [[""] * cols for _ in range(rows)]

        def dot_x(x: float) -> int:
            return round((x - x0) / (x1 - x0) * (cols * 2 - 1))

        def dot_y(y: float) -> int:
            return round((y1 - y) / (y1 - y0) * (rows * 4 - 1))

        for b in bands:  # the cells a band covers (any of their dots), as their background
            for qx, lo, hi in _band_columns(b, dot_x):
                for cy in range(dot_y(hi) // 4, dot_y(lo) // 4 + 1):
                    background[cy][qx // 2] = shade(b.colour)
        for s in shown:
            last: tuple[int, int] | None = None
            for x, y in zip(s.xs, s.ys):
                if math.isnan(y):
                    last = None
                    continue
                px, py = dot_x(x), dot_y(y)
                for qx, qy in _segment(last, (px, py)):
                    cx, cy = qx // 2, qy // 4
                    cells[cy][cx] |= _DOTS[qx % 2][qy % 4]
                    colour[cy][cx] = s.colour
                last = (px, py)
        out = Text()
        out.append_text(legend)
        out.append("\n")
        for r in range(rows):
            label = _fmt(y1) if r == 0 else _fmt(y0) if r == rows - 1 else ""
            out.append(label.rjust(AXIS_W - 1)[: AXIS_W - 1] + "┤", style="dim")
            for c in range(cols):
                style = f"{colour[r][c]} on {background[r][c]}" if background[r][c] else colour[r][c]
                out.append(chr(0x2800 + cells[r][c]) if cells[r][c] else " ", style=style)
            out.append("\n")
        left, right = _fmt_step(x0), _fmt_step(x1)
        out.append(" " * AXIS_W + left + right.rjust(max(1, cols - len(left))), style="dim")
        return out


def _segment(a: tuple[int, int] | None, b: tuple[int, int]) -> list[tuple[int, int]]:
    """The dots of a straight line from a to b (just b if there is no a)."""
    if a is None:
        return [b]
    (x0, y0), (x1, y1) = a, b
    n = max(abs(x1 - x0), abs(y1 - y0), 1)
    return [(round(x0 + (x1 - x0) * i / n), round(y0 + (y1 - y0) * i / n)) for i in range(1, n + 1)]


def _band_columns(band: Band, dot_x: Callable[[float], int]) -> list[tuple[int, float, float]]:
    """(dot column, low, high) for every dot column the band spans, low and high interpolated linearly
    between its points (a NaN point leaves a gap)."""
    out: list[tuple[int, float, float]] = []
    points = list(zip(band.xs, band.lows, band.highs))
    for (xa, la, ha), (xb, lb, hb) in zip(points, points[1:] or points):
        if any(math.isnan(v) for v in (la, ha, lb, hb)):
            continue
        qa, qb = dot_x(xa), dot_x(xb)
        for q in range(qa, qb + 1):
            f = 0.0 if qb == qa else (q - qa) / (qb - qa)
            out.append((q, la + (lb - la) * f, ha + (hb - ha) * f))
    return out
