"""The rules' side of a replay, any run's: every firing as a TextLog line (its level is the rule, so the
log view filters by rule), a markdown document per step (what changed, what fired, the rewards, and the
why-tree of each atom `--why` names and of each piece that died on the board, as `tracelab why` prints
it), and per predicate how many of its atoms changed in each step."""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable

import numpy as np
import rerun as rr
from tracelab.viewers.replay import style
from tracelab.viewers.replay.columns import send_per_entity
from tracelab.viewers.replay.graph_run import GraphEpisode

from tracelab.store.coordinates import run_grid
from tracelab.store.episode import EpisodeTrace
from tracelab.store.model import RunModel
from tracelab.store.reader import RunConnection
from tracelab.store.why import WhyNode, explain_in, render_why
from tracelab.engine.terminal_text import printable
from tracelab.viewers.replay.markdown_text import code_block, literal

MORE = "more"   # the level of the line that counts a step's firings past the log's limit


def no_edges(step: int) -> dict[str, int]:
    """The edges per predicate of a run drawn on its board (none: the graph is not drawn)."""
    return {}


def log_rule_log(rec: rr.RecordingStream, episode: GraphEpisode) -> None:
    f = episode.firings
    steps, levels, lines = f.t.tolist(), list(f.rule), list(f.line)
    for s, n in sorted(f.per_step.items()):
        logged = int((f.t == s).sum())
        if n > logged:
            steps.append(s)
            levels.append(MORE)
            lines.append(f"... and {n - logged:,} more firings at t={s} "
                         f"(tracelab trace RUN --episode {episode.episode} --from {s} --to {s})")
    if not lines:
        return
    order = np.argsort(np.asarray(steps), kind="stable")
    rec.send_columns(style.RULE_LOG, indexes=[rr.TimeColumn(style.STEP, sequence=np.asarray(steps)[order])],
                     columns=rr.TextLog.columns(text=[printable(lines[i]) for i in order],
                                                level=[printable(levels[i]) for i in order]))


