"""What a run without a board shows beside its trace, as queries: the atoms true (or changed) at a
timestep of an episode, and an atom's neighbourhood in the graph (the edges of its node(s) and their
labels). Every answer is one bounded query through the store's read-only path (RunSource): the atoms
are aggregated in DuckDB and at most `limit` rows come back with the count of all, so a run of millions
of changes costs a scan of its changes up to t, never a Python object per change."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from tracelab.store.names import UnknownName, check_name
from tracelab.store.static_facts import STATIC_ROW_SQL
from tracelab.viewers.tui.source import RunSource

ATOMS_LIMIT = 500       # atoms listed at one timestep (the count says how many there are)
EDGES_LIMIT = 40        # neighbours listed per node
MODES = ("true", "changed")


def pattern_clause(pattern: str) -> str:
    """SQL for the atom ids a filter names: `exposed(*)` (a GLOB on the atom's text, as the trace's atom
    filter), or a bare predicate name or GLOB, `exposed`, `exp*` (a GLOB on its label)."""
    if "(" in pattern:
        return "atom IN (SELECT atom FROM atoms WHERE text GLOB $pattern)"
    return ("atom IN (SELECT a.atom FROM raw.atoms a JOIN raw.labels l USING (label) "
            "WHERE l.name GLOB $pattern)")


def unknown_pattern(source: RunSource, pattern: str) -> str | None:
    """Why `pattern` matches no atom of the run (did you mean, how to write one), or None if some match."""
    kind = "atom" if "(" in pattern else "label"
    try:
        source.call(lambda con: check_name(con, kind, pattern))
    except UnknownName as e:
        return str(e)
    return None


@dataclass
class AtomsAt:
    """The atoms at timestep `t` of an episode: `rows` (at most the limit) of `total`, and how many were
    left out as set by static facts."""
    episode: int
    t: int
    mode: str
    rows: list[dict[str, Any]] = field(default_factory=list)
    total: int = 0
    static_hidden: int = 0

    @property
    def truncated(self) -> bool:
        return self.total > len(self.rows)


def atoms_at(source: RunSource, episode: int, t: int, mode: str = "true", pattern: str = "",
             hide_static: bool = True, limit: int = ATOMS_LIMIT) -> AtomsAt:
    """The atoms of `episode` true at the end of timestep t (mode "true": lower bound > 0, with their
    bound and the t of their last change) or changed during t (mode "changed": the bound before t and at
    its end), in text order, at most `limit`. hide_static leaves out atoms last set by a static fact."""
    if mode not in MODES:
        raise ValueError(f"mode is one of {', '.join(MODES)}, not {mode!r}")
    where = ["episode = $episode", "t <= $t" if mode == "true" else "t = $t"]
    params: dict[str, Any] = {"episode": episode, "t": t}
    if pattern:
        where.append(pattern_clause(pattern))
        params["pattern"] = pattern
    keep = "lower > 0" if mode == "true" else "TRUE"
    shown = "NOT static" if hide_static else "TRUE"
    sql = f"""
    WITH last AS (
        SELECT atom, arg_min(old_lower, seq) AS old_lower, arg_min(old_upper, seq) AS old_upper,
               arg_max(new_lower, seq) AS lower, arg_max(new_upper, seq) AS upper,
               arg_max(cause_kind, seq) AS cause_kind, arg_max(cause_id, seq) AS cause_id, max(t) AS last_t
        FROM raw.changes WHERE {' AND '.join(where)} GROUP BY atom),
    kept AS MATERIALIZED (SELECT *, {STATIC_ROW_SQL} AS static FROM last WHERE {keep}),
    counts AS (SELECT count(*) FILTER (WHERE {shown}) AS total,
                      count(*) FILTER (WHERE NOT ({shown})) AS hidden FROM kept),
    top AS (SELECT k.atom AS atom_id, a.text AS atom, a.label, k.old_lower, k.old_upper, k.lower, k.upper,
                   k.last_t
            FROM kept k JOIN atoms a ON a.atom = k.atom WHERE {shown}
            ORDER BY a.text, k.atom LIMIT {int(limit)})
    SELECT * FROM counts LEFT JOIN top ON TRUE ORDER BY top.atom, top.atom_id
    """
    rows = source.rows(sql, params)
    first = rows[0] if rows else {"total": 0, "hidden": 0}
    listed = [{k: v for k, v in r.items() if k not in ("total", "hidden")} for r in rows if r["atom_id"] is not None]
    return AtomsAt(episode, t, mode, listed, int(first["total"]), int(first["hidden"]))


@dataclass
class Neighbour:
    """One node next to the node: the direction of the pair (`out` node→other, `in` other→node, `both`),
    whether the graph has an edge there, the labels on the pair with their bounds at t, and the other
    node's own labels set at t (not [0,1])."""
    other: str
    direction: str
    edge: bool
    labels: list[tuple[str, float, float]]
    other_labels: list[tuple[str, float, float]] = field(default_factory=list)


