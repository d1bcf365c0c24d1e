"""TraceWriter: records one run (program, vocabulary, groundings, episodes, trace rows, steps, metrics) as
Parquet parts that other processes can read while it writes.

Callers only append to in-memory buffers (after checking and converting the data). One background thread
publishes the buffers: a new part per table, then a new manifest that lists them, so readers see every
table at the same moment (layout and atomicity: tracelab.store.parts):
- at most `flush_interval` (1 s) after a row arrives,
- soon after an episode ends (at most one such flush per `min_flush_gap`),
- when the buffers hold `part_rows` rows (or `max_pending_rows`, if fewer), and on flush() / close();
every publication is one new immutable part per table that has rows (small parts are compacted).
A kill -9 therefore loses at most the rows of the last second (or since the last episode end), and the
run still opens. SIGTERM and interpreter exit close open writers (status 'interrupted').

Ctrl-C and SIGTERM raise wherever Python's handler runs in the calling thread, which may be inside a
hand-over to the flusher. So the caller's thread takes the writer's lock only through a C lock's own `with`
(no Python frame between acquiring and the block's cleanup, where threading.Condition's __enter__ has one:
a KeyboardInterrupt landing there left the lock held, and close() then waited forever for the flusher) and
never waits on a Condition; it waits on a lock of its own that the flusher releases (`_wait_for_flusher`)."""
from __future__ import annotations

import atexit
import errno
import fcntl
import os
import signal
import threading
import time
import weakref
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa

from tracelab.engine.errors import is_interrupt
from tracelab.store import arrow_build, convert, layout
from tracelab.store.agent_rows import ObservationName, action_names_table, observation_names_table
from tracelab.store.graph_tables import edges_table
from tracelab.store.meta import (RunMeta, initial_meta, meta_bytes, now_iso, open_writer_lock, read_meta,
                                 reopened_meta, write_meta)
from tracelab.store.parts import TableParts, remove_unlisted, write_manifest
from tracelab.store.portable_paths import portable_config, portable_path
from tracelab.store.stored import PROGRAM_TABLES, VOCABULARY_TABLES, StoredRun, stored_run
from tracelab.store.schema import SCHEMAS, TABLES
from tracelab.store.sources import sources_tables

class RunSealed(ValueError):
    """Reopening a sealed run: its rows live in run.duckdb now, which takes no more."""


_OPEN_WRITERS: "weakref.WeakSet[TraceWriter]" = weakref.WeakSet()
# Back-pressure: callers wait while this many rows are buffered (a row group of changes, ~10 MB). The
# flusher takes them all at once and the caller refills the buffers meanwhile, so a busy writer (a merge,
# a loaded machine) holds about twice this: at 500k rows a 10,000-episode play peaked ~60 MB higher
# (docs/benchmarks/history.md, "Memory of long runs").
MAX_PENDING_ROWS = 131_072
# How many steps' trace rows a recorder (a declared env's, a reasoning's) lets wait in the engine before it
# takes them: a live reader sees a step that late at most.
HANDOVER_STEPS = 64


def _without_file(table: pa.Table) -> pa.Table:
    return table.drop_columns(["file"]) if "file" in table.column_names else table


def _use_system_allocator() -> None:
    """Arrow's buffers from malloc rather than pyarrow's default mimalloc, unless the user chose a pool
    (ARROW_DEFAULT_MEMORY_POOL): mimalloc kept ~130 MB more resident after each merge of a table's small
    parts (64 parts, 1.7M change rows: +130 MB against +40 MB at the peak and +8 MB after, with
    malloc_trim), so a long run's memory rose with its length (docs/benchmarks/history.md, "Memory of long runs")."""
    if "ARROW_DEFAULT_MEMORY_POOL" not in os.environ and pa.default_memory_pool().backend_name != "system":
        pa.set_memory_pool(pa.system_memory_pool())


def _close_open_writers() -> None:
    for w in list(_OPEN_WRITERS):
        if w._pid != os.getpid():  # a forked child inherited it: the run belongs to the parent
            continue
        try:
            w.close(status="interrupted")
        except Exception:  # noqa: BLE001 - at exit, one broken writer must not stop the others
            pass


