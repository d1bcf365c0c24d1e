"""What the replay reads from a run: of a run without a board (a reasoning run, `tracelab reason --run`)
its nodes, their positions when the graph gives them (node attributes `x` and `y`), its predicates, and
per episode the bounds of the colour predicate over time and the binary atoms that draw the edges; of
every run, per episode the fired rules and how many atoms of each predicate changed in each step.

Everything is read through the run's sandboxed connection (tracelab.store.reader.open_run), as numpy
columns, one query each; what a big episode holds is bounded by what it changed: the rule log keeps at
most MAX_LOGGED_FIRINGS firings a step (and says how many more there were)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracelab.store.names import UnknownName, unknown_name_message
from tracelab.store.reader import RunConnection

MAX_LOGGED_FIRINGS = 2000   # firings of one step in the rule log; the rest are counted in one line
# the biggest graph the replay draws: past these, rerun's graph view is no longer usable and the recording
# (a colour per node at each step that changes one, every edge's two names) grows to gigabytes
MAX_NODES = 100_000
MAX_EDGES = 1_000_000
POSITION_LABELS = ("x", "y")  # node attributes that place a node (GraphML <data key="x">)

# a change that counts (for the default colour predicate, and in each step's "changed"): any but a static
# fact's (the graph's own attributes, which never change); `c` is raw.changes, `sf` its static facts
_STATIC_FACTS = "LEFT JOIN raw.facts sf ON c.cause_kind = 0 AND sf.fact = c.cause_id AND sf.static"
_DERIVED = "sf.fact IS NULL"


@dataclass(frozen=True)
class RunGraph:
    """What every episode of a run shares: the nodes (ids index `nodes`), the unary and binary predicates
    (name -> label id), and the graph's own edges (node-id pairs; the `edges` table)."""
    nodes: list[str]
    unary: dict[str, int]
    binary: dict[str, int]
    edges: np.ndarray              # [E, 2] int64 source, target

    @classmethod
    def read(cls, con: RunConnection) -> RunGraph:
        """The run's graph; a ValueError (one line) for one too big to draw, counted before it is read."""
        n_nodes, n_edges = con.execute(
            "SELECT (SELECT count(*) FROM raw.nodes), (SELECT count(*) FROM raw.edges) + (SELECT count(*) FROM "
            "raw.atoms a JOIN raw.labels l ON l.label = a.label WHERE l.arity = 2)").fetchall()[0]
        if n_nodes > MAX_NODES or n_edges > MAX_EDGES:
            raise ValueError(f"this run's graph has {n_nodes:,} nodes and up to {n_edges:,} edges; the replay "
                             f"draws at most {MAX_NODES:,} nodes and {MAX_EDGES:,} edges (read the run with "
                             f"tracelab trace, why, sql or the TUI)")
        nodes = [n for (n,) in con.execute("SELECT name FROM raw.nodes ORDER BY node").fetchall()]
        _check_node_ids(con, len(nodes))
        labels = con.execute("SELECT name, label, arity FROM raw.labels ORDER BY name").fetchall()
        e = con.execute("SELECT source, target FROM raw.edges").fetchnumpy()
        edges = np.stack([np.asarray(e["source"], np.int64), np.asarray(e["target"], np.int64)], axis=1)
        return cls(nodes, {n: lid for n, lid, arity in labels if arity == 1},
                   {n: lid for n, lid, arity in labels if arity == 2}, edges.reshape(-1, 2))

    def color_label(self, con: RunConnection, wanted: str | None, episode: int) -> str | None:
        """The predicate whose bound colours the nodes: `wanted` (an unknown name is an UnknownName
        naming the run's unary predicates), else the one with the most changes over nodes in the
        episode, static facts' not counted (unless there are no others); None without any."""
        if wanted is not None:
            if wanted not in self.unary:
                raise UnknownName(unknown_name_message("predicate", wanted, list(self.unary),
                                                       where=" over nodes in this run (--color-by)"))
            return wanted
        for derived in (_DERIVED, "TRUE"):
            rows = con.execute(
                f"SELECT l.name, count(*) AS n FROM raw.changes c JOIN raw.atoms a ON a.atom = c.atom "
                f"JOIN raw.labels l ON l.label = a.label {_STATIC_FACTS} "
                f"WHERE c.episode = ? AND l.arity = 1 AND {derived} "
                f"GROUP BY l.name ORDER BY n DESC, l.name LIMIT 1", [episode]).fetchall()
            if rows:
                return str(rows[0][0])
        return None

    def given_positions(self, con: RunConnection, episode: int) -> np.ndarray | None:
        """[nodes, 2] positions from the nodes' `x` and `y` facts (their lower bound), y up; None unless
        every node has both."""
        if not all(name in self.unary for name in POSITION_LABELS):
            return None
        out = np.full((len(self.nodes), 2), np.nan)
        for axis, name in enumerate(POSITION_LABELS):
            cols = con.execute("SELECT a.arg0, c.new_lower FROM raw.changes c JOIN raw.atoms a ON a.atom = c.atom "
                               "WHERE c.episode = ? AND a.label = ? AND c.t = 0 AND c.cause_kind = 0 ORDER BY c.seq",
                               [episode, self.unary[name]]).fetchnumpy()
            out[np.asarray(cols["arg0"], np.int64), axis] = np.asarray(cols["new_lower"], np.float64)
        if np.isnan(out).any():
            return None
        out[:, 1] *= -1.0                 # the viewer's y grows downwards
        return out