def log_changed(rec: rr.RecordingStream, episode: GraphEpisode) -> None:
    """Per predicate that changed in the episode, how many of its atoms changed at each step; the colour
    predicate's line in the nodes' red, the others in the palette's colours."""
    labels = sorted({name for per in episode.changed.values() for name in per})
    if not labels:
        return
    others = iter(style.SERIES_COLORS * (len(labels) // len(style.SERIES_COLORS) + 1))
    for name in labels:
        colour = tuple(style.BOUND_TRUE.astype(int)) if name == episode.color_label else next(others)
        rec.log(f"{style.CHANGED}/{name}", rr.SeriesLines(colors=[colour], names=name, widths=2.0), static=True)
    steps = np.arange(episode.steps)
    counts = [np.array([episode.changed.get(s, {}).get(name, 0) for s in steps.tolist()]) for name in labels]
    every = np.tile(steps, len(labels))
    send_per_entity(rec, [f"{style.CHANGED}/{name}" for name in labels], [len(steps)] * len(labels),
                    [rr.TimeColumn(style.STEP, sequence=every)],
                    rr.Scalars.columns(scalars=np.concatenate(counts).astype(np.float64)))


def check_atoms(model: RunModel, atoms: tuple[str, ...]) -> None:
    """Each atom `--why` names must be a ground atom of the run (the store's own errors, one line)."""
    for atom in atoms:
        try:
            model.parse_atom(atom)
        except (KeyError, ValueError) as e:
            msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
            raise ValueError(f"--why {atom}: {msg}") from None


def _per_step(episode: GraphEpisode) -> tuple[dict[int, Counter[str]], dict[int, str]]:
    """Each step's logged firings per rule, and the first head a step's rules set that can be quoted (a
    backtick would end the code span): one pass over the log, not one a step."""
    fired: dict[int, Counter[str]] = {}
    example: dict[int, str] = {}
    for rule, head, t in zip(episode.firings.rule, episode.firings.head, episode.firings.t.tolist()):
        fired.setdefault(t, Counter())[rule] += 1
        if t not in example and "`" not in head:
            example[t] = head
    return fired, example


def _step_header(episode: GraphEpisode, s: int, edges: dict[str, int], notes: list[str]) -> list[str]:
    last = episode.steps - 1
    lines = [f"## Episode {episode.episode}, step {s} of {last}"]
    if s == last and episode.outcome:
        lines.append(f"**It ended: {literal(episode.outcome)}.**\n")
    lines += notes
    if edges:
        lines.append("- edges: " + ", ".join(f"{literal(name)} {n:,}" for name, n in edges.items()))
    return lines


def _step_counts(episode: GraphEpisode, s: int, fired: Counter[str]) -> list[str]:
    """What changed and fired in step s, per predicate and rule: long lists, so they come after the step's
    why-trees (a panel's first screen shows the why of a death, not the tally)."""
    changed = episode.changed.get(s, {})
    lines = ["\n### Changed and fired",
             "- changed: " + (", ".join(f"{literal(name)} {n:,}" for name, n in changed.items()) or "nothing")]
    total = episode.firings.per_step.get(s, 0)
    if total:
        lines.append(f"- fired: {total:,} (" + ", ".join(f"{literal(r)} {n:,}" for r, n in fired.most_common()) + ")")
    return lines


def why_documents(con: RunConnection, episode: GraphEpisode, atoms: tuple[str, ...], depth: int = 6,
                  model: Callable[[], RunModel] | None = None,
                  edges: Callable[[int], dict[str, int]] = no_edges,
                  at_step: dict[int, list[str]] | None = None,
                  notes: dict[int, list[str]] | None = None) -> list[str]:
    """A markdown document per step 0 .. steps-1: `notes[step]` (a game's actions and rewards), the
    edges per predicate (`edges(step)`), what changed and fired, the why-tree of each of `atoms` at the end
    of the step (a tree is explained again only when its atom changed) and of each of `at_step[step]` (a
    piece's death, in that step only)."""
    at_step, notes = at_step or {}, notes or {}
    trace = None
    if atoms or at_step:
        run_model = model() if model else RunModel(con)
        trace = EpisodeTrace(con, episode.episode)
        run_model.prefetch_groundings(np.unique(trace.c["grounding"]))
        ids = {a: run_model.parse_atom(a) for a in atoms}
    grid = run_grid(con)     # a run's cell ids with their (x, y), as `tracelab why` shows them
    trees: dict[tuple[str, int], WhyNode] = {}
    docs = []
    fired, examples = _per_step(episode)
    for s in range(episode.steps):
        lines = _step_header(episode, s, edges(s), notes.get(s, []))
        for atom in at_step.get(s, []):
            lines += [f"\n### Why {literal(atom)}",
                      *code_block(render_why(explain_in(run_model, trace, atom, s, depth), s, grid))]
        for atom in atoms:
            last = trace.last_at_end_of(ids[atom], s)
            key = (atom, -1 if last is None else last.index)
            if key not in trees:
                trees[key] = explain_in(run_model, trace, atom, s, depth)
            lines += [f"\n### Why {literal(atom)}", *code_block(render_why(trees[key], s, grid))]
        lines += _step_counts(episode, s, fired.get(s, Counter()))
        if not atoms and examples.get(s):
            lines.append(f"\nAsk why an atom has its bound: `tracelab replay RUN --why '{examples[s]}'`.")
        docs.append("\n".join(lines))
    return docs


def log_why(rec: rr.RecordingStream, con: RunConnection, episode: GraphEpisode, atoms: tuple[str, ...],
            depth: int = 6, model: Callable[[], RunModel] | None = None,
            edges: Callable[[int], dict[str, int]] = no_edges, at_step: dict[int, list[str]] | None = None,
            notes: dict[int, list[str]] | None = None) -> None:
    docs = why_documents(con, episode, atoms, depth, model, edges, at_step, notes)
    rec.send_columns(style.WHY, indexes=[rr.TimeColumn(style.STEP, sequence=np.arange(len(docs)))],
                     columns=rr.TextDocument.columns(text=[printable(d, keep="\n\t") for d in docs],
                                                     media_type=["text/markdown"] * len(docs)))
