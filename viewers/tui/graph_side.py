"""GraphSide: what stands beside the trace where a game run has its board, for a run without one (a
reasoning run, a world without a `[board]`). Above: the atoms true at the end of the cursor's timestep, or the atoms changed in it
(`c`), filtered by a predicate name or an atom pattern (`exposed`, `exposed(*)`; `/`), each with its bound,
at most graph_state.ATOMS_LIMIT of them with the count of all. Below: the neighbourhood in the graph of
the selected atom (the trace's cursor, or the list's when it has the focus): its node's labels, edges
and their labels with their bounds at that time. Enter on an atom shows only its changes in the trace.
Everything is read per timestep by bounded queries in workers (graph_state.py), each kind on its own
connection to the run: on a run of millions of changes a read of the atoms takes seconds, and neither
the trace's pages nor the neighbourhood wait behind it; a read for a timestep the cursor has left is
interrupted."""
from __future__ import annotations

import threading
from typing import Any

import pyarrow as pa
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.message import Message
from textual.timer import Timer
from textual.widget import Widget
from textual.widgets import Input, Static

from tracelab.viewers.tui.colours import DIM, bound_colour, styled_bound
from tracelab.viewers.tui.graph_state import AtomsAt, Neighbourhood, atoms_at, neighbourhood, unknown_pattern
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.paging import ArrowSource
from tracelab.viewers.tui.source import RunSource
from tracelab.viewers.tui.shown_text import shown

ARROWS = {"out": "→", "in": "←", "both": "↔"}
# the atoms are read once the trace's cursor rests on a timestep this long, not for every row passed
SETTLE_S = 0.15


def _bound(row: dict[str, Any]) -> Text:
    return styled_bound(row["lower"], row["upper"])


def _change(row: dict[str, Any]) -> Text:
    return styled_bound(row["old_lower"], row["old_upper"]) + Text("→", style=DIM) + \
        styled_bound(row["lower"], row["upper"])


# atom, its bound at the end of t and the t it was last set (true); its bound before t and after (changed)
TRUE_COLUMNS = [Column("atom", "atom", 14, flex=1, max_width=60),
                Column("bound", "bound", None, render=_bound, max_width=11),
                Column("last_t", "t", 3, align="right")]
CHANGED_COLUMNS = [Column("atom", "atom", 14, flex=1, max_width=60),
                   Column("change", "old→new", None, render=_change, max_width=23)]


def _labels(labels: list[tuple[str, float, float]]) -> list[Text]:
    return [Text(label, style=bound_colour(lower, upper)) for label, lower, upper in labels]


def _flow(prefix: Text, words: list[Text], width: int, indent: int) -> Text:
    """prefix and words separated by spaces, wrapped at `width` between words, continuation lines
    indented by `indent` (so a neighbour's labels stay under it)."""
    text = prefix.copy()
    x = text.cell_len
    for word in words:
        if x > indent and x + 1 + word.cell_len > width:
            text.append("\n" + " " * indent)
            x = indent
        elif x > 0:
            text.append(" ")
            x += 1
        text.append_text(word)
        x += word.cell_len
    return text


def draw_neighbourhood(hood: Neighbourhood, width: int = 80) -> Text:
    """The node(s) of an atom: their labels, then a line per neighbour (→ out, ← in, ↔ both ways) with
    the labels on the pair and after `·` the neighbour's own, coloured by their bound at t; wrapped at
    `width` under the neighbour's name."""
    lines: list[Text] = []
    for node in hood.nodes:
        lines.append(_flow(Text.assemble((node.node, "bold")), _labels(node.labels), width, 2))
        for n in node.neighbours:
            words = _labels(n.labels) if n.labels else [Text("edge", style=DIM)]
            own = _labels(n.other_labels)     # what the neighbour itself is at t, after a `·`
            if own:
                words += [Text("· ", style=DIM) + own[0], *own[1:]]
            lines.append(_flow(Text.assemble((f" {ARROWS[n.direction]} ", DIM), n.other), words, width, 5))
        shown = len(node.neighbours)
        more = f"first {shown} of {node.degree:,} neighbours" if node.degree > shown else \
            "no edges" if not shown else f"{shown} neighbour{'s' if shown != 1 else ''}"
        lines.append(Text(f" {more}", style=f"italic {DIM}"))
    if not hood.nodes:
        lines.append(shown(f"{hood.atom}: not an atom of this run", f"italic {DIM}"))
    return Text("\n").join(lines)