def _check_node_ids(con: RunConnection, n_nodes: int) -> None:
    """Every node id the replay indexes its arrays with (the edges' ends, the atoms' arguments) names one
    of the run's `n_nodes` nodes (-1: no argument): a run from a stranger may hold any number there."""
    (edges, atoms), = con.execute(
        "SELECT (SELECT count(*) FROM raw.edges WHERE coalesce(source NOT BETWEEN 0 AND $n - 1 "
        "OR target NOT BETWEEN 0 AND $n - 1, true)), "
        "(SELECT count(*) FROM raw.atoms WHERE coalesce(arg0 NOT BETWEEN -1 AND $n - 1 "
        "OR arg1 NOT BETWEEN -1 AND $n - 1, true))", {"n": n_nodes}).fetchall()
    if edges or atoms:
        where = f"{edges:,} edges" if edges else f"{atoms:,} atoms"
        raise ValueError(f"this run's {where} name a node id out of range (it has {n_nodes:,} nodes): a "
                         "damaged or hand-made run; the replay cannot draw it")


@dataclass
class Firings:
    """The rule log of an episode: at most MAX_LOGGED_FIRINGS firings a step, in the engine's order, and
    per step how many firings there were in all."""
    t: np.ndarray                  # [F] int64
    rule: list[str]
    head: list[str]
    line: list[str]                # rule(bindings): head old -> new
    per_step: dict[int, int]       # step -> firings in all


@dataclass
class GraphEpisode:
    """One episode as the replay draws it (the colour and edge rows: a run without a board's)."""
    episode: int
    steps: int                     # timesteps drawn: t = 0 .. steps - 1
    outcome: str | None
    color_label: str | None
    color_nodes: np.ndarray               # node ids that have an atom of the colour predicate (may be coloured)
    color_rows: dict[str, np.ndarray]     # the colour predicate's changes: t, node, lower, upper (seq order)
    edge_rows: dict[str, np.ndarray]      # binary atoms' changes: t, label, source, target, lower (seq order)
    firings: Firings
    changed: dict[int, dict[str, int]]    # step -> predicate -> atoms changed in it (derived changes only)


def _bound(lo: float, hi: float) -> str:
    return f"[{lo:g},{hi:g}]"


