"""Reasoning: a rule program run over a graph for some timesteps, as `tracelab reason` does it: printed,
or recorded into a run of the trace store (tracelab.store.reasoning.ReasoningRecorder).

- `load_inputs` reads the program, the graph and the facts, in tracelab's language or PyReason's files.
- `plan_episodes`: one reasoning is one episode. `repeat` runs it several times; a fact table with an
  `episode` column gives facts that hold in one episode only (empty: in every one), and each of its
  episodes runs with its own. Every episode's engine is given *every* fact, those of the other episodes
  with a window that never opens (they set nothing, but are counted as settable): so all episodes ground
  the same atoms in the same order, and share one vocabulary, one grounding table and one fact
  numbering, which a run of the store holds once.
- `EpisodeRun` builds one episode's engine and steps it, handing its trace rows to a recorder in chunks
  (or to the caller after every step, when it prints them).

Library code: nothing here prints (the command does)."""
from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.engine.errors import is_interrupt

# deferred: the engine's readers and Engine (numba), the PyReason translator (numba) and the store (DuckDB, pyarrow)
# load where they are used: import tracelab.pyreason needs no engine, the tracelab dialect no translator, a printed
# reasoning no store


@dataclass(frozen=True)
class Source:
    """A file a reasoning read: `role` rules, facts, graph or facts-table."""
    role: str
    path: str


@dataclass
class ReasoningInputs:
    program: Any                  # tracelab.engine.program.Program
    graph: Any                    # tracelab.engine.Graph (GraphML, then fact tables), or None
    names: Any                    # PyReason's name map (dialect pyreason), else None
    graph_facts: int              # how many of the graph's facts came from the GraphML file
    dialect: str
    sources: list[Source] = field(default_factory=list)
    translation: str | None = None  # the tracelab program text a PyReason program became


def load_inputs(program_files: Sequence[str], *, dialect: str = "tracelab", graph_file: str | None = None,
                fact_files: Sequence[str] = (), fact_tables: Sequence[str] = (),
                persistent: bool = False) -> ReasoningInputs:
    """Read and check the program, graph and facts (errors are the engine's located ones)."""
    from tracelab.engine import check_program, load_fact_table, load_graphml, load_program
    names, translation = None, None
    if dialect == "pyreason":
        from tracelab.pyreason.translate import load_pyreason
        translated = load_pyreason(program_files, fact_files, graph_file, persistent=persistent)
        program, graph, names = translated.program, translated.graph, translated.names
        translation = translated.text
    elif dialect == "tracelab":
        if persistent:
            raise ValueError("persistent belongs to the pyreason dialect (tracelab programs say %timesteps)")
        program = load_program(*program_files, *fact_files)
        graph = load_graphml(graph_file) if graph_file else None
    else:
        raise ValueError(f"unknown dialect {dialect!r}; choose tracelab or pyreason")
    graph_facts = graph.n_facts if graph is not None else 0
    for table in fact_tables:
        facts = load_fact_table(table)
        graph = facts if graph is None else graph.concat(facts)
    if graph is not None:  # what the graph sets is set: no "never set" warnings, arities must agree
        check_program(program, graph.predicates())
    sources = [*(Source("rules", p) for p in program_files), *(Source("facts", p) for p in fact_files),
               *([Source("graph", graph_file)] if graph_file else []),
               *(Source("facts-table", p) for p in fact_tables)]
    return ReasoningInputs(program, graph, names, graph_facts, dialect, sources, translation)


# ---- episodes ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EpisodePlan:
    episode: int                  # the episode's id in the run
    graph: Any                    # the graph its engine gets (other episodes' facts never applied)
    info: dict[str, Any]          # what the run's episode_begin.info says of it


def fact_episodes(graph: Any) -> list[int]:
    """The episodes a fact table's `episode` column names, in order (empty: it has none)."""
    if graph is None or graph.fact_episode is None:
        return []
    return sorted(set(np.unique(graph.fact_episode).tolist()) - {-1})