class HoodText(Widget):
    """The neighbourhood, drawn at the pane's width (its lines wrap under each neighbour's name)."""
    def __init__(self) -> None:
        super().__init__(id="gs-hood-text")
        self.hood: Neighbourhood | None = None
        self.note = Text("select a change or an atom: its node's edges show here", style=f"italic {DIM}")

    def show(self, hood: Neighbourhood | None, note: Text | None = None) -> None:
        self.hood, self.note = hood, note or self.note
        self.refresh(layout=True)

    def render(self) -> Text:
        return self.note if self.hood is None else draw_neighbourhood(self.hood, max(20, self.size.width))


class GraphSide(Vertical):
    BINDINGS = [
        Binding("slash", "focus_filter", "filter atoms"),
        Binding("c", "toggle_mode", "true/changed"),    # also from the trace (TracePane)
    ]
    class OnlyAtom(Message):
        """Show only this atom's changes in the trace (Enter on an atom of the list)."""
        def __init__(self, atom_id: int) -> None:
            super().__init__()
            self.atom_id = atom_id

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.mode = "true"
        self.hide_static = True
        self.atoms: AtomsAt | None = None         # the list shown (tests wait on it)
        self.hood: Neighbourhood | None = None
        self._episode: int | None = None
        self._t: int | None = None
        self._trace_atom: int | None = None        # the trace cursor's atom
        self._asked: tuple[Any, ...] | None = None  # the list last asked for
        self._hood_asked: tuple[int, int, int] | None = None
        self._settle: Timer | None = None
        self._readers: dict[str, RunSource] = {}     # "atoms", "hood": connections of their own
        self._readers_lock = threading.Lock()
        self._closed = False

    def compose(self) -> ComposeResult:
        with Vertical(id="gs-atoms"):
            yield Input(placeholder="atoms: exposed or exposed(*)", id="gs-filter", compact=True)
            yield LazyTable(TRUE_COLUMNS, id="gs-table")
            yield Static("", id="gs-status")
        with VerticalScroll(id="gs-hood"):
            yield HoodText()

    def on_mount(self) -> None:
        self.query_one("#gs-atoms").border_title = "atoms"
        self.query_one("#gs-hood").border_title = "graph"
        self.query_one("#gs-table", LazyTable).placeholder = "select a change in the trace"

    @property
    def table(self) -> LazyTable:
        return self.query_one("#gs-table", LazyTable)

    def _reader(self, kind: str) -> RunSource:
        """The run opened again for one kind of read (in the worker that first needs it)."""
        with self._readers_lock:
            if self._closed:        # unmounted while this worker waited: open nothing that stays open
                raise RuntimeError("the run was closed")
            if kind not in self._readers:
                self._readers[kind] = RunSource(self.source.path)
            return self._readers[kind]

    def _interrupt(self, kind: str) -> None:
        """Cancel a read of `kind` that is no longer wanted (its worker's answer is dropped as stale)."""
        with self._readers_lock:
            reader = self._readers.get(kind)
        if reader is not None:
            reader.interrupt()

    def on_unmount(self) -> None:
        with self._readers_lock:
            readers, self._readers, self._closed = list(self._readers.values()), {}, True
        for reader in readers:
            reader.close()

    # ---- following the trace -----------------------------------------------------------------------------
    def show(self, episode: int, t: int, atom_id: int | None) -> None:
        """Follow the trace's cursor: the atoms at timestep t of `episode`, and the neighbourhood of
        `atom_id` (unless the list has the focus: then its atom's)."""
        self._episode, self._t, self._trace_atom = episode, t, atom_id
        if self._settle is not None:
            self._settle.stop()
        self._settle = self.set_timer(SETTLE_S, self._follow)

    def _follow(self) -> None:
        self.reload()
        if not self.table.has_focus and self._trace_atom is not None:
            self._show_hood(self._trace_atom)

    def reread(self) -> None:
        """Read the list and the neighbourhood again (a live run's episode grew under the cursor)."""
        self._hood_asked = None
        self.reload(force=True)
        atom = self._trace_atom if not self.table.has_focus else \
            (self.table.cursor_row or {}).get("atom_id", self._trace_atom)
        if atom is not None:
            self._show_hood(int(atom))

    def reload(self, force: bool = False) -> None:
        """Ask for the list at the current time, mode, filter and static choice, if that changed."""
        if self._episode is None or self._t is None:
            return
        pattern = self.query_one("#gs-filter", Input).value.strip()
        asked = (self._episode, self._t, self.mode, pattern, self.hide_static)
        if asked == self._asked and not force:
            self._place_cursor()
            return
        self._asked = asked
        self.query_one("#gs-atoms").border_title = f"atoms {self.mode} at t={self._t}"
        self.query_one("#gs-status", Static).update(Text("reading…", style=DIM))
        self._interrupt("atoms")
        self.run_worker(lambda: self._read_atoms(asked), thread=True, group="graph-atoms", exclusive=True,
                        exit_on_error=False)

    def _read_atoms(self, asked: tuple[Any, ...]) -> None:
        episode, t, mode, pattern, hide_static = asked
        problem = None
        try:
            reader = self._reader("atoms")
            if asked != self._asked:     # the cursor moved on while this worker waited
                return
            found = atoms_at(reader, episode, t, mode, pattern, hide_static)
            if not found.rows and pattern:
                problem = unknown_pattern(reader, pattern)
        except Exception as e:  # noqa: BLE001 - a bad pattern or a cancelled query: a message, not a crash
            found, problem = None, str(e).splitlines()[0] if str(e) else type(e).__name__
        self.app.call_from_thread(self._atoms_read, asked, found, problem)

    def _atoms_read(self, asked: tuple[Any, ...], found: AtomsAt | None, problem: str | None) -> None:
        if asked != self._asked:
            return
        self.atoms = found
        table, status = self.table, self.query_one("#gs-status", Static)
        rows = found.rows if found is not None else []
        columns = TRUE_COLUMNS if self.mode == "true" else CHANGED_COLUMNS
        table.set_source(ArrowSource(pa.Table.from_pylist(rows)) if rows else None, columns,
                         cursor=self._row_of(self._trace_atom))
        if problem is not None or found is None:
            table.placeholder = ""
            status.update(shown(problem or "cannot read the atoms", "bold red"))
            return
        table.placeholder = f"no atom {found.mode} at t={found.t}"
        status.update(self._describe(found, asked[3]))

    def _describe(self, found: AtomsAt, pattern: str) -> Text:
        what = f"{found.total:,} {found.mode}" + (f" matching {pattern}" if pattern else "")
        if found.truncated:   # the list holds the first ATOMS_LIMIT: a filter (/) finds the others
            what = f"first {len(found.rows):,} of {what}"
        if found.static_hidden:
            what += f" · {found.static_hidden:,} static hidden (s)"
        return shown(what)

    def _row_of(self, atom_id: int | None) -> int:
        rows = self.atoms.rows if self.atoms is not None else []
        return next((i for i, r in enumerate(rows) if r["atom_id"] == atom_id), 0)

    def _place_cursor(self) -> None:
        """Put the list's cursor on the trace's atom when the list shows it (and does not have the focus)."""
        if not self.table.has_focus and self.atoms is not None and self.table.ready:
            self.table.move_to(self._row_of(self._trace_atom))

    # ---- the neighbourhood ------------------------------------------------------------------------------
    def _show_hood(self, atom_id: int) -> None:
        if self._episode is None or self._t is None:
            return
        asked = (self._episode, self._t, atom_id)
        if asked == self._hood_asked:
            return
        self._hood_asked = asked
        self._interrupt("hood")
        self.run_worker(lambda: self._read_hood(asked), thread=True, group="graph-hood", exclusive=True,
                        exit_on_error=False)

    def _read_hood(self, asked: tuple[int, int, int]) -> None:
        try:
            reader = self._reader("hood")
            if asked != self._hood_asked:
                return
            hood: Neighbourhood | str = neighbourhood(reader, *asked)
        except Exception as e:  # noqa: BLE001
            hood = str(e).splitlines()[0] if str(e) else type(e).__name__
        self.app.call_from_thread(self._hood_read, asked, hood)

    def _hood_read(self, asked: tuple[int, int, int], hood: Neighbourhood | str) -> None:
        if asked != self._hood_asked:
            return
        box, text = self.query_one("#gs-hood"), self.query_one(HoodText)
        if isinstance(hood, str):
            self.hood = None
            text.show(None, shown(hood, "bold red"))
            return
        self.hood = hood
        box.border_title = shown(f"{hood.atom} at t={hood.t}")
        text.show(hood)

    # ---- the list's own events and keys -------------------------------------------------------------------
    def on_lazy_table_loaded(self, event: LazyTable.Loaded) -> None:
        event.stop()

    def on_lazy_table_row_highlighted(self, event: LazyTable.RowHighlighted) -> None:
        event.stop()
        if event.row is not None and self.table.has_focus:
            self._show_hood(int(event.row["atom_id"]))

    def on_lazy_table_row_selected(self, event: LazyTable.RowSelected) -> None:
        event.stop()
        if event.row is not None:
            self.post_message(self.OnlyAtom(int(event.row["atom_id"])))

    def on_descendant_focus(self) -> None:
        row = self.table.cursor_row if self.table.has_focus else None
        if row is not None:
            self._show_hood(int(row["atom_id"]))

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self.reload()
        self.table.focus()

    def action_focus_filter(self) -> None:
        self.query_one("#gs-filter", Input).focus()

    def action_toggle_mode(self) -> None:
        self.mode = "changed" if self.mode == "true" else "true"
        self.reload()

    def set_hide_static(self, hide: bool) -> None:
        self.hide_static = hide
        self.reload()
