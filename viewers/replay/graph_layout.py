"""Where the replay draws a graph's nodes when the graph does not say (GraphML without `x`/`y`): a
force-directed layout (Fruchterman-Reingold), computed once per replay, the same for the same graph
(a fixed seed).

Not networkx's spring_layout, although it is installed (torch needs it): on the supply-chain sample
(2,430 nodes, 6,667 edges) it took 14-17 s of CPU (its `force` and `energy` methods alike), this one
1.7 s. The repulsion between nodes is approximated on a grid: each node is pushed by the centre of
mass of every occupied cell (GRID x GRID cells) instead of by every other node, so an iteration costs
nodes x cells, not nodes². Past MAX_FORCE_NODES nodes, even that is too slow for a replay: the nodes
go on a sunflower spiral (in node order), which costs nothing and overlaps nothing."""
from __future__ import annotations

import numpy as np

GRID = 24                  # cells a side for the repulsion's approximation
ITERATIONS = 80
# pull towards the middle: a lone node (no edge) settles where it balances the others' push, at a
# distance of about 1 / sqrt(GRAVITY) (with 1 it sat at twice the radius of the rest, alone in a corner
# of the picture)
GRAVITY = 4.0
MAX_FORCE_NODES = 20_000
SPACING = 40.0             # drawing units between neighbouring nodes (the replay's node radius is 14)
# the drawing's least size: the graph view zooms out to fit a graph but never in past 1:1 (a drawing unit is
# a point on screen), so a small graph drawn SPACING apart was a clump in the middle of the view
MIN_EXTENT = 700.0


def spiral_layout(n: int) -> np.ndarray:
    """[n, 2] points of a sunflower (Vogel) spiral, evenly spread over a disc of radius ~sqrt(n)."""
    i = np.arange(n, dtype=np.float64)
    angle = i * np.pi * (3.0 - np.sqrt(5.0))
    radius = np.sqrt(i + 0.5)
    return np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)


def force_layout(n: int, edges: np.ndarray, seed: int = 0, iterations: int = ITERATIONS) -> np.ndarray:
    """[n, 2] positions of n nodes joined by `edges` ([E, 2] node ids), in about a unit disc."""
    rng = np.random.default_rng(seed)
    pos = rng.random((n, 2)) - 0.5
    if n < 2:
        return pos * 0.0
    src, dst = np.asarray(edges, np.int64).reshape(-1, 2).T
    k = 1.0 / np.sqrt(n)                     # the ideal distance between nodes
    step = 0.1                               # the largest move, cooling to 0
    cooling = step / (iterations + 1)
    for _ in range(iterations):
        lo = pos.min(axis=0)
        size = float((pos.max(axis=0) - lo).max()) / GRID + 1e-12
        cell = np.minimum(((pos - lo) / size).astype(np.int64), GRID - 1)
        cid = cell[:, 0] * GRID + cell[:, 1]
        mass = np.bincount(cid, minlength=GRID * GRID).astype(np.float64)
        used = np.flatnonzero(mass)
        cx = np.bincount(cid, pos[:, 0], GRID * GRID)[used] / mass[used]
        cy = np.bincount(cid, pos[:, 1], GRID * GRID)[used] / mass[used]
        dx, dy = pos[:, 0, None] - cx, pos[:, 1, None] - cy
        # push / distance of each node from each cell (softened: a node's own cell is near zero); the
        # push along x is sum_c w (x - cx) = x sum_c w - w @ cx, two matrix-vector products
        w = (k * k) * mass[used] / (dx * dx + dy * dy + (size * 0.25) ** 2)
        total = w.sum(axis=1)
        disp = np.stack([pos[:, 0] * total - w @ cx, pos[:, 1] * total - w @ cy], axis=1)
        if len(src):
            pull = pos[src] - pos[dst]
            pull *= np.sqrt((pull * pull).sum(axis=1))[:, None] / k
            for axis in (0, 1):
                disp[:, axis] += np.bincount(dst, pull[:, axis], n) - np.bincount(src, pull[:, axis], n)
        disp -= pos * GRAVITY                # components and lone nodes stay near the middle
        length = np.maximum(np.sqrt((disp * disp).sum(axis=1)), 1e-12)[:, None]
        pos += disp / length * np.minimum(length, step)
        step -= cooling
    return pos


def _scale(n: int) -> float:
    """Drawing units per unit of a layout about one unit across: neighbours SPACING apart, at least
    MIN_EXTENT across."""
    return max(SPACING * np.sqrt(max(n, 1)), MIN_EXTENT)


def layout(n: int, edges: np.ndarray, seed: int = 0) -> np.ndarray:
    """[n, 2] drawing positions: a force layout (a spiral past MAX_FORCE_NODES), scaled so that
    neighbouring nodes are about SPACING apart, y down as the viewer draws it."""
    if n > MAX_FORCE_NODES:
        return spiral_layout(n) * SPACING
    return force_layout(n, edges, seed) * _scale(n)


def fit_given(positions: np.ndarray) -> np.ndarray:
    """Positions the graph gives, scaled like `layout`'s: their bounding box's longer side one unit (a
    tracelab GraphML number is in [0, 1]; PyReason's dialect takes any)."""
    positions = np.asarray(positions, np.float64)
    if not len(positions):
        return positions
    lo = positions.min(axis=0)
    extent = float((positions.max(axis=0) - lo).max()) or 1.0
    return (positions - lo) / extent * _scale(len(positions))