def plan_episodes(inputs: ReasoningInputs, repeat: int = 1) -> list[EpisodePlan]:
    """The episodes to run: `repeat` of the one reasoning (ids 0..repeat-1), or one per episode a fact
    table names (with the facts of that episode and those of every episode)."""
    if repeat < 1:
        raise ValueError(f"repeat must be at least 1, got {repeat}")
    named = fact_episodes(inputs.graph)
    if named and repeat > 1:
        raise ValueError(f"a fact table's episode column gives the episodes ({len(named)}: "
                         f"{', '.join(map(str, named[:5]))}{', ...' if len(named) > 5 else ''}); "
                         "--repeat gives them too: use one or the other")
    if not named:
        return [EpisodePlan(r, inputs.graph, {"repeat": r} if repeat > 1 else {}) for r in range(repeat)]
    return [EpisodePlan(e, episode_graph(inputs.graph, e), {"facts_episode": e}) for e in named]


def episode_graph(graph: Any, episode: int) -> Any:
    """`graph` with the facts of other episodes made inert: a window that never opens (start 0, end -1,
    not static), so that the engine counts their atoms as settable but sets nothing with them."""
    other = (graph.episodes >= 0) & (graph.episodes != episode)
    windows = graph.windows.copy()
    windows[other] = (0, -1)
    statics = graph.statics & ~other
    return replace(graph, fact_window=windows, fact_static=statics)


# ---- running an episode --------------------------------------------------------------------------------

class EpisodeRun:
    """One episode's engine (built here: grounding, and compiling on a cold cache, happen in the
    constructor and the first step), stepped by `steps()`. With a recorder (ReasoningRecorder) the
    trace goes to the store; `finish()` ends the episode there and says how it ended."""

    def __init__(self, inputs: ReasoningInputs, plan: EpisodePlan, *, trace: bool = True, kernel: str = "auto",
                 recorder: Any = None) -> None:
        from tracelab.engine import Engine
        self.plan = plan
        self.recorder = recorder
        if recorder is not None:  # the program and facts first: written while the engine grounds
            recorder.begin_run(inputs.program, inputs.graph)
        self.engine = Engine(inputs.program, plan.graph, trace=trace or recorder is not None, kernel=kernel)
        self.steps_run = 0
        self._quiet_steps = 0  # steps in a row, up to the last, that changed nothing
        # a delayed rule's firings read the state of `delay` steps before: that many quiet steps more
        self._quiet_needed = 1 + max((r.delay for r in inputs.program.rules), default=0)
        self._last_fact_start = _last_fact_start(inputs.program, plan.graph)
        if recorder is not None:
            recorder.begin_episode(plan.episode, self.engine, plan.info)

    def steps(self, steps: int, rows_each_step: bool = False) -> Iterator[tuple[int, dict[str, np.ndarray] | None]]:
        """Step the engine `steps` times, yielding (t, rows) after each step: rows are the step's trace
        rows when `rows_each_step` (they go to the recorder too), else None (the recorder takes them in
        chunks, as the envs' tracer does)."""
        engine = self.engine
        for t in range(steps):
            before = int(engine.stats["changes"][0])
            try:
                engine.step()
            except BaseException as e:  # an inconsistency, no fixpoint, Ctrl-C: the run keeps what happened
                self._end_after(e, t + 1)
                raise
            self.steps_run += 1
            self._quiet_steps = self._quiet_steps + 1 if int(engine.stats["changes"][0]) == before else 0
            rows = None
            if rows_each_step:
                rows = engine.take_trace()
                if self.recorder is not None:
                    self.recorder.write(engine, rows)
            elif self.recorder is not None:
                self.recorder.stepped(engine)
            yield t, rows

    @property
    def converged(self) -> bool:
        """Further steps would change nothing: the last 1 + (the longest rule delay) steps changed
        nothing (so every firing still scheduled read a state that is the state now, and the same
        firings changed nothing), and no fact's window opens later."""
        return self._quiet_steps >= self._quiet_needed and self._last_fact_start < self.steps_run

    def _end_after(self, error: BaseException, steps: int) -> None:
        """A step raised: record the rows up to it and end the episode `failed` (or `interrupted`)."""
        if self.recorder is None:
            return
        outcome = "interrupted" if is_interrupt(error) else "failed"
        try:
            self.recorder.end_episode(self.plan.episode, self.engine, steps=steps, outcome=outcome,
                                      info={"error": str(error) or type(error).__name__, "kernel": self.engine.kernel})
        except Exception:  # noqa: BLE001 - a writer that failed too: the step's error is the one to report
            pass

    def finish(self) -> str:
        """The episode's outcome: `converged` (see there), or `stopped` (it ran its steps and may have
        changed further); recorded with the engine's counters when there is a recorder. (A step that
        raised ended a recorded episode `failed` or `interrupted`, with its error and the rows up to it.)"""
        outcome = "converged" if self.converged else "stopped"
        if self.recorder is not None:
            stats = {k: int(np.sum(v)) for k, v in self.engine.stats.items()}
            self.recorder.end_episode(self.plan.episode, self.engine, steps=self.steps_run, outcome=outcome,
                                      info={"kernel": self.engine.kernel, "stats": stats})
        return outcome


