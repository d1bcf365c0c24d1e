"""What the replay looks like: entity paths, timelines, classes and colours, and where a cell is drawn.

Board space: the viewer's 2D space has y growing downwards, the game's upwards, so cell (x, y) is drawn
centred on (x + 0.5, height - 1 - y + 0.5), one unit wide (pixel (x, height - 1 - y) of the terrain
image)."""
from __future__ import annotations

import numpy as np
import rerun as rr

from tracelab.viewers.board import PHASES, BoardMap

# ---- timelines: `step` is the game step; `pass` orders the phases within steps: step·10 + phase ----
STEP = "step"
PASS = "pass"
PASS_PER_STEP = 10
TRAIN_STEP = "train_step"
assert len(PHASES) <= PASS_PER_STEP

# ---- entity paths ----------------------------------------------------------------------------------------
BOARD = "/board"
TERRAIN = "/board/terrain"          # free cells, mountains and bases as a segmentation image
GRID = "/board/grid"
BASES = "/board/bases"              # both bases' outlines (red's first)
AGENTS = "/board/agents"            # /board/agents/red-agent-1
BULLETS = "/board/bullets"          # /board/bullets/red: the team's bullets in flight
ACTIONS = "/board/actions"          # /board/actions/red/move (arrows), /board/actions/red/shot (lines)
FIRED = "/board/fired"              # cells named by the step's firings, labelled with the rules
RULE_LOG = "/rules/log"
LANES = "/lanes"                    # /lanes/alive/red-agent-1, /lanes/atLoc/..., ...
WHY = "/why"
PLOTS = "/plots"                    # /plots/reward/red, /plots/return/blue
TRAIN = "/train"                    # /train/eval/win_rate, /train/loss, ...
VALUES = "/values"                  # /values/red-agent-1/up: the policy's value of each action
TERMS = "/terms"                    # /terms/red-agent-1/step: the return by reward term, stacked

# ---- classes (AnnotationContext on /board) ---------------------------------------------------------------
FREE, MOUNTAIN, RED_BASE, BLUE_BASE = 0, 1, 2, 3
RED_AGENT, BLUE_AGENT, DEAD_AGENT = 10, 11, 12
RED_BULLET, BLUE_BULLET = 20, 21
FIRED_CELL = 30
RED = (230, 57, 70)
BLUE = (52, 120, 246)
CLASSES = [
    (FREE, "free", (60, 60, 60)),
    (MOUNTAIN, "mountain", (121, 85, 61)),
    (RED_BASE, "red base", (120, 30, 36)),
    (BLUE_BASE, "blue base", (28, 62, 128)),
    (RED_AGENT, "red agent", RED),
    (BLUE_AGENT, "blue agent", BLUE),
    (DEAD_AGENT, "dead agent", (140, 140, 140)),
    (RED_BULLET, "red bullet", (255, 150, 120)),
    (BLUE_BULLET, "blue bullet", (130, 200, 255)),
    (FIRED_CELL, "fired rule", (255, 214, 10)),
]
TEAM_AGENT_CLASS = np.array([RED_AGENT, BLUE_AGENT])
TEAM_BULLET_CLASS = np.array([RED_BULLET, BLUE_BULLET])
TEAM_COLOR = np.array([RED, BLUE], dtype=np.uint8)
LOG_COLOR = {"start": (150, 150, 150), "shield": (150, 150, 150), "bullets": (255, 170, 120),
             "hits": (255, 110, 110), "act": (160, 220, 160), "walk-in": (255, 130, 180),
             "deaths": (255, 80, 80), "end": (255, 214, 10)}

DIRECTION_VECTORS = np.array([(0, -1), (0, 1), (-1, 0), (1, 0)], dtype=np.float32)  # up down left right, drawn
ACTION_NAMES = ("up", "down", "left", "right", "shoot up", "shoot down", "shoot left", "shoot right",
                "nothing")
# the action lane's text: a one-step segment is a few characters wide, where "shoot right" was cut to
# "shoo"; a move is its arrow, a shot the bullet (⁍, as in the agents' labels) and its arrow
ACTION_LANE_TEXT = ("↑", "↓", "←", "→", "⁍↑", "⁍↓", "⁍←", "⁍→", "idle")
assert len(ACTION_LANE_TEXT) == len(ACTION_NAMES)


def annotation_context() -> rr.AnnotationContext:
    return rr.AnnotationContext([rr.AnnotationInfo(id=i, label=name, color=color) for i, name, color in CLASSES])


def cell_centers(board_map: BoardMap, cells: np.ndarray) -> np.ndarray:
    """Drawing positions [..., 2] of cell ids (cells < 0 land off the board; callers mask them)."""
    x, y = board_map.xy(cells)
    return np.stack([x + 0.5, board_map.height - 0.5 - y], axis=-1).astype(np.float32)


def pass_time(step: np.ndarray, phase: np.ndarray | int) -> np.ndarray:
    return np.asarray(step, dtype=np.int64) * PASS_PER_STEP + np.asarray(phase, dtype=np.int64)


def short_name(agent: str) -> str:
    """red-agent-3 -> R3 (board labels stay small)."""
    team, _, number = agent.partition("-agent-")
    return f"{team[:1].upper()}{number}"


# ---- the replay of a run without a board (a reasoning run): its graph ----------------------------------
GRAPH = "/graph"
CHANGED = "/plots/changed"          # /plots/changed/exposed: atoms of the predicate changed per step
NODE_RADIUS = 14.0
UNCOLOURED_RADIUS = 6.0             # a node the colour predicate has no atom on (it stays grey)
SHOWN_NODE_LABELS = 60              # up to this many nodes, their names (and the edges' labels) are drawn
EDGE_LABEL_COLOR = (150, 150, 160)
SERIES_COLORS = [(80, 170, 255), (255, 214, 10), (160, 220, 160), (200, 140, 255), (255, 150, 200),
                 (120, 220, 220)]     # the other predicates' lines of "atoms changed per step"
# a node's colour from its bound [l, u] of the colour predicate: blue [0,0] .. red [1,1] by the middle
# (l + u) / 2, towards grey by the width u - l, so a never-set [0,1] atom (or none) is grey
BOUND_FALSE = np.array((70, 120, 210), np.float64)
BOUND_TRUE = np.array((255, 90, 60), np.float64)
BOUND_UNKNOWN = np.array((85, 85, 95), np.float64)
GRAPH_BACKGROUND = (24, 24, 28)


def bound_colors(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """[n, 3] uint8 colours of bounds (see BOUND_FALSE)."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    c = BOUND_FALSE + (BOUND_TRUE - BOUND_FALSE) * ((lower + upper) / 2)[:, None]
    c += (BOUND_UNKNOWN - c) * (upper - lower)[:, None]
    return np.clip(np.rint(c), 0, 255).astype(np.uint8)