atexit.register(_close_open_writers)
_sigterm_installed = False


def _install_sigterm_handler() -> None:
    """Turn SIGTERM into SystemExit, so `with` blocks and atexit close writers (only if nobody else
    handles SIGTERM, and only from the main thread, where Python allows it)."""
    global _sigterm_installed
    if _sigterm_installed or threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        def _raise(signum: int, frame: Any) -> None:
            raise SystemExit(128 + signum)
        signal.signal(signal.SIGTERM, _raise)
    _sigterm_installed = True


class TraceWriter:
    """Writes one run directory. Use `TraceWriter.open(run_dir, meta)` or the constructor, ideally as a
    context manager; call close() otherwise. Call it from one thread (the flushing thread is its own)."""

    def __init__(self, run_dir: str | Path, meta: RunMeta | dict[str, Any] | None = None, *,
                 flush_interval: float = 1.0, min_flush_gap: float = 0.05, part_rows: int = 250_000,
                 compact_files: int = 64, max_pending_rows: int = MAX_PENDING_ROWS,
                 compression: str = "zstd", _reopen: Mapping[str, Any] | None = None) -> None:
        self.run_dir = Path(run_dir)
        self._pid = os.getpid()
        _use_system_allocator()
        exists = os.path.lexists(layout.meta_path(self.run_dir))
        if _reopen is None and exists:
            raise FileExistsError(f"{str(self.run_dir)!r} already holds a run; choose a new run directory")
        if _reopen is not None and not exists:
            raise FileNotFoundError(f"{str(self.run_dir)!r} is not a tracelab run: it has no {layout.META}")
        if flush_interval <= 0 or part_rows <= 0:
            raise ValueError(f"flush_interval ({flush_interval}) and part_rows ({part_rows}) must be > 0")
        # a new run's metadata, refused before anything is created if its readers would refuse it
        new_meta = initial_meta(self.run_dir, meta) if _reopen is None else {}
        if _reopen is None:
            meta_bytes(self.run_dir, new_meta)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self._lock_file = open_writer_lock(self.run_dir)
        try:
            fcntl.flock(self._lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock_file.close()
            raise RuntimeError(f"another process is writing {str(self.run_dir)!r}") from None
        try:
            stored = None if _reopen is None else self._stored_unsealed()
        except BaseException:
            self._lock_file.close()  # releases the lock
            raise
        self._lock_file.truncate(0)
        self._lock_file.write(f"{os.getpid()}\n".encode())
        self._lock_file.flush()

        self.flush_interval = flush_interval
        self.min_flush_gap = min_flush_gap
        self.part_rows = part_rows
        self.max_pending_rows = max_pending_rows
        self._flush_rows = min(part_rows, max_pending_rows)  # buffered rows that make a flush due now
        layout.remove_stale_temps(self.run_dir)
        self._parts = {t: TableParts(self.run_dir, t, part_rows, compact_files, compression=compression,
                                     existing=None if stored is None else stored.parts[t])
                       for t in TABLES}
        # Counts of what has been accepted (buffered or published): ids are checked against them.
        self._vocab_have = {"nodes": 0, "labels": 0, "atoms": 0}
        self._groundings_have = 0
        self._seq = 0
        self._program_written = False
        self._action_names_written = False
        self._observation_names_written = False
        self._sources_written = False
        self._open_episodes: set[int] = set()
        self.flushes = 0
        # the flusher thread's CPU seconds for its last publication, read by a recorder that paces its writes by
        # it (store/write_pacing.py; a float's assignment is atomic)
        self.last_publish_cpu_s = 0.0
        # A reopened run's program and vocabulary, to check a new engine's against (first call only)
        self._stored_tables: dict[str, pa.Table] | None = None
        self.next_free_episode = 0  # one past the highest episode id the run held when opened
        if stored is None:
            write_manifest(self.run_dir, self._parts, 0)
            self._meta = new_meta
        else:
            self._continue_counts(stored)
            self._meta = reopened_meta(self.run_dir, read_meta(self.run_dir), _reopen)
        write_meta(self.run_dir, self._meta)  # the run exists (or runs again) from here on

        self._lock = threading.Lock()  # the caller's thread takes it only by `with` (see the module's doc)
        self._cond = threading.Condition(self._lock)  # the flusher waits on it; the caller only notifies
        self._waiters: list[Any] = []  # the caller's locks the flusher releases after each flush
        self._pending: dict[str, list[pa.Table]] = {t: [] for t in TABLES}
        self._pending_rows = 0
        self._pending_since: float | None = None
        self._urgent = False
        self._requested = 0
        self._done = 0
        self._last_flush = time.monotonic()
        self._closing = False
        self._closed = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._flusher, name=f"TraceWriter:{self.run_dir.name}",
                                        daemon=True)
        self._thread.start()
        _OPEN_WRITERS.add(self)
        _install_sigterm_handler()

    @classmethod
    def open(cls, run_dir: str | Path, meta: RunMeta | dict[str, Any] | None = None,
             **options: Any) -> "TraceWriter":
        return cls(run_dir, meta, **options)

    @classmethod
    def reopen(cls, run_dir: str | Path, meta_changes: Mapping[str, Any] | None = None,
               **options: Any) -> "TraceWriter":
        """Append to a closed run that is not sealed (a resumed training): its parts, ids, episode
        numbering and flush count continue; meta.json reads `running` again (with `meta_changes`
        applied) until close() records the new status. Refuses a sealed run (RunSealed) and one another
        process writes. A program or vocabulary written later must be the run's own (ValueError if not)."""
        return cls(run_dir, None, _reopen=dict(meta_changes or {}), **options)

    def _stored_unsealed(self) -> StoredRun:
        """What the run holds, once we hold its lock: refused if it is sealed; leftovers of a killed
        writer (temp files, parts no manifest lists) are removed first."""
        if os.path.lexists(layout.sealed_path(self.run_dir)) or read_meta(self.run_dir).get("sealed_at"):
            raise RunSealed(f"run {str(self.run_dir)!r} is sealed ({layout.SEALED}): a sealed run takes "
                            f"no more rows")
        layout.remove_stale_temps(self.run_dir)
        remove_unlisted(self.run_dir)
        return stored_run(self.run_dir)

    def _continue_counts(self, stored: StoredRun) -> None:
        self._vocab_have = {t: stored.rows(t) for t in ("nodes", "labels", "atoms")}
        self._groundings_have = stored.groundings
        self._seq = stored.changes
        self._program_written = stored.rows("policies") > 0  # every program writes the policy names
        self._action_names_written = stored.rows("action_names") > 0
        self._observation_names_written = stored.rows("observation_names") > 0
        self._sources_written = stored.rows("sources") > 0
        self._open_episodes = set(stored.open_episodes)
        self.flushes = stored.flushes  # the manifest's count keeps growing: readers watch it
        self._stored_tables = stored.small_tables
        self.next_free_episode = stored.next_free_episode

    # ---- context manager ---------------------------------------------------------------------------
    def __enter__(self) -> "TraceWriter":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            status = "finished"
        elif exc is not None and is_interrupt(exc):
            status = "interrupted"
        else:
            status = "failed"
        self.close(status=status)

    # ---- the program and the world ----------------------------------------------------------------
    def write_program(self, program: Any, vocabulary: Mapping[str, Any] | None = None,
                      groundings: Any = None, *, facts: Sequence[Any] | None = None, graph: Any = None) -> None:
        """The rules and facts (tracelab.engine.program.Program) and, optionally, the vocabulary and
        grounding table as they stand now; later growth goes through write_vocabulary().
        facts: what the trace's fact ids index, Engine.facts (graph facts first); default program.facts.
        graph: the Engine's Graph, whose facts come first, written as columns (then `facts` are the
        program's; its edges go through write_edges, once the nodes they name are written).
        With an engine at hand, write_engine_program(engine) passes the program, graph, vocabulary and
        groundings, and the graph's edges."""
        tables = convert.program_tables(program, facts, graph, lambda path: portable_path(path, self.run_dir))
        if self._program_written and self._stored_tables is not None:  # a reopened run: the same program
            self._check_stored(tables, PROGRAM_TABLES, "program")
            for name in PROGRAM_TABLES:
                del self._stored_tables[name]
            tables = {}
        elif self._program_written:
            raise RuntimeError(f"the program of run {self.run_dir.name!r} was already written")
        self._append(tables)
        self._program_written = True
        if vocabulary is not None or groundings is not None:
            self.write_vocabulary(vocabulary, groundings)

    def write_edges(self, pairs: Any) -> None:
        """A graph's edges, (source, target) node ids of the vocabulary (Graph.edges)."""
        if len(pairs):
            self._append({"edges": edges_table(pairs)})

    def write_engine_program(self, engine: Any) -> None:
        """write_program() with an Engine's program, graph (its facts first), vocabulary and groundings,
        then the graph's edges (a reopened run holds them already)."""
        reopened = self._program_written and self._stored_tables is not None
        self.write_program(engine.program, engine.vocabulary(), engine.groundings, graph=engine.graph)
        if not reopened:
            self.write_edges(engine.graph.edges)

    def write_vocabulary(self, vocabulary: Mapping[str, Any] | None,
                         groundings: Any = None) -> None:
        """Append the nodes, labels, atoms (Engine.vocabulary()) and groundings (Engine.groundings) that
        are new since the last call; cheap when nothing is new."""
        tables: dict[str, pa.Table] = {}
        if vocabulary is not None and self._stored_tables and "atoms" in self._stored_tables:
            self._check_stored(convert.vocabulary_tables(vocabulary, dict.fromkeys(VOCABULARY_TABLES, 0)),
                               tuple(VOCABULARY_TABLES), "vocabulary")
            for name in VOCABULARY_TABLES:
                del self._stored_tables[name]
        if vocabulary is not None:
            tables.update(convert.vocabulary_tables(vocabulary, self._vocab_have))
        if groundings is not None and convert.grounding_count(groundings) != self._groundings_have:
            tables["groundings"] = convert.groundings_table(groundings, self._groundings_have)
        self._append(tables)
        for name in ("nodes", "labels", "atoms"):
            if name in tables:
                self._vocab_have[name] += tables[name].num_rows
        if "groundings" in tables:
            self._groundings_have += tables["groundings"].num_rows

    def write_engine_vocabulary(self, engine: Any) -> None:
        """write_vocabulary() with an Engine's vocabulary and groundings: cheap when nothing is new (the
        vocabulary is only rebuilt when the engine's counts moved)."""
        vocab = getattr(engine, "vocab", None)
        grown = vocab is None or (len(vocab.nodes), len(vocab.labels), vocab.n_atoms) != (
            self._vocab_have["nodes"], self._vocab_have["labels"], self._vocab_have["atoms"])
        self.write_vocabulary(engine.vocabulary() if grown else None, engine.groundings)

    def _check_stored(self, tables: Mapping[str, pa.Table], names: Sequence[str], what: str) -> None:
        """A reopened run: the stored rows of `names` must begin `tables` (the new engine's). Whatever
        file a rule or fact was read from: the same program read where the run was moved to, or by a run
        recorded before its paths were portable (portable_paths), is the run's."""
        assert self._stored_tables is not None
        for name in names:
            have, new = (_without_file(t[name]) for t in (self._stored_tables, tables))
            if new.num_rows < have.num_rows or not new.slice(0, have.num_rows).equals(have):
                raise ValueError(f"run {str(self.run_dir)!r}: this engine's {what} ({name}) differs from "
                                 f"the one the run holds; write into a new run")

    # ---- episodes ------------------------------------------------------------------------------------
    def begin_episode(self, episode: int, *, world: int = 0, t_start: int | None = None,
                      seed: int | None = None, info: Any = None) -> None:
        self.begin_episodes([{"episode": episode, "world": world, "t_start": t_start, "seed": seed,
                              "info": info}])

    def begin_episodes(self, episodes: Sequence[Mapping[str, Any]]) -> None:
        """begin_episode for many episodes in one table (dicts with episode and optionally world,
        t_start, seed, info, and started_at: when the episode began, if not now; a UTC datetime without
        tzinfo, convert.utc_now()): a training loop logs thousands of short episodes."""
        rows, now = [], convert.utc_now()
        for e in episodes:
            episode = int(e["episode"])
            if episode in self._open_episodes:
                raise ValueError(f"episode {episode} was already begun and not yet ended")
            self._open_episodes.add(episode)
            rows.append({"episode": episode, "world": e.get("world", 0), "t_start": e.get("t_start"),
                         "seed": e.get("seed"), "started_at": e.get("started_at") or now,
                         "info": convert.json_text(e.get("info"))})
        if rows:
            self._append({"episode_begin": arrow_build.table_from_rows(rows, SCHEMAS["episode_begin"])})

    def end_episode(self, episode: int, *, steps: int, outcome: str, reward: float | None = None,
                    rewards: Mapping[str, float] | None = None, t_end: int | None = None,
                    info: Any = None) -> None:
        """Close an episode. outcome: 'win', 'loss', 'draw' or 'truncated' (the saved queries use
        these); reward: the learner's return; rewards: per-agent returns. Triggers a flush."""
        self.end_episodes([{"episode": episode, "steps": steps, "outcome": outcome, "reward": reward,
                            "rewards": rewards, "t_end": t_end, "info": info}])

    def end_episodes(self, episodes: Sequence[Mapping[str, Any]]) -> None:
        """end_episode for many episodes in one table (dicts with episode, steps, outcome and optionally
        reward, rewards, t_end, info, and ended_at: when the episode ended, if not now; a UTC datetime
        without tzinfo, convert.utc_now()). Triggers a flush."""
        rows, now = [], convert.utc_now()
        for e in episodes:
            episode = int(e["episode"])
            if episode not in self._open_episodes:
                raise ValueError(f"episode {episode} is not open (begin_episode it first; open: "
                                 f"{sorted(self._open_episodes)[:10]})")
            self._open_episodes.discard(episode)
            reward, rewards = e.get("reward"), e.get("rewards")
            rows.append({"episode": episode, "steps": int(e["steps"]), "t_end": e.get("t_end"),
                         "outcome": str(e["outcome"]), "reward": None if reward is None else float(reward),
                         "rewards": convert.json_text(dict(rewards) if rewards is not None else None),
                         "ended_at": e.get("ended_at") or now, "info": convert.json_text(e.get("info"))})
        if rows:
            self._append({"episode_end": arrow_build.table_from_rows(rows, SCHEMAS["episode_end"])},
                         urgent=True)

    # ---- rows ------------------------------------------------------------------------------------------
    def write_changes(self, episode: int | Sequence[int] | np.ndarray | None,
                      arrays: Mapping[str, Any], owned: bool = False) -> int:
        """Trace rows as Engine.take_trace() returns them. episode: the id of every row, or an array
        giving the episode each world is playing (indexed by the `world` column), or None if `arrays`
        has its own `episode` column. owned: the caller will not touch the arrays again (take_trace's
        own), so they are kept without a copy. Returns the number of rows accepted."""
        table = convert.trace_table(arrays, episode, self._seq, self._vocab_have["atoms"],
                                    self._groundings_have, owned)
        self._seq += table.num_rows
        self._append({"changes": table})
        return table.num_rows

    def write_engine(self, episode: int | Sequence[int] | np.ndarray | None, engine: Any,
                     rows: Mapping[str, Any] | None = None) -> int:
        """write_vocabulary(engine's vocabulary and groundings) then write_changes(engine.take_trace(), or
        `rows`: trace rows the caller already took from it and leaves alone). Cheap per step: the
        vocabulary is only rebuilt when the engine's counts moved. take_trace's arrays are new at every
        call (the engine hands its buffers over or copies them out), so they are kept without a copy."""
        self.write_engine_vocabulary(engine)
        return self.write_changes(episode, engine.take_trace() if rows is None else rows, owned=True)

    def write_steps(self, episode: int | np.ndarray, arrays: Mapping[str, Any]) -> int:
        """Per-step rows (see convert.steps_table): step, action, reward [, agent, t, terminated,
        truncated, obs], of one episode or (an int array) each row's own. Returns the number of rows."""
        table = convert.steps_table(episode, arrays)
        self._append({"steps": table})
        return table.num_rows

    def write_agent_table(self, table: str, rows: pa.Table) -> None:
        """Decision or reward-term rows (tracelab.store.agent_rows: Decisions.table, RewardTerms.table)."""
        if table not in ("decisions", "reward_terms"):
            raise ValueError(f"write_agent_table writes decisions or reward_terms, not {table!r}")
        self._append({table: rows})

    def write_action_names(self, names: Sequence[str], positions: Sequence[int | None] | None = None) -> None:
        """The run's actions, once: action k (as steps.action holds it) is names[k], at positions[k] in a
        decision's values (default k; None: the policy does not offer it). A reopened run keeps its own."""
        if self._action_names_written:
            return
        self._action_names_written = True
        self._append({"action_names": action_names_table(names, positions)})

    def write_observation_names(self, names: Sequence[ObservationName]) -> None:
        """What the entries of steps.obs are (agent_rows.ObservationName), once; a reopened run keeps its own."""
        if self._observation_names_written or not names:
            return
        self._observation_names_written = True
        self._append({"observation_names": observation_names_table(names)})

    def write_sources(self, rows: Sequence[Mapping[str, Any]]) -> None:
        """The files the program was read from, with their texts (tracelab.store.sources.read_sources),
        once; a reopened run keeps its own."""
        if self._sources_written or not rows:
            return
        self._sources_written = True
        rows = [{**r, "path": None if r.get("path") is None else portable_path(r["path"], self.run_dir)} for r in rows]
        self._append({"sources": pa.concat_tables(sources_tables(rows))})

    def write_metrics(self, step: int, values: Mapping[str, float], episode: int | None = None) -> None:
        """Training metrics at a global training step, one row per name."""
        self._append({"metrics": convert.metrics_table(step, values, episode)})

    # ---- flushing --------------------------------------------------------------------------------------
    def _check(self) -> None:
        if self._error is not None:
            raise self._failure(self._error) from self._error
        if self._closing:
            raise RuntimeError(f"the trace writer of {str(self.run_dir)!r} is closed")

    def _append(self, tables: Mapping[str, pa.Table], urgent: bool = False) -> None:
        with self._lock:
            self._check()
            added = 0
            for name, table in tables.items():
                if table.num_rows:
                    self._pending[name].append(table)
                    added += table.num_rows
            first = added and self._pending_since is None
            if first:
                self._pending_since = time.monotonic()
            self._pending_rows += added
            self._urgent = self._urgent or urgent
            if first or urgent or self._pending_rows >= self._flush_rows:
                self._cond.notify_all()  # the flusher recomputes when its next flush is due
        # back-pressure: let the flusher catch up
        self._wait_for_flusher(lambda: self._pending_rows < self.max_pending_rows)

    def flush(self) -> None:
        """Publish everything written so far; returns when readers can see it."""
        with self._lock:
            self._check()
            self._requested += 1
            mine = self._requested
            self._cond.notify_all()
        self._wait_for_flusher(lambda: self._done >= mine)

    def _wait_for_flusher(self, done: Callable[[], bool]) -> None:
        """Return once done() holds (checked under the lock), raising if the writer failed meanwhile. The
        wait is on a new lock of this call's own, which the flusher releases after its next flush: an
        interrupt landing anywhere here leaves no lock held that the flusher or close() needs."""
        while True:
            with self._lock:
                self._check()
                if done():
                    return
                waiter = threading.Lock()
                waiter.acquire()
                self._waiters.append(waiter)
            waiter.acquire(timeout=0.1)

    def _wake_waiters(self) -> None:
        """The flusher, holding the lock: release every waiter registered so far."""
        for waiter in self._waiters:
            waiter.release()
        self._waiters.clear()

    def _due_in(self, now: float) -> float | None:
        """Seconds until a flush is due (<= 0: now), or None if nothing is due at all."""
        if self._closing or self._requested > self._done or self._pending_rows >= self._flush_rows:
            return 0.0
        if self._pending_since is None:
            return None
        due = self._pending_since + self.flush_interval - now
        if self._urgent:
            due = min(due, self._last_flush + self.min_flush_gap - now)
        return due

    def _flusher(self) -> None:
        while True:
            with self._cond:
                while True:
                    due = self._due_in(time.monotonic())
                    if due is not None and due <= 0:
                        break
                    self._cond.wait(due)
                take, self._pending = self._pending, {t: [] for t in TABLES}
                self._pending_rows, self._pending_since, self._urgent = 0, None, False
                request, closing = self._requested, self._closing
                self._cond.notify_all()  # a caller held back by back-pressure goes on now
            try:
                cpu0 = time.thread_time()
                if any(take.values()):
                    for name in TABLES:
                        if take[name]:
                            self._parts[name].publish(take[name])
                    write_manifest(self.run_dir, self._parts, self.flushes + 1)  # now readers see them
                    self.last_publish_cpu_s = time.thread_time() - cpu0
            except BaseException as e:  # noqa: BLE001 - reported to the caller by _check()
                with self._cond:
                    self._error = e
                    self._wake_waiters()
                return
            with self._cond:
                self._done = request
                self._last_flush = time.monotonic()
                self.flushes += 1
                self._wake_waiters()
            if closing:
                return

    # ---- closing -----------------------------------------------------------------------------------------
    def close(self, status: str = "finished") -> None:
        """Flush, stop the flusher, record the end time and status, release the run directory."""
        if self._closed:
            return
        with self._lock:
            self._closing = True
            self._cond.notify_all()
        self._thread.join()  # a second Ctrl-C here leaves the writer open: atexit closes it
        self._closed = True
        error = self._error
        self._meta.update(ended_at=now_iso(), status="failed" if error else status)
        try:
            write_meta(self.run_dir, self._meta)
        except OSError as e:  # a full disk: the run stays as its last flush left it, readable
            error = error or e
        finally:
            fcntl.flock(self._lock_file, fcntl.LOCK_UN)
            self._lock_file.close()
            _OPEN_WRITERS.discard(self)
        if error is not None:
            raise self._failure(error) from error

    def _failure(self, error: BaseException) -> Exception:
        """The error to raise for a failed write: a full disk is the user's to fix, an OSError (one line,
        naming the run); anything else stays a RuntimeError (a bug, with its traceback)."""
        if isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT):
            return OSError(error.errno, "the disk is full: the run keeps what was written before, "
                                        f"readable ({os.strerror(error.errno)})", str(self.run_dir))
        return RuntimeError(f"the trace writer of {str(self.run_dir)!r} failed: {error!r}")

    def add_config(self, entries: Mapping[str, Any]) -> None:
        """`entries` set in the run's config (meta.json's `config`), written now: what a recorder knows of
        the run that its opener did not say (a declared world's facts and board: envs/declared/recording.py).
        Refused (ValueError) as a new run's metadata is, when its readers would refuse it."""
        doc = {**self._meta, "config": {**self._meta.get("config", {}), **portable_config(entries, self.run_dir)}}
        meta_bytes(self.run_dir, doc)
        write_meta(self.run_dir, doc)
        self._meta = doc

    @property
    def meta(self) -> dict[str, Any]:
        """meta.json as this writer last wrote it (a copy)."""
        return dict(self._meta)

    @property
    def closed(self) -> bool:
        return self._closed

    def stats(self) -> dict[str, Any]:
        """Rows published per table, the seconds spent writing each table's parts, part files written,
        compactions and flushes so far."""
        return {"rows": {t: p.rows_published for t, p in self._parts.items()},
                "seconds": {t: p.seconds for t, p in self._parts.items()},
                "files": sum(p.files_written for p in self._parts.values()),
                "compactions": sum(p.compactions for p in self._parts.values()), "flushes": self.flushes}