def read_firings(con: RunConnection, episode: int) -> Firings:
    # one query: the step's count of firings beside each logged one (the window counts before QUALIFY keeps);
    # the bindings' text once per grounding (the `firings` view spells it out per firing: 5x the time)
    rows = con.execute(
        "WITH f AS (SELECT c.seq, c.t, r.name AS rule, c.grounding, a.text AS head, c.old_lower, c.old_upper, "
        "  c.new_lower, c.new_upper, count(*) OVER (PARTITION BY c.t) AS n "
        "  FROM raw.changes c JOIN raw.rules r ON c.cause_kind = 2 AND r.rule = c.cause_id "
        "  LEFT JOIN atoms a ON a.atom = c.atom WHERE c.episode = ? "
        "  QUALIFY row_number() OVER (PARTITION BY c.t ORDER BY c.seq) <= ?), "
        "v AS (SELECT g.grounding, r.variables, unnest(g.var_values) AS node, "
        "  generate_subscripts(g.var_values, 1) AS i FROM raw.groundings g JOIN raw.rules r ON r.rule = g.rule "
        "  WHERE g.grounding IN (SELECT grounding FROM f)), "
        "b AS (SELECT v.grounding, string_agg(v.variables[v.i] || '=' || n.name, ', ' ORDER BY v.i) AS bindings "
        "  FROM v JOIN raw.nodes n ON n.node = v.node GROUP BY v.grounding) "
        "SELECT f.t, f.rule, coalesce(b.bindings, ''), f.head, f.old_lower, f.old_upper, f.new_lower, f.new_upper, "
        "f.n FROM f LEFT JOIN b USING (grounding) ORDER BY f.seq", [episode, MAX_LOGGED_FIRINGS]).fetchall()
    return Firings(np.array([r[0] for r in rows], np.int64), [r[1] for r in rows], [r[3] for r in rows],
                   [f"{r}({b}): {h} {_bound(ol, ou)} -> {_bound(nl, nu)}" for _, r, b, h, ol, ou, nl, nu, _ in rows],
                   {int(r[0]): int(r[8]) for r in rows})


def read_episode(con: RunConnection, graph: RunGraph | None, episode: int, label: str | None,
                 edges: bool = True) -> GraphEpisode:
    """The episode's rows of the colour predicate `label` (None: none), edge rows (`edges`: the graph is
    drawn), rule log and change counts (one query each)."""
    # the timesteps drawn are t = 0 .. the last: an env's episode of n steps ends at t = n (its t = 0 is the
    # start), a reasoning's of n timesteps at t = n - 1, a running episode at its last change so far
    (outcome, t_end, last), = con.execute(
        "SELECT (SELECT any_value(outcome) FROM episodes WHERE episode = $e), "
        "(SELECT any_value(t_end) FROM episodes WHERE episode = $e), "
        "(SELECT max(t) FROM raw.changes WHERE episode = $e)", {"e": episode}).fetchall()
    steps = max(int(last or 0), int(t_end or 0)) + 1
    color_rows: dict[str, np.ndarray] = {"t": np.zeros(0, np.int64), "node": np.zeros(0, np.int64),
                                         "lower": np.zeros(0), "upper": np.zeros(0)}
    color_nodes = np.zeros(0, np.int64)
    if label is not None and graph is not None:
        color_nodes = np.asarray(con.execute("SELECT DISTINCT arg0 FROM raw.atoms WHERE label = ? AND arg0 >= 0",
                                             [graph.unary[label]]).fetchnumpy()["arg0"], np.int64)
        cols = con.execute("SELECT c.t, a.arg0 AS node, c.new_lower AS lower, c.new_upper AS upper "
                           "FROM raw.changes c JOIN raw.atoms a ON a.atom = c.atom "
                           "WHERE c.episode = ? AND a.label = ? ORDER BY c.seq",
                           [episode, graph.unary[label]]).fetchnumpy()
        color_rows = {k: np.asarray(v) for k, v in cols.items()}
    edge_rows = {"t": np.zeros(0, np.int64), "label": np.zeros(0, np.int64), "source": np.zeros(0, np.int64),
                 "target": np.zeros(0, np.int64), "lower": np.zeros(0)}
    if edges:
        cols = con.execute("SELECT c.t, a.label, a.arg0 AS source, a.arg1 AS target, c.new_lower AS lower "
                           "FROM raw.changes c JOIN raw.atoms a ON a.atom = c.atom "
                           "WHERE c.episode = ? AND a.arg1 >= 0 ORDER BY c.seq", [episode]).fetchnumpy()
        edge_rows = {k: np.asarray(v) for k, v in cols.items()}
    changed: dict[int, dict[str, int]] = {}
    for t, name, n in con.execute(
            f"SELECT c.t, l.name, count(DISTINCT c.atom) FROM raw.changes c JOIN raw.atoms a ON a.atom = c.atom "
            f"JOIN raw.labels l ON l.label = a.label {_STATIC_FACTS} WHERE c.episode = ? AND {_DERIVED} "
            f"GROUP BY c.t, l.name ORDER BY c.t, 3 DESC, l.name", [episode]).fetchall():
        changed.setdefault(int(t), {})[str(name)] = int(n)
    return GraphEpisode(episode, steps, outcome, label, color_nodes, color_rows, edge_rows, read_firings(con, episode),
                        changed)
