"""LazyTable: a Line-API table that pages rows from a PageSource (tracelab.viewers.tui.paging).

It knows only the row count; render_line() draws the visible rows from cached pages and asks a worker
thread for the missing ones, so a table of 10M rows costs what a screenful costs. The header stays on
the first line; the cursor row is highlighted; arrows, PgUp/PgDn, Home/End, Enter and the mouse work.
textual's DataTable measures every cell up front and is far too slow past 10k rows (library notes)."""
from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from rich.style import Style
from rich.text import Text
from textual import events
from textual.binding import Binding
from textual.geometry import Size
from textual.message import Message
from textual.reactive import reactive
from textual.scroll_view import ScrollView
from textual.strip import Strip

from tracelab.viewers.tui.paging import PAGE, PageSource, fetch_span
from tracelab.viewers.tui.shown_text import shown, shown_text
from tracelab.viewers.tui.source import background

Row = dict[str, Any]
CACHED_PAGES = 64
WARM_AFTER_S = 0.5
CURSOR_FOCUSED = "#1f4e79"
CURSOR_BLURRED = "#3a3a3a"


def plain_cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass
class Column:
    key: str
    title: str
    width: int | None = None               # None: measured on the first page (at most max_width)
    render: Callable[[Row], Text | str] | None = None
    align: str = "left"
    max_width: int = 40
    flex: int = 0                          # share of the room left over when the table is wider
    min_width: int | None = None           # the width before any room was shared out
    narrowest: int | None = None           # a flex column narrower than the table's columns may go down to

    def cell(self, row: Row) -> Text:
        value = self.render(row) if self.render else plain_cell(row.get(self.key))
        return shown_text(value) if isinstance(value, Text) else shown(value)


def _narrow(columns: list[Column], excess: int) -> None:
    """Take `excess` cells from the columns, one at a time from the one with the most to spare above its
    `narrowest` (weighted by its flex), until none has any to spare."""
    while excess > 0:
        spare = max(columns, key=lambda c: (c.width - (c.narrowest or c.width)) * c.flex)  # type: ignore[operator]
        if spare.width <= (spare.narrowest or spare.width):  # type: ignore[operator]
            return
        spare.width -= 1  # type: ignore[operator]
        excess -= 1


