"""ReasoningRecorder: streams reasonings (an Engine running one program over one graph, once per episode:
tracelab.reasoning) into a run of the trace store through TraceWriter, as StoreSink streams an
environment's games.

What a reasoning run holds: the rules and clauses, every fact (the graph's and fact tables' as columns,
with the episode a fact table gave each; then the program's), the vocabulary (nodes, labels, atoms), the
grounding table, the graph's edges (`edges`), one episode per reasoning (begin info: which repeat or
which fact-table episode; end: steps, t_end, outcome `converged`, `stopped`, or `failed` with the
engine's error (an inconsistency, no fixpoint) and the rows up to it, info with the kernel and the
engine's counters), and every change row with its cause and grounding. No `steps` rows (nobody
acts) and no board (RunMeta.board stays None).

Trace rows are taken from the engine in chunks, as a declared env's recorder does
(tracelab/envs/declared/recording.py): after HANDOVER_STEPS steps (store/writer.py), when
TRACE_HANDOVER_ROWS rows wait in the engine (a step that big hands its
buffers over without a copy), and at the episode's end; the writer publishes them as Parquet parts in
its own thread. So a reasoning of any size holds at most one chunk of its trace in memory."""
from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from tracelab.store.writer import HANDOVER_STEPS, TraceWriter


class ReasoningRecorder:
    """Records the `episodes` episodes of one program over one graph into `writer` (which the caller
    closes)."""

    def __init__(self, writer: TraceWriter, episodes: int = 1) -> None:
        # when used: core imports numba and the kernels
        from tracelab.engine.core import TRACE_HANDOVER_ROWS
        self._handover_steps = HANDOVER_STEPS
        self.writer = writer
        self.rows = 0
        self.seconds = 0.0  # spent in this recorder's calls: what recording held the reasoning up
        self._handover_rows = TRACE_HANDOVER_ROWS
        self._several = episodes > 1
        self._steps_waiting = 0
        self._program: threading.Thread | None = None  # writes the program's tables (begin_run)
        self._program_error: BaseException | None = None
        self._vocabulary_written = False
        self._graph: Any = None
        self._episode: int | None = None
        self._written: dict[str, np.ndarray] | None = None  # ids of the episodes before (several only)

    def begin_run(self, program: Any, graph: Any) -> None:
        """The rules and the facts: `graph`'s (the graph every episode's facts come from,
        tracelab.reasoning.plan_episodes) as columns, then the program's. Called before the first
        engine is built: they are converted in a thread of their own while the engine grounds (a
        million facts' texts take most of a second), and reach the writer before the episode begins."""
        if self._program is None:
            self._graph = graph
            self._program = threading.Thread(target=self._write_program, args=(program, graph),
                                             name="ReasoningRecorder:program", daemon=True)
            self._program.start()

    def _write_program(self, program: Any, graph: Any) -> None:
        try:
            self.writer.write_program(program, graph=graph)
        except BaseException as e:  # noqa: BLE001 - raised in the caller's thread by _wait_for_program
            self._program_error = e

    def _wait_for_program(self) -> None:
        assert self._program is not None, "begin_run first"
        self._program.join()
        if self._program_error is not None:
            raise self._program_error

    def begin_episode(self, episode: int, engine: Any, info: dict[str, Any]) -> None:
        """Start `episode` on `engine` (after begin_run). The first episode writes the vocabulary, the
        groundings and the graph's edges; later ones must have grounded the same (checked)."""
        with self._timed():
            self._wait_for_program()
            if not self._vocabulary_written:
                self.writer.write_vocabulary(engine.vocabulary(), engine.groundings)
                if self._graph is not None:
                    self.writer.write_edges(self._graph.edges)
                self._vocabulary_written = True
            self._check_same_grounding(episode, engine)
            self._episode = episode
            self._steps_waiting = 0
            self.writer.begin_episode(episode, t_start=0, info=info or None)

    def stepped(self, engine: Any) -> None:
        """After a step: hand the engine's rows over when a chunk is due."""
        self._steps_waiting += 1
        if self._steps_waiting >= self._handover_steps or engine.trace_rows_waiting >= self._handover_rows:
            self.write(engine, engine.take_trace())

    def write(self, engine: Any, rows: dict[str, np.ndarray]) -> None:
        """Trace rows taken from `engine` (with the atoms and groundings they name, if new)."""
        with self._timed():
            self._write(engine, rows)

    def _write(self, engine: Any, rows: dict[str, np.ndarray]) -> None:
        assert self._episode is not None, "begin_episode first"
        self._steps_waiting = 0
        if len(rows["t"]):
            self.rows += self.writer.write_engine(self._episode, engine, rows)

    def end_episode(self, episode: int, engine: Any, *, steps: int, outcome: str, info: dict[str, Any]) -> None:
        """The episode's last rows, then its end: `steps` run (t = 0 .. steps-1) and the outcome."""
        with self._timed():
            self._write(engine, engine.take_trace())
            self._check_same_grounding(episode, engine)
            if self._several:
                self._written = _ids(engine)
            self.writer.end_episode(episode, steps=steps, t_end=steps - 1, outcome=outcome, info=info)
            self._episode = None

    @contextmanager
    def _timed(self) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds += time.perf_counter() - t0

    def _check_same_grounding(self, episode: int, engine: Any) -> None:
        """Every episode's ids must mean what the run's tables say: the atoms and groundings of the
        episodes before are a prefix of this engine's (they are, as every episode grounds every fact's
        atoms; checked when a run has several episodes, at each one's start and end)."""
        if self._written is None:
            return
        now = _ids(engine)
        for name, written in self._written.items():
            if len(now[name]) < len(written) or not np.array_equal(now[name][:len(written)], written):
                raise RuntimeError(f"episode {episode} grounded the program differently from the episodes "
                                   f"before it ({name} differ): its rows cannot share the run's ids")


def _ids(engine: Any) -> dict[str, np.ndarray]:
    """The arrays that give atom and grounding ids their meaning."""
    v, g = engine.vocab, engine.groundings
    n = v.n_atoms
    return {"atom_label": np.array(v.atom_label[:n]), "atom_arg0": np.array(v.atom_arg0[:n]),
            "atom_arg1": np.array(v.atom_arg1[:n]), "grounding_rule": np.array(g.rule),
            "grounding_body": np.array(g.body_atoms), "grounding_values": np.array(g.var_values)}
