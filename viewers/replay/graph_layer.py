"""The graph of a run without a board, drawn with rerun's graph archetypes in one entity (/graph): the
nodes (GraphNodes, at fixed positions, coloured by one predicate's bound) and the edges (GraphEdges,
directed: the pairs of the binary atoms whose lower bound is above 0). A row is logged only at the steps
where a node's colour or the set of edges changed (a colour row holds every node's colour: a GraphNodes
batch is one array).

Edge labels: rerun 0.41's GraphEdges has no label and no colour, and a graph view draws each entity's
graph in a frame of its own and joins edges only to their own entity's nodes, so the edges cannot be
split into one entity per predicate without frames and copies of the nodes. A small graph (at most
SHOWN_NODE_LABELS nodes, where names are drawn) gets a label node on each pair of nodes with edges, 40%
of the way from the source (so a pair's two directions do not overlap), naming the predicates of the
edges it has at that step; a bigger graph's edge labels would be unreadable, and the step document
counts its edges per predicate instead."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.graph_run import GraphEpisode, RunGraph

UNLABELLED = "edge"       # the graph's own edges that no binary predicate holds (GraphML without attributes)
LABEL_AT = 0.4            # where an edge's label sits, from its source


def _last_per_key(keys: np.ndarray) -> np.ndarray:
    """Indices of the last occurrence of each key (rows in seq order: the last change wins)."""
    _, first_of_reversed = np.unique(keys[::-1], return_index=True)
    return np.sort(len(keys) - 1 - first_of_reversed)


@dataclass
class GraphSteps:
    """The episode's graph at the steps where it changed: `steps` (0 first), and the edges (indices into
    `pairs`) at those of them in `edges_on`."""
    steps: np.ndarray                     # [S] int64
    pairs: np.ndarray                     # [P, 2] node ids: every edge the episode ever has
    pair_label: list[str]                 # [P] its predicate
    edges_on: dict[int, np.ndarray]       # step -> bool [P], at the steps where the edges changed

    def edge_counts(self, step: int) -> dict[str, int]:
        """predicate -> its edges at the end of `step`, most first."""
        changed = [s for s in self.edges_on if s <= step]
        if not changed:
            return {}
        on = self.edges_on[max(changed)]
        names, counts = np.unique(np.array(self.pair_label, dtype=object)[on].astype(str), return_counts=True)
        order = np.lexsort((names, -counts))
        return {str(names[i]): int(counts[i]) for i in order}


def node_colors(episode: GraphEpisode, n: int, steps: np.ndarray) -> list[np.ndarray]:
    """[n, 3] uint8 colours of the nodes at the end of each of `steps` (ascending, every step where the
    colour predicate changed among them), built one step at a time from its changes."""
    rows = episode.color_rows
    t, node = rows["t"].astype(np.int64), rows["node"].astype(np.int64)
    lower, upper = np.zeros(n), np.ones(n)
    colours = style.bound_colors(lower, upper)
    bounds = np.searchsorted(t, steps, side="left").tolist() + [len(t)]
    out = []
    for i in range(len(steps)):
        at = np.arange(bounds[i], bounds[i + 1])
        at = at[_last_per_key(node[at])] if len(at) else at
        changed = node[at]
        lower[changed], upper[changed] = rows["lower"][at], rows["upper"][at]
        colours[changed] = style.bound_colors(lower[changed], upper[changed])
        out.append(colours.copy())
    return out


def graph_steps(episode: GraphEpisode, graph: RunGraph) -> GraphSteps:
    """The graph's changes over the episode (see GraphSteps): the graph's own edges that no binary
    predicate holds at step 0 are UNLABELLED edges for the whole episode."""
    n = max(len(graph.nodes), 1)
    rows = episode.edge_rows
    label_names = {lid: name for name, lid in graph.binary.items()}
    key = rows["label"].astype(np.int64) * n * n + rows["source"].astype(np.int64) * n + rows["target"]
    keys, which = np.unique(key, return_inverse=True)
    which = which.reshape(-1)
    on = np.zeros(len(keys), dtype=bool)
    edges_on: dict[int, np.ndarray] = {}
    t = rows["t"].astype(np.int64)
    for s in np.unique(t).tolist():
        at = np.flatnonzero(t == s)
        at = at[_last_per_key(which[at])]
        now = on.copy()
        now[which[at]] = rows["lower"][at] > 0
        if s == 0 or not np.array_equal(now, on):
            edges_on[s] = now
        on = now
    pairs = np.stack([(keys // n) % n, keys % n], axis=1)
    labels = [label_names.get(int(k // (n * n)), "?") for k in keys.tolist()]
    first = edges_on.get(0, np.zeros(len(keys), dtype=bool))
    if len(graph.edges):
        held = pairs[first, 0] * n + pairs[first, 1]
        bare = graph.edges[~np.isin(graph.edges[:, 0] * n + graph.edges[:, 1], held)]
        if len(bare):
            pairs = np.concatenate([pairs, bare])
            labels += [UNLABELLED] * len(bare)
            edges_on = {s: np.r_[v, np.ones(len(bare), dtype=bool)] for s, v in edges_on.items()}
            edges_on.setdefault(0, np.r_[np.zeros(len(keys), dtype=bool), np.ones(len(bare), dtype=bool)])
    steps = np.unique(np.r_[0, episode.color_rows["t"].astype(np.int64), list(edges_on)]).astype(np.int64)
    return GraphSteps(steps, pairs.astype(np.int64), labels, edges_on)


def edge_labels(names: np.ndarray, positions: np.ndarray, pairs: np.ndarray, labels: list[str]
                ) -> tuple[list[str], list[str], np.ndarray]:
    """One label node per directed pair of nodes with edges: its id `a->b`, its text the pair's
    predicates (`link, near`: several on one spot would hide each other), placed LABEL_AT along it."""
    texts: dict[tuple[int, int], list[str]] = {}
    for (a, b), label in zip(pairs.tolist(), labels):
        texts.setdefault((a, b), []).append(label)
    ends = np.array(list(texts), np.int64).reshape(-1, 2)
    where = positions[ends[:, 0]] + (positions[ends[:, 1]] - positions[ends[:, 0]]) * LABEL_AT
    return ([f"{names[a]}->{names[b]}" for a, b in texts], [", ".join(sorted(t)) for t in texts.values()],
            where)


def log_graph(rec: rr.RecordingStream, graph: RunGraph, positions: np.ndarray, episode: GraphEpisode) -> GraphSteps:
    """The nodes (ids, positions, names: static; colours: over the steps) and the edges over the steps.
    A small graph's nodes also carry its edges' labels, those of the edges present at each step (its
    nodes are logged again at each step where something changed: a few dozen)."""
    g = graph_steps(episode, graph)
    names = np.array(graph.nodes, dtype=object)
    small = len(names) <= style.SHOWN_NODE_LABELS
    colours = node_colors(episode, len(names), g.steps)
    times = [rr.TimeColumn(style.STEP, sequence=g.steps)]
    # a node without an atom of the colour predicate can never be coloured: drawn small
    radii = np.full(len(names), style.UNCOLOURED_RADIUS, np.float32)
    radii[episode.color_nodes[episode.color_nodes < len(names)]] = style.NODE_RADIUS
    rec.log(style.GRAPH, rr.GraphEdges.from_fields(graph_type="directed"), static=True)
    if small:
        ids, labels, where, sizes, sized = [], [], [], [], []
        on = np.zeros(len(g.pairs), dtype=bool)
        for s in g.steps.tolist():
            on = g.edges_on.get(s, on)
            pair_ids, texts, spots = edge_labels(names, positions, g.pairs[on],
                                                 np.array(g.pair_label, dtype=object)[on].tolist())
            ids += names.tolist() + pair_ids
            labels += names.tolist() + texts
            where.append(np.concatenate([positions, spots]))
            sizes.append(len(names) + len(pair_ids))
            sized.append(np.r_[radii, np.full(len(pair_ids), style.UNCOLOURED_RADIUS, np.float32)])
        label_colour = np.array(style.EDGE_LABEL_COLOR, np.uint8)
        colours = [np.concatenate([c, np.repeat(label_colour[None], size - len(c), axis=0)])
                   for c, size in zip(colours, sizes)]
        rec.log(style.GRAPH, rr.GraphNodes.from_fields(show_labels=True), static=True)
        rec.send_columns(style.GRAPH, indexes=times, columns=rr.GraphNodes.columns(
            node_ids=ids, labels=labels, positions=np.concatenate(where).astype(np.float32),
            colors=np.concatenate(colours), radii=np.concatenate(sized)).partition(sizes))
    else:
        rec.log(style.GRAPH, rr.GraphNodes(node_ids=names.tolist(), positions=positions, labels=names.tolist(),
                                           show_labels=False, radii=radii), static=True)
        rec.send_columns(style.GRAPH, indexes=times, columns=rr.GraphNodes.columns(
            colors=np.concatenate(colours)).partition([len(c) for c in colours]))
    edge_steps = sorted(g.edges_on)
    if edge_steps:
        sets = [g.pairs[g.edges_on[s]] for s in edge_steps]
        rec.send_columns(style.GRAPH, indexes=[rr.TimeColumn(style.STEP, sequence=edge_steps)],
                         columns=rr.GraphEdges.columns(edges=names[np.concatenate(sets)].tolist()).partition(
                             [len(p) for p in sets]))
    return g
