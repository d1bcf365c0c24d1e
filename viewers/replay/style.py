"""What the replay looks like: entity paths, timelines and colours (the board's space: board_layer.py)."""
from __future__ import annotations

import numpy as np

# ---- the timeline: `step` is the timestep (an env's step, a reasoning's timestep)
STEP = "step"

# ---- entity paths ----------------------------------------------------------------------------------------
BOARD = "/board"
TERRAIN = "/board/terrain"          # the cells as the env's rgb_array paints them (its marks too)
FIRED = "/board/fired"              # cells where the step's rules set an `annotate` atom, labelled with them
RULE_LOG = "/rules/log"
LANES = "/lanes"                    # /lanes/alive/red-agent-1, /lanes/atLoc/...: --lanes' predicates
WHY = "/why"
PLOTS = "/plots"                    # /plots/reward/red-agent-1, /plots/return/red-agent-1
VALUES = "/values"                  # /values/red-agent-1/up: the policy's value of each action
TERMS = "/terms"                    # /terms/red-agent-1/step: the return by reward term, stacked

# ---- colours ------------------------------------------------------------------------------------------------
FIRED_COLOR = (255, 214, 10)
BOARD_BACKGROUND = (24, 24, 28)
# the lines of a plot whose series have no colour of their own (an agent that is no piece of the board,
# an action's value, a predicate's changes)
SERIES_COLORS = [(80, 170, 255), (255, 214, 10), (160, 220, 160), (200, 140, 255), (255, 150, 200),
                 (120, 220, 220)]


# ---- a run without a board (a reasoning run): its graph ----------------------------------
GRAPH = "/graph"
CHANGED = "/plots/changed"          # /plots/changed/exposed: atoms of the predicate changed per step
NODE_RADIUS = 14.0
UNCOLOURED_RADIUS = 6.0             # a node the colour predicate has no atom on (it stays grey)
SHOWN_NODE_LABELS = 60              # up to this many nodes, their names (and the edges' labels) are drawn
EDGE_LABEL_COLOR = (150, 150, 160)
# a node's colour from its bound [l, u] of the colour predicate: blue [0,0] .. red [1,1] by the middle
# (l + u) / 2, towards grey by the width u - l, so a never-set [0,1] atom (or none) is grey
BOUND_FALSE = np.array((70, 120, 210), np.float64)
BOUND_TRUE = np.array((255, 90, 60), np.float64)
BOUND_UNKNOWN = np.array((85, 85, 95), np.float64)
GRAPH_BACKGROUND = BOARD_BACKGROUND


def bound_colors(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """[n, 3] uint8 colours of bounds (see BOUND_FALSE)."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    c = BOUND_FALSE + (BOUND_TRUE - BOUND_FALSE) * ((lower + upper) / 2)[:, None]
    c += (BOUND_UNKNOWN - c) * (upper - lower)[:, None]
    return np.clip(np.rint(c), 0, 255).astype(np.uint8)
