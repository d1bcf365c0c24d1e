"""Row sources the lazy table pages from: `prepare()` (in a worker) returns the row count, `fetch(page)`
returns one page of PAGE rows as dicts. Nothing fetches more than the pages asked for.

- ArrowSource: rows already in memory (the run catalog, SQL console results).
- QuerySource: any read-only SELECT, paged with LIMIT/OFFSET under a total order (small tables: episodes,
  rules), its rows DuckDB's own (RunSource.rows): the Episodes table, the first screen, loads no Arrow.
- An episode's change rows: trace_paging.TraceSource (it loads numpy and the episode index).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from tracelab.viewers.tui.source import RunSource

if TYPE_CHECKING:
    import pyarrow as pa

PAGE = 256


class PageSource(Protocol):
    def prepare(self) -> int: ...     # may set `start_row`: where the cursor opens
    def fetch(self, page: int) -> list[dict[str, Any]]: ...
    def warm(self) -> None: ...        # optional work done when the table has fetched what it showed


def fetch_span(source: PageSource, first: int, last: int) -> list[tuple[int, list[dict[str, Any]]]]:
    """Pages first..last of any source (in one query where the source can)."""
    many = getattr(source, "fetch_pages", None)
    if many is not None:
        return many(first, last)
    return [(p, source.fetch(p)) for p in range(first, last + 1)]


class ArrowSource:
    def __init__(self, table: pa.Table) -> None:
        self.table = table

    def prepare(self) -> int:
        return self.table.num_rows

    def warm(self) -> None:
        pass

    def fetch(self, page: int) -> list[dict[str, Any]]:
        return self.table.slice(page * PAGE, PAGE).to_pylist()


ROW_COUNT = "tracelab_row_count"   # QuerySource's count column beside the first page's rows


class QuerySource:
    """`sql` (one SELECT) ordered by `order` (tie-broken by the caller: every ORDER BY is total)."""

    def __init__(self, source: RunSource, sql: str, order: str, params: dict[str, Any] | None = None
                 ) -> None:
        self.source, self.sql, self.order, self.params = source, sql, order, params
        self._first_page: list[dict[str, Any]] | None = None

    def prepare(self) -> int:
        """The row count, read with the first page in one statement (each costs its planning: the
        Episodes table is the first screen's, issue 40); the page is kept for the first fetch of it."""
        rows = self._page(0, f", count(*) OVER () AS {ROW_COUNT}")
        count = rows[0][ROW_COUNT] if rows else 0
        for row in rows:
            del row[ROW_COUNT]
        self._first_page = rows
        return int(count)

    def warm(self) -> None:
        pass

    def fetch(self, page: int) -> list[dict[str, Any]]:
        if page == 0 and self._first_page is not None:
            rows, self._first_page = self._first_page, None
            return rows
        return self._page(page)

    def _page(self, page: int, extra: str = "") -> list[dict[str, Any]]:
        return self.source.rows(f"SELECT *{extra} FROM ({self.sql}) ORDER BY {self.order} "
                                f"LIMIT {PAGE} OFFSET {page * PAGE}", self.params)