@dataclass
class NodeView:
    """A node of the atom, its own labels (unary atoms set at t) and its neighbours (at most the limit of
    `degree`)."""
    node: str
    labels: list[tuple[str, float, float]]
    neighbours: list[Neighbour]
    degree: int


@dataclass
class Neighbourhood:
    atom: str
    t: int
    nodes: list[NodeView]


_BOUNDS_SQL = """
SELECT atom, arg_max(new_lower, seq) AS lower, arg_max(new_upper, seq) AS upper
FROM raw.changes WHERE episode = $episode AND t <= $t AND atom IN (SELECT unnest($atoms)) GROUP BY atom
"""

# The pairs around node $node: the graph's edges (stored both ways when undirected) and the binary atoms
# about the node (a run without a graph file has only these), each with its direction and label atoms.
_PAIRS_SQL = """
WITH pairs AS (
    SELECT target AS other, 'out' AS dir, true AS edge, NULL AS atom FROM raw.edges WHERE source = $node
    UNION ALL SELECT source, 'in', true, NULL FROM raw.edges WHERE target = $node
    UNION ALL SELECT arg1, 'out', false, atom FROM raw.atoms WHERE arg0 = $node AND arg1 >= 0
    UNION ALL SELECT arg0, 'in', false, atom FROM raw.atoms WHERE arg1 = $node AND arg0 <> $node),
per_other AS (
    SELECT other, bool_or(dir = 'out') AS has_out, bool_or(dir = 'in') AS has_in, bool_or(edge) AS edge,
           list(DISTINCT atom) FILTER (WHERE atom IS NOT NULL) AS atoms
    FROM pairs GROUP BY other)
SELECT p.other AS other_id, n.name AS other, p.has_out, p.has_in, p.edge, p.atoms, count(*) OVER () AS degree
FROM per_other p JOIN raw.nodes n ON n.node = p.other
ORDER BY n.name, p.other LIMIT $limit
"""


def neighbourhood(source: RunSource, episode: int, t: int, atom_id: int,
                  limit: int = EDGES_LIMIT) -> Neighbourhood:
    """The node(s) atom `atom_id` is about, each with its labels set at the end of t and its neighbours
    (sorted by name, at most `limit`), each pair's label atoms and the neighbour's own labels with their
    bounds at t."""
    head = source.rows("SELECT a.arg0, a.arg1, t.text FROM raw.atoms a JOIN atoms t USING (atom) "
                       "WHERE a.atom = $atom", {"atom": atom_id})
    if not head:
        return Neighbourhood(f"atom #{atom_id}", t, [])
    node_ids = [n for n in (head[0]["arg0"], head[0]["arg1"]) if n is not None and n >= 0]
    found: list[tuple[int, str, list[dict[str, Any]], list[dict[str, Any]]]] = []
    wanted: set[int] = set()
    for node in dict.fromkeys(node_ids):
        name = source.scalar("SELECT name FROM raw.nodes WHERE node = $node", {"node": node})
        pairs = source.rows(_PAIRS_SQL, {"node": node, "limit": limit})
        wanted.update(int(a) for r in pairs for a in r["atoms"] or [])
        found.append((node, str(name), pairs))
    # the unary atoms of the node(s) and of their listed neighbours, by node
    around = sorted({n for n, _, _ in found} | {int(r["other_id"]) for _, _, pairs in found for r in pairs})
    unary: dict[int, list[int]] = {}
    for r in source.rows("SELECT atom, arg0 FROM raw.atoms WHERE arg1 < 0 AND arg0 IN (SELECT unnest($nodes)) "
                         "ORDER BY arg0, atom", {"nodes": around}):
        unary.setdefault(int(r["arg0"]), []).append(int(r["atom"]))
        wanted.add(int(r["atom"]))
    bounds = {int(r["atom"]): (r["lower"], r["upper"]) for r in source.rows(
        _BOUNDS_SQL, {"episode": episode, "t": t, "atoms": sorted(wanted)})} if wanted else {}
    labels_of = {int(r["atom"]): r["label"] for r in source.rows(
        "SELECT a.atom, l.name AS label FROM raw.atoms a JOIN raw.labels l USING (label) "
        "WHERE a.atom IN (SELECT unnest($atoms))", {"atoms": sorted(wanted)})} if wanted else {}

    def labelled(atoms: list[int]) -> list[tuple[str, float, float]]:
        out = [(labels_of[a], *bounds.get(a, (0.0, 1.0))) for a in atoms]
        return sorted(out)

    def own(node: int) -> list[tuple[str, float, float]]:
        return [lab for lab in labelled(unary.get(node, [])) if (lab[1], lab[2]) != (0.0, 1.0)]

    nodes = []
    for node, name, pairs in found:
        neighbours = [Neighbour(str(r["other"]), "both" if r["has_out"] and r["has_in"] else
                                "out" if r["has_out"] else "in", bool(r["edge"]),
                                labelled([int(a) for a in r["atoms"] or []]), own(int(r["other_id"])))
                      for r in pairs]
        nodes.append(NodeView(name, own(node), neighbours, int(pairs[0]["degree"]) if pairs else 0))
    return Neighbourhood(str(head[0]["text"]), t, nodes)
