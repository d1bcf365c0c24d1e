"""One open run for the TUI (or several, for the SQL console: SeveralRunsSource): its connection
(tracelab.store.open_run) behind a lock, so that queries from worker threads never overlap on it, and
every statement through the store's read-only path (query_readonly inside retrying). Esc cancels the query
the user waits on (`interrupt_foreground()`), not background work (`background()`). The run's life as
other processes change it (its writer closing or dying, `tracelab seal`) is read by `follow()`; the
views re-read a run while it is `live` and once more after it closes (LiveReads)."""
from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from tracelab.store.catalog import short_command
from tracelab.store.kind import has_board, is_game_run
from tracelab.store.reader import RunConnection, fetch_arrow, open_run, query_readonly, retrying, run_info

if TYPE_CHECKING:   # pyarrow is loaded by the views that read Arrow, after the first screen (issue 40)
    import pyarrow as pa

    from tracelab.board import Board

T = TypeVar("T")

_thread = threading.local()


def background(work: Callable[[], None]) -> Callable[[], None]:
    """`work` (a worker thread's body) marked as background: reads the user did not ask for and is not
    waiting on (a warm-up, a panel following the cursor, a live run's re-read). Esc does not cancel its
    queries (interrupt_foreground), so that it goes back at once; closing the run does (close)."""
    @functools.wraps(work)
    def marked() -> None:
        _thread.background = True
        try:
            work()
        finally:
            _thread.background = False
    return marked


class LockedConnection:
    """A store connection behind a lock: queries from worker threads never overlap on it, every statement
    goes through the store's read-only path (query_readonly inside retrying), `interrupt()` cancels the
    running query, `interrupt_foreground()` only one the user waits on (Esc)."""

    def __init__(self, con: RunConnection) -> None:
        self.con = con
        self._lock = threading.Lock()
        # the call holding the connection: None, "foreground" or "background"; read and changed under
        # _running_lock, so that Esc's interrupt cannot land on a background call that has just begun
        self._running: str | None = None
        self._running_lock = threading.Lock()

    @property
    def busy(self) -> bool:
        return self._running is not None

    @property
    def foreground_busy(self) -> bool:
        """A query the user waits on is running (Esc would cancel it)."""
        return self._running == "foreground"

    def call(self, fn: Callable[[RunConnection], T]) -> T:
        """fn(connection) alone on the connection (the explain functions take a connection)."""
        with self._lock:
            with self._running_lock:
                self._running = "background" if getattr(_thread, "background", False) else "foreground"
            try:
                return retrying(lambda: fn(self.con))
            finally:
                with self._running_lock:
                    self._running = None

    def arrow(self, sql: str, params: dict[str, Any] | None = None) -> pa.Table:
        return self.call(lambda con: query_readonly(con, sql, params).to_arrow_table())

    def rows(self, sql: str, params: dict[str, Any] | None = None) -> list[dict[str, Any]]:
        """The rows as dicts, from DuckDB's own rows (no Arrow: the first screen's table pages through
        here before pyarrow is loaded)."""
        def read(con: RunConnection) -> list[dict[str, Any]]:
            rel = query_readonly(con, sql, params)
            names = rel.columns
            return [dict(zip(names, row)) for row in rel.fetchall()]
        return self.call(read)

    def columns(self, sql: str) -> list[str]:
        """The names of a statement's columns (bound, not run)."""
        return self.call(lambda con: list(query_readonly(con, sql).columns))

    def scalar(self, sql: str, params: dict[str, Any] | None = None) -> Any:
        rows = self.call(lambda con: query_readonly(con, sql, params).fetchall())
        return rows[0][0] if rows else None

    def fetch(self, con: RunConnection, sql: str, params: dict[str, Any] | None, saved: bool,
              limit: int) -> pa.Table:
        """The first `limit` rows of a statement (the SQL console's; `saved`: a saved query's text)."""
        return fetch_arrow(query_readonly(con, sql, params), limit)

    def interrupt(self) -> bool:
        """Cancel the query running now, if any; True if there was one."""
        return self._interrupt(("foreground", "background"))

    def interrupt_foreground(self) -> bool:
        """Cancel the query running now if the user waits on it (not background work); True if so."""
        return self._interrupt(("foreground",))

    def _interrupt(self, kinds: tuple[str, ...]) -> bool:
        with self._running_lock:
            if self._running not in kinds:
                return False
            self.con.interrupt()
            return True

    def close(self) -> None:
        # a long query would otherwise hold the lock, and closing the app, for minutes; interrupted again
        # until the lock is ours: a query that had the lock but had not started yet missed the first one
        while not self._lock.acquire(timeout=0.05):
            self.interrupt()
        try:
            self.con.close()
        finally:
            self._lock.release()