class LazyTable(ScrollView, can_focus=True):
    BINDINGS = [
        Binding("up", "cursor(-1)", "up", show=False),
        Binding("down", "cursor(1)", "down", show=False),
        Binding("pageup", "page(-1)", "page up", show=False),
        Binding("pagedown", "page(1)", "page down", show=False),
        Binding("home", "jump_to(0)", "first", show=False),
        Binding("end", "jump_to(-1)", "last", show=False),
        Binding("enter", "select", "open", show=False),
    ]

    cursor = reactive(0)

    class RowHighlighted(Message):
        def __init__(self, table: "LazyTable", index: int, row: Row | None) -> None:
            super().__init__()
            self.table, self.index, self.row = table, index, row

        @property
        def control(self) -> "LazyTable":
            return self.table

    class RowSelected(RowHighlighted):
        pass

    class HeaderClicked(Message):
        def __init__(self, table: "LazyTable", column: Column) -> None:
            super().__init__()
            self.table, self.column = table, column

        @property
        def control(self) -> "LazyTable":
            return self.table

    class Loaded(Message):
        """The row count is known (after a new source was set)."""
        def __init__(self, table: "LazyTable", count: int) -> None:
            super().__init__()
            self.table, self.count = table, count

        @property
        def control(self) -> "LazyTable":
            return self.table

    def __init__(self, columns: list[Column] | None = None, *, name: str | None = None,
                 id: str | None = None, classes: str | None = None) -> None:
        super().__init__(name=name, id=id, classes=classes)
        # copies: widths are measured per table, never into the (often module-level) definitions
        self.columns: list[Column] = [replace(c) for c in columns or []]
        self.source: PageSource | None = None
        self.count = 0
        self.ready = False                # the count is known
        self.error: str | None = None
        self.sort_key: str | None = None
        self.sort_desc = False
        # what row 0 says while there is no source (nothing asked for yet): not "loading…", which is
        # true only while a source is being prepared
        self.placeholder = ""
        self._pages: OrderedDict[int, list[Row]] = OrderedDict()
        self._wanted: set[int] = set()
        self._inflight: set[int] = set()     # pages being fetched now
        self._fetching = False
        self._generation = 0
        self._pending_cursor: int | None = None
        self._guard = threading.Lock()
        # drawn rows by (index, cursor on it, focus, scroll x, width, style, version): textual asks for
        # every line on each refresh (~1 ms a row here), and a new filter repaints the same rows 2-3 times
        self._lines: dict[tuple[Any, ...], Strip] = {}
        self._version = 0          # bumped whenever a row's drawing may change (rows, widths, source)

    # ---- the data ------------------------------------------------------------------------------------
    def set_source(self, source: PageSource | None, columns: list[Column] | None = None,
                   cursor: int = 0) -> None:
        """Show `source` (prepared in a worker); the cursor goes to row `cursor` once it is known."""
        self._generation += 1
        self._redraw()
        self.source = source
        if columns is not None:
            self.columns = [replace(c) for c in columns]
            self._share_room()
        self._pages.clear()
        with self._guard:
            self._wanted.clear()
            self._inflight.clear()
        self.count, self.ready, self.error = 0, False, None
        self._pending_cursor = cursor
        self.virtual_size = Size(self._total_width(), 1)
        self.scroll_to(y=0, animate=False)
        self.refresh()
        if source is not None:
            # the rows the screen shows are read here, on the UI thread: a widget's size read in the worker
            # (a table in a hidden tab) made textual lay out the whole screen in that thread, which raised
            # LookupError (no active app there) and raced the UI thread's own layout
            generation, reach = self._generation, max(1, self.size.height)
            self.run_worker(lambda: self._prepare(source, generation, cursor, reach), thread=True,
                            group=f"prepare-{id(self)}", exclusive=True, exit_on_error=False)

    def _prepare(self, source: PageSource, generation: int, cursor: int, reach: int) -> None:
        """Count the rows and, in the same worker, fetch the page the cursor opens on (one round trip
        to the UI thread instead of two): the pages `reach` rows either side of it. In a worker thread:
        it reads none of the widget's state (set_source passes it in)."""
        start, pages, error = None, [], None
        try:
            count = source.prepare()
            start = getattr(source, "start_row", None)
            target = start if start else cursor
            target = max(0, min(count - 1, target if target >= 0 else count + target))
            if count:  # the cursor's page, and the next or previous one if the screen reaches into it
                pages = fetch_span(source, max(0, target - reach) // PAGE, min(count - 1, target + reach) // PAGE)
        except Exception as e:  # noqa: BLE001 - shown in the table, the app goes on
            count, error = 0, str(e) or type(e).__name__
        self.app.call_from_thread(self._prepared, generation, count, error, start, pages)

    def _start_warm(self, generation: int) -> None:
        """Warm the source (e.g. the trace's anchors) once the user has looked at it for WARM_AFTER_S:
        a filter typed and changed quickly never waits behind the warm-up of the one before."""
        source = self.source
        if generation != self._generation or source is None:
            return

        def warm() -> None:
            try:
                source.warm()
            except Exception:  # noqa: BLE001 - a failing warm-up shows up again when a page needs it
                pass

        self.run_worker(background(warm), thread=True, group=f"warm-{id(self)}", exit_on_error=False)

    def _prepared(self, generation: int, count: int, error: str | None, start: int | None = None,
                  pages: list[tuple[int, list[Row]]] | None = None) -> None:
        if generation != self._generation:
            return
        self.count, self.ready, self.error = count, True, error
        self.virtual_size = Size(self._total_width(), count + 1)
        for page, rows in pages or []:
            self.put_page(page, rows)
        target = start if start else (self._pending_cursor or 0)
        self._pending_cursor = None
        if error is None:
            self.set_timer(WARM_AFTER_S, lambda: self._start_warm(generation))
        self.cursor = -1  # make the watcher fire even if the row number did not change
        self.move_to(target)
        self.refresh()
        self.post_message(self.Loaded(self, count))

    def row(self, index: int) -> Row | None:
        page = self._pages.get(index // PAGE)
        if page is None or index % PAGE >= len(page):
            return None
        return page[index % PAGE]

    @property
    def cursor_row(self) -> Row | None:
        return self.row(self.cursor)

    @property
    def idle(self) -> bool:
        """Nothing is being prepared or fetched, and every visible row is here."""
        if not self.ready or self._fetching or self._wanted:
            return False
        if not self.count:
            return True
        first = max(0, min(int(self.scroll_offset.y), self.count - 1))
        last = min(self.count, first + self._visible_rows) - 1
        return all(p in self._pages for p in range(first // PAGE, last // PAGE + 1))

    def _want(self, page: int) -> None:
        with self._guard:
            if page in self._inflight:
                return
            self._wanted.add(page)
            start = not self._fetching
            self._fetching = True
        if start:
            source, generation = self.source, self._generation   # read here, not in the worker
            self.run_worker(lambda: self._fetch(source, generation), thread=True,
                            group=f"fetch-{id(self)}", exit_on_error=False)

    def _fetch(self, source: PageSource | None, generation: int) -> None:
        while True:
            with self._guard:
                if generation != self._generation or source is None:
                    self._fetching = False  # set_source() cleared the wish list; restart for the new source
                    if self._wanted:
                        self.app.call_from_thread(self._restart)
                    return
                if not self._wanted:
                    self._fetching = False
                    break
                page = min(self._wanted)
                self._wanted.discard(page)
                self._inflight.add(page)
            try:
                rows, error = source.fetch(page), None
            except Exception as e:  # noqa: BLE001
                rows, error = [], str(e)
            self.app.call_from_thread(self._arrived, generation, page, rows, error)
            with self._guard:
                self._inflight.discard(page)

    def _restart(self) -> None:
        pages = set(self._wanted)
        self._wanted.clear()
        for page in pages:
            self._want(page)

    def _arrived(self, generation: int, page: int, rows: list[Row], error: str | None) -> None:
        if generation != self._generation:
            return
        if error:
            self.error = error
        self.put_page(page, rows)

    def put_page(self, page: int, rows: list[Row]) -> None:
        """Cache a page fetched elsewhere (by a worker that also found where to move the cursor)."""
        self._pages[page] = rows
        self._pages.move_to_end(page)
        self._redraw()
        while len(self._pages) > CACHED_PAGES:
            self._pages.popitem(last=False)
        if any(c.width is None for c in self.columns) and rows:
            self._measure(rows)
        self.refresh()
        if page == self.cursor // PAGE:
            self.post_message(self.RowHighlighted(self, self.cursor, self.cursor_row))

    def _redraw(self) -> None:
        """Forget the drawn rows (new rows, source or column widths)."""
        self._version += 1
        self._lines.clear()

    def _measure(self, rows: list[Row]) -> None:
        self._redraw()
        for c in self.columns:
            if c.width is None:
                c.width = min(c.max_width, max([len(c.title) + 1, *(c.cell(r).cell_len for r in rows)]))
        self.virtual_size = Size(self._total_width(), self.count + 1)

    def _total_width(self) -> int:
        return sum((c.width or len(c.title) + 1) + 1 for c in self.columns)

    # ---- drawing -------------------------------------------------------------------------------------
    def render_line(self, y: int) -> Strip:
        scroll_x, scroll_y = self.scroll_offset
        width = self.size.width
        base = self.rich_style
        if y == 0:
            text = self._header()
            return Strip(text.render(self.app.console), text.cell_len).crop_extend(scroll_x, scroll_x + width, base)
        index = scroll_y + y - 1
        key = (index, index == self.cursor, self.has_focus, scroll_x, width, base, self._version)
        strip = self._lines.get(key)
        if strip is None:
            text = self._line(index)
            strip = Strip(text.render(self.app.console), text.cell_len).crop_extend(scroll_x, scroll_x + width, base)
            if self.row(index) is not None:     # placeholders ("…", loading) are not kept
                if len(self._lines) > 4096:
                    self._lines.clear()
                self._lines[key] = strip
        return strip

    def _header(self) -> Text:
        text = Text(style="bold")
        for c in self.columns:
            width = c.width or len(c.title) + 1
            title = c.title
            if c.key == self.sort_key:  # the marker always shows; the title gives way
                title = title[: max(1, width - 1)] + ("▼" if self.sort_desc else "▲")
            text.append(self._fit(Text(title), width, c.align))
            text.append(" ")
        text.stylize(Style(underline=True))
        return text

    def _line(self, index: int) -> Text:
        if index == 0 and self.source is None:
            return Text(self.placeholder, style="italic")
        if index == 0 and not self.ready:
            return Text("  loading…  (Esc cancels)", style="italic")
        if index == 0 and self.error:
            return shown(self.error.splitlines()[0], "bold red")
        if index >= self.count:
            if index == 0 and self.ready:
                return Text("  (no rows)", style="italic")
            return Text("")
        row = self.row(index)
        if row is None:
            self._want(index // PAGE)
            return Text("  …", style="dim")
        text = Text()
        for c in self.columns:
            text.append(self._fit(c.cell(row), c.width or len(c.title) + 1, c.align))
            text.append(" ")
        if index == self.cursor:
            text.pad_right(max(0, self.size.width + int(self.scroll_offset.x) - text.cell_len))
            text.stylize(Style(bgcolor=CURSOR_FOCUSED if self.has_focus else CURSOR_BLURRED))
        return text

    @staticmethod
    def _fit(cell: Text, width: int, align: str) -> Text:
        if cell.cell_len > width:
            cell = cell.copy()
            cell.truncate(width - 1)
            cell.append("…")
        pad = width - cell.cell_len
        if align == "right":
            return Text(" " * pad) + cell
        return cell + Text(" " * pad)

    def on_resize(self) -> None:
        self._share_room()
        # narrower (a pane shown beside it) the table may gain a horizontal scrollbar over its last line
        self.call_after_refresh(self._scroll_to_cursor)

    def _share_room(self) -> None:
        """Widen the flex columns to fill the widget (back to their own width when it shrinks); in a widget
        narrower than the columns, narrow them down to their `narrowest` first, so that the last column
        is not cut to a few characters behind a sideways scroll (the trace beside the board at 80x24)."""
        self._redraw()
        flex = [c for c in self.columns if c.flex and c.width is not None]
        if not flex:
            return
        for c in flex:
            c.min_width = c.min_width or c.width
            c.width = c.min_width
        room = self.size.width - self._total_width() - 2   # the scrollbar
        total = sum(c.flex for c in flex)
        for c in flex:
            c.width = min(c.max_width, c.width + max(0, room) * c.flex // total)  # type: ignore[operator]
        _narrow(flex, -room)
        self.virtual_size = Size(self._total_width(), self.virtual_size.height)
        self.refresh()

    def on_focus(self) -> None:
        self.refresh()

    def on_blur(self) -> None:
        self.refresh()

    # ---- the cursor ------------------------------------------------------------------------------------
    @property
    def _visible_rows(self) -> int:
        """Rows on screen under the header: a horizontal scrollbar (a narrow table) takes the last line."""
        return max(1, self.scrollable_content_region.height - 1)

    def move_to(self, index: int) -> None:
        if not self.ready:
            self._pending_cursor = index
            return
        if self.count == 0:
            self.cursor = 0
            return
        self.cursor = max(0, min(self.count - 1, index if index >= 0 else self.count + index))

    def watch_cursor(self, old: int, new: int) -> None:
        if new < 0:
            return
        self._scroll_to_cursor()
        self.refresh()
        if self.ready and new < self.count and new // PAGE not in self._pages:
            self._want(new // PAGE)
        if self.ready:
            self.post_message(self.RowHighlighted(self, new, self.cursor_row))

    def _scroll_to_cursor(self) -> None:
        new, visible, top = self.cursor, self._visible_rows, int(self.scroll_offset.y)
        # force: right after a new source the scrollbar is not laid out yet and textual would refuse to
        # scroll, leaving rows 0.. on screen (and fetching page 0) instead of the cursor's page
        if new < top:
            self.scroll_to(y=new, animate=False, immediate=True, force=True)
        elif new >= top + visible:
            self.scroll_to(y=new - visible + 1, animate=False, immediate=True, force=True)

    def action_cursor(self, delta: int) -> None:
        self.move_to(self.cursor + delta)

    def action_page(self, direction: int) -> None:
        self.move_to(self.cursor + direction * max(1, self._visible_rows - 1))

    def action_jump_to(self, index: int) -> None:
        self.move_to(index)

    def action_select(self) -> None:
        if self.ready and self.count:
            self.post_message(self.RowSelected(self, self.cursor, self.cursor_row))

    def on_click(self, event: events.Click) -> None:
        offset = event.get_content_offset(self)
        if offset is None:
            return
        if offset.y == 0:
            x = offset.x + int(self.scroll_offset.x)
            for c in self.columns:
                w = (c.width or len(c.title) + 1) + 1
                if x < w:
                    self.post_message(self.HeaderClicked(self, c))
                    return
                x -= w
            return
        index = int(self.scroll_offset.y) + offset.y - 1
        if 0 <= index < self.count:
            if index == self.cursor and event.chain >= 2:
                self.action_select()
            self.move_to(index)
