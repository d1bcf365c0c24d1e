"""What the replay looks like: entity paths, timelines and colours (the board's space: board_layer.py)."""
from __future__ import annotations

import numpy as np

from tracelab.viewers.board import PHASES

# ---- timelines: `step` is the game step; `pass` orders the phases within steps: step·10 + phase ----
STEP = "step"
PASS = "pass"
PASS_PER_STEP = 10
TRAIN_STEP = "train_step"
assert len(PHASES) <= PASS_PER_STEP

# ---- entity paths ----------------------------------------------------------------------------------------
BOARD = "/board"
TERRAIN = "/board/terrain"          # the cells as the env's rgb_array paints them (its marks too)
FIRED = "/board/fired"              # cells where the step's rules set an `annotate` atom, labelled with them
RULE_LOG = "/rules/log"
LANES = "/lanes"                    # /lanes/alive/red-agent-1, /lanes/atLoc/..., ...
WHY = "/why"
PLOTS = "/plots"                    # /plots/reward/red, /plots/return/blue
TRAIN = "/train"                    # /train/eval/win_rate, /train/loss, ...
VALUES = "/values"                  # /values/red-agent-1/up: the policy's value of each action
TERMS = "/terms"                    # /terms/red-agent-1/step: the return by reward term, stacked

# ---- colours ------------------------------------------------------------------------------------------------
RED = (230, 57, 70)
BLUE = (52, 120, 246)
TEAM_COLOR = np.array([RED, BLUE], dtype=np.uint8)
FIRED_COLOR = (255, 214, 10)
LOG_COLOR = {"start": (150, 150, 150), "shield": (150, 150, 150), "bullets": (255, 170, 120),
             "hits": (255, 110, 110), "act": (160, 220, 160), "walk-in": (255, 130, 180),
             "deaths": (255, 80, 80), "end": (255, 214, 10)}

ACTION_NAMES = ("up", "down", "left", "right", "shoot up", "shoot down", "shoot left", "shoot right",
                "nothing")
# the action lane's text: a one-step segment is a few characters wide, where "shoot right" was cut to
# "shoo"; a move is its arrow, a shot the bullet (⁍, as in the agents' labels) and its arrow
ACTION_LANE_TEXT = ("↑", "↓", "←", "→", "⁍↑", "⁍↓", "⁍←", "⁍→", "idle")
assert len(ACTION_LANE_TEXT) == len(ACTION_NAMES)


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