def _last_fact_start(program: Any, graph: Any) -> int:
    """The latest time a fact's window opens (-1: none), inert facts (end < start) left out."""
    starts = [f.start for f in program.facts]
    if graph is not None and graph.fact_window is not None:
        w = graph.fact_window
        live = w[:, 1] >= w[:, 0]
        if live.any():
            starts.append(int(w[live, 0].max()))
    return max(starts, default=-1)


# ---- what a run records of the reasoning -------------------------------------------------------------

def run_meta(inputs: ReasoningInputs, command: str, settings: dict[str, Any],
             sources: Sequence[dict[str, Any]] = ()) -> dict[str, Any]:
    """The run's metadata (tracelab.store.RunMeta fields): the command, the settings, the program's
    files and a PyReason program's translation (`sources`: their run_sources rows, by path, size and hash;
    their texts go in the run's `sources` table), the graph and fact tables by path and size. No board: a
    reasoning run's episodes are a trace, not games."""
    from tracelab.store.sources import source_summaries
    read = {(r["role"], r["path"]): r for r in source_summaries(sources)}
    listed = [read.pop((s.role, s.path), None) or {"role": s.role, "path": s.path, "bytes": _size(s.path)}
              for s in inputs.sources]
    config = {**settings, "dialect": inputs.dialect, "sources": [*listed, *read.values()]}  # then the translation
    if inputs.graph is not None:
        config["graph"] = {"nodes": len(inputs.graph.nodes), "edges": int(len(inputs.graph.edges)),
                           "facts": int(inputs.graph.n_facts), "graphml_facts": inputs.graph_facts}
    return {"command": command, "config": config,
            "rule_files": [s.path for s in inputs.sources if s.role in ("rules", "facts")]}


def run_sources(inputs: ReasoningInputs) -> list[dict[str, Any]]:
    """The run's `sources` rows (tracelab.store.sources): each rule and fact file with its text, then the
    tracelab program a PyReason program became (role `translation`, no path)."""
    from tracelab.store.sources import read_sources, text_source
    rows = read_sources((s.role, s.path) for s in inputs.sources if s.role in ("rules", "facts"))
    return rows if inputs.translation is None else [*rows, text_source("translation", inputs.translation)]


def open_reasoning_run(run_dir: Path, inputs: ReasoningInputs, command: str, settings: dict[str, Any]) -> Any:
    """A new run of the store (a TraceWriter) for a reasoning: its metadata (run_meta) and its sources."""
    from tracelab.store import TraceWriter
    sources = run_sources(inputs)
    writer = TraceWriter.open(run_dir, run_meta(inputs, command, settings, sources))
    writer.write_sources(sources)
    return writer


def _size(path: str) -> int | None:
    try:
        return os.path.getsize(path)
    except OSError:
        return None


