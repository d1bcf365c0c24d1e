"""One open run for the TUI: its connection (tracelab.store.open_run) behind a lock, so that queries from
worker threads never overlap on it, and every statement through the store's read-only path
(query_readonly inside retrying). `interrupt()` cancels the running query (Esc)."""
from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import pyarrow as pa

from tracelab.store.catalog import short_command
from tracelab.store.reader import LiveRunConnection, RunConnection, open_run, query_readonly, retrying, run_info

T = TypeVar("T")


class RunSource:
    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        info = run_info(self.path)
        self.status: str = info.status
        self.command = short_command(str(info.meta.get("command") or ""))
        self.con: RunConnection = open_run(self.path)
        self.live = isinstance(self.con, LiveRunConnection)
        self._lock = threading.Lock()
        self._busy = 0

    @property
    def busy(self) -> bool:
        return self._busy > 0

    def call(self, fn: Callable[[RunConnection], T]) -> T:
        """fn(connection) alone on the connection (the explain functions take a connection)."""
        with self._lock:
            self._busy += 1
            try:
                return retrying(lambda: fn(self.con))
            finally:
                self._busy -= 1

    def arrow(self, sql: str, params: dict[str, Any] | None = None) -> pa.Table:
        return self.call(lambda con: query_readonly(con, sql, params).to_arrow_table())

    def rows(self, sql: str, params: dict[str, Any] | None = None) -> list[dict[str, Any]]:
        return self.arrow(sql, params).to_pylist()

    def scalar(self, sql: str, params: dict[str, Any] | None = None) -> Any:
        rows = self.call(lambda con: query_readonly(con, sql, params).fetchall())
        return rows[0][0] if rows else None

    def interrupt(self) -> bool:
        """Cancel the query running now, if any; True if there was one."""
        if not self.busy:
            return False
        self.con.interrupt()
        return True

    def close(self) -> None:
        with self._lock:
            self.con.close()