class RunSource(LockedConnection):
    """One open run: its connection (open_run), its status and kind."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        info = run_info(self.path)
        self.status: str = info.status
        self.sealed = info.sealed_file is not None
        self.command = short_command(str(info.meta.get("command") or ""))
        super().__init__(open_run(self.path))
        # a run of games (a board, or episodes with returns: a spec world's): return, outcome, game queries
        self.games: bool = self.call(is_game_run)

    @cached_property
    def has_board(self) -> bool:
        """Whether the SQL console offers the saved queries that read a board's labels."""
        return self.call(has_board)

    @cached_property
    def has_eval_games(self) -> bool:
        """A training run's evaluation games (kind 'eval'), of a world with a board or without: ] and [
        step through them in the trace."""
        return self.call(lambda con: bool(con.execute(
            "SELECT EXISTS (SELECT 1 FROM episodes WHERE kind = 'eval')").fetchall()[0][0]))

    @cached_property
    def board(self) -> Board | None:
        """The board to draw the run's episodes on (its spec's `[board]`; an older RuleSim run's from
        war.toml: board_state.board_of_run), None for a run without one (a reasoning run, a world without
        a [board]): the trace shows the atoms and the graph beside it instead. Read when the trace first
        asks: the first screen does not load the board's modules."""
        from tracelab.viewers.board_state import board_of_run
        return self.call(board_of_run)

    @property
    def live(self) -> bool:
        """Being written now: its rows may still grow."""
        return self.status == "running"

    @property
    def state(self) -> str:
        """The run's state in a few words, as the views' headers show it."""
        if self.live:
            return "live · running"
        if self.sealed:
            return "sealed" if self.status == "finished" else f"sealed · {self.status}"
        return self.status

    @property
    def can_change(self) -> bool:
        """Whether another process may still change the run: its writer, or `seal` (not yet sealed)."""
        return not self.sealed

    def follow(self) -> bool:
        """Read the run's status, and whether it is sealed, as of now (a file read, without the
        connection's lock); True if either changed since the last look."""
        info = run_info(self.path)
        now = (info.status, info.sealed_file is not None)
        changed = now != (self.status, self.sealed)
        self.status, self.sealed = now
        return changed


class SeveralRunsSource(LockedConnection):
    """Several runs on one connection (tracelab.store.several), for the SQL console: every view with a
    first column `run`; a saved query runs on each run, its rows after the run's name."""

    def __init__(self, paths: Sequence[Path]) -> None:
        from tracelab.store.several import SeveralRunsConnection, run_names
        self.path = Path(paths[0])     # the first run: names the console's export
        con = SeveralRunsConnection(list(paths), run_names(paths))
        super().__init__(con)
        games, with_board = [], []
        for i in range(len(con.names)):
            con.use(i)
            games.append(is_game_run(con))
            with_board.append(has_board(con))
        con.use(None)
        self.games = all(games)
        self.has_board = all(with_board)   # the saved queries that read a board: every run has one

    def fetch(self, con: RunConnection, sql: str, params: dict[str, Any] | None, saved: bool,
              limit: int) -> pa.Table:
        if not saved:
            return super().fetch(con, sql, params, saved, limit)
        import pyarrow as pa

        from tracelab.store.several import SeveralRunsConnection, each_run_stream
        assert isinstance(con, SeveralRunsConnection)
        schema, batches = each_run_stream(con, sql, params, limit)
        return pa.Table.from_batches(list(batches), schema=schema)


class LiveReads:
    """When a view re-reads a run on a timer: on every tick while the run is written, then once more
    after it closed (a read that begins after the close sees the writer's last flush: the writer flushes
    before it records its status), then never."""

    def __init__(self, source: RunSource) -> None:
        self.source = source
        self.done = False

    @property
    def due(self) -> bool:
        return not self.done

    @contextmanager
    def read(self) -> Iterator[bool]:
        """Around one re-read; yields whether it is the last one (the run had closed as it began)."""
        last = not self.source.live
        yield last
        if last:
            self.done = True
