"""The Trace view: the method's trace table of one episode (t, node/edge, label, old -> new, rule), paged
lazily by seq (TraceSource). Filters: a time range (`3..9`), atom, label and rule GLOBs; `g` jumps to a
timestep; `n` / `p` move to the next / previous change of the selected atom; Enter or `w` opens the why
tree of the selected change; `a` shows only the selected atom's changes; `b` shows or hides the board
(shown by default when the terminal is at least 100 columns wide), or on a run without a board the
atoms at the cursor's time and the selected atom's graph neighbourhood (graph_side.py; `c` true or
changed); `s` shows or hides the rows of static facts (hidden by default: the status line says how
many). Cells read `30@(6,3)` where the run declares a grid. In a training run `]` / `[` move to the
next / previous evaluation game (the filters and the cursor's timestep kept), and a header line says which
game is shown. On a live run the trace is re-read when the episode grows. Under the board (any run whose
world has one: source.RunSource.board) the decision of the cursor's step: the policy's value of each action, the
chosen one, explored or greedy, the reward by term (decision.py; `d` moves into it, `w` there explains the
decision as `tracelab why --action` does)."""
from __future__ import annotations

import re
from typing import Any

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.reactive import reactive
from textual.widgets import Input, Static

from tracelab.store.names import UnknownName, check_name
from tracelab.viewers.tui.colours import DIM, styled_bound, styled_name
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.board import BoardView, drawn_width
from tracelab.viewers.tui.decision import DecisionPanel
from tracelab.viewers.tui.eval_games import EvalGame, eval_games, neighbour
from tracelab.viewers.tui.graph_side import GraphSide
from tracelab.viewers.tui.messages import ExplainChange
from tracelab.viewers.tui.paging import PAGE
from tracelab.viewers.tui.trace_paging import TraceFilter, TraceSource
from tracelab.viewers.tui.places import TracePlace
from tracelab.viewers.tui.source import LiveReads, RunSource, background
from tracelab.viewers.tui.shown_text import shown
from tracelab.engine.terminal_text import printable


def _change(row: dict[str, Any]) -> Text:
    return styled_bound(row["old_lower"], row["old_upper"]) + Text(" → ", style=DIM) + \
        styled_bound(row["new_lower"], row["new_upper"])


def _rule(row: dict[str, Any]) -> Text:
    rule = row["rule"] or ""
    return Text(rule, style=DIM if rule.startswith("fact:") else "")


TRACE_COLUMNS = [
    Column("t", "t", 5, align="right"),
    Column("node", "node/edge", 18, render=lambda r: styled_name(r.get("place", r["node"])), flex=2, max_width=34,
           narrowest=12),
    Column("label", "label", 12, flex=1, max_width=18, narrowest=7),
    Column("change", "old → new", 15, render=_change),
    # beside the board at 80 columns the table has 58: every column fits, the rule still 12 wide
    Column("rule", "rule", 22, render=_rule, flex=2, max_width=40, narrowest=12),
]

LIVE_REFRESH_S = 2.0
BOARD_MIN_WIDTH = 100      # the table needs ~78 columns, the board ~22 (the atoms beside it 36%)
SIDE_MIN_WIDTH = 22        # the board's side: the decision panel's bars need ~20 columns
SIDE_ROOMY_WIDTH = 32      # with a decision shown, where the table keeps TABLE_WIDTH: its names whole
TABLE_WIDTH = 86           # the table's columns at their natural widths

_RANGE = re.compile(r"^\s*(-?\d+)?\s*(?:\.\.\s*(-?\d+)?)?\s*$")


def parse_range(text: str) -> tuple[int | None, int | None]:
    """`3..9`, `3..`, `..9` or `5` (one timestep); raises ValueError."""
    text = text.strip()
    if not text:
        return None, None
    m = _RANGE.match(text)
    if not m or (m.group(1) is None and ".." not in text):
        raise ValueError(f"cannot read time range {text!r}: write 3..9, 3.., ..9 or 5")
    lo, hi = (None if g is None else int(g) for g in m.groups())
    return (lo, lo) if ".." not in text else (lo, hi)


class TracePane(Vertical):
    BINDINGS = [
        Binding("g", "focus('#tr-goto')", "goto t"),
        Binding("slash", "focus('#tr-atom')", "filter"),
        Binding("n", "next_change(1)", "next"),
        Binding("p", "next_change(-1)", "prev"),
        Binding("w", "why", "why"),
        Binding("d", "focus_decision", "decision"),      # the step's decision beside the board (check_action)
        Binding("a", "only_atom", "only atom", show=False),
        Binding("x", "clear", "clear filters", show=False),
        Binding("b", "toggle_board", "board"),
        Binding("b", "toggle_side", "atoms"),           # a run without a board (check_action)
        Binding("c", "atoms_mode", "true/changed"),     # the atoms beside it: true at t or changed in t
        Binding("s", "toggle_static", "static facts", show=False),
        # one entry in the key bar for both, so that it fits in 80 columns
        Binding("right_square_bracket", "eval_game(1)", "eval games", key_display="]/["),
        Binding("left_square_bracket", "eval_game(-1)", "previous eval game", show=False),
    ]
    # Setting one of these shows it (its watch_ method): by a key, the terminal's width or a reopened place.
    side_shown = reactive(True, init=False, bindings=True)   # the board, or the atoms, beside the table (b)
    hide_static = reactive(True, init=False)                 # the rows of static facts left out (s)

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.filter: TraceFilter | None = None
        self.trace: TraceSource | None = None
        self._goto_t: int | None = None
        self.jumps = 0            # jumps that landed (benchmarks and tests wait on it)
        self._board_choice: bool | None = None   # the user's b, else side_shown follows the width
        self.live_reads = LiveReads(source)

    def compose(self) -> ComposeResult:
        game = Static("", id="tr-game", classes="title", markup=False)  # a run's params and outcomes are anyone's
        game.display = False           # shown for the episodes of a training run
        yield game
        with Horizontal(id="tr-filters"):
            yield Input(placeholder="t 3..9", id="tr-range", compact=True)
            yield Input(placeholder="atom glob", id="tr-atom", compact=True)
            yield Input(placeholder="label", id="tr-label", compact=True)
            yield Input(placeholder="rule glob", id="tr-rule", compact=True)
            yield Input(placeholder="go to t", id="tr-goto", compact=True)
        with Horizontal(id="tr-body"):
            yield LazyTable(TRACE_COLUMNS, id="tr-table")
            if self.source.board is not None:
                with Vertical(id="tr-side"):
                    yield BoardView(self.source, self.source.board)
                    yield DecisionPanel(self.source)
            else:
                yield GraphSide(self.source)
        yield Static(" choose an episode (1 Episodes, Enter)", id="tr-status", classes="status")

    def place(self) -> TracePlace | None:
        """Where the user is (None: no episode opened), for reopening the run later in the session."""
        if self.filter is None:
            return None
        row = self.table.cursor_row
        value = lambda name: self.field(name).value  # noqa: E731
        return TracePlace(self.filter.episode, value("range"), value("atom"), value("label"),
                          value("rule"), self.filter.atom_id, self.hide_static, self._board_choice,
                          None if row is None else int(row["seq"]))

    def reopen(self, place: TracePlace) -> None:
        """Show the episode, filters and cursor of `place` (the run was left there earlier)."""
        for name, text in (("range", place.time_range), ("atom", place.atom),
                           ("label", place.label), ("rule", place.rule)):
            self.field(name).value = text
        self.hide_static, self._board_choice = place.hide_static, place.board
        if place.board is not None:
            self.side_shown = place.board
        self.apply_filters(place.episode, keep_seq=place.seq, atom_id=place.atom_id)
        self._read_game_later(place.episode)

    def _read_game_later(self, episode: int) -> None:
        self.run_worker(background(lambda: self._read_game(episode)), thread=True, group="trace-game", exclusive=True,
                        exit_on_error=False)

    def on_mount(self) -> None:
        if self.source.live:   # rows of the episode may still be arriving
            self.set_interval(LIVE_REFRESH_S, self._follow)

    def _follow(self) -> None:
        """On a live run, re-read the trace when the episode has grown (the cursor stays on its change)."""
        trace = self.trace
        if (not self.live_reads.due or trace is None or not self.table.ready or self.source.busy
                or not self.screen.is_current):
            return

        def work() -> None:
            with self.live_reads.read():
                grown = trace.count_now() > trace.count
            if grown and trace is self.trace:
                self.app.call_from_thread(self._refollow)

        self.run_worker(background(work), thread=True, group="trace-follow", exclusive=True, exit_on_error=False)

    def _refollow(self) -> None:
        side = self.side
        if isinstance(side, GraphSide) and self.side_shown:   # the grown episode may change the atoms at t
            side.reread()
        self._refilter()

    def _refilter(self, keep_atom: bool = True) -> None:
        """Apply the filters again, the cursor kept on its change (or the next one shown); `keep_atom`: and
        the selected atom's filter (a, or Enter on an atom beside the trace)."""
        row = self.table.cursor_row
        self.apply_filters(keep_seq=None if row is None else int(row["seq"]),
                           atom_id=self.filter.atom_id if keep_atom and self.filter is not None else None)

    @property
    def board(self) -> BoardView | None:
        return next(iter(self.query(BoardView)), None) if self.is_mounted else None

    @property
    def side_box(self) -> Vertical:
        """What `b` shows or hides beside the table: the board with the decision under it, or the atoms."""
        return self.query_one("#tr-body > #tr-side, #tr-body > GraphSide")  # type: ignore[return-value]

    @property
    def decision(self) -> DecisionPanel | None:
        """The panel of the cursor's step's decision (None: a run without a board of any kind)."""
        return next(iter(self.query(DecisionPanel)), None) if self.is_mounted else None

    @property
    def side(self) -> BoardView | GraphSide:
        """What stands beside the table: the board of a game run, else the atoms and the graph."""
        return self.query_one("#tr-side > BoardView, #tr-body > GraphSide")  # type: ignore[return-value]

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        # a run without a board has its atoms beside the trace (key b: "atoms"); evaluation games are a
        # training's (a live run may get them): a play run is not offered a key that can only say no
        if action == "eval_game":
            return self.source.has_eval_games or self.source.live
        if action == "toggle_board":
            return self.source.board is not None
        if action == "toggle_side":
            return self.source.board is None
        if action == "atoms_mode":
            return self.source.board is None and self.side_shown
        if action == "focus_decision":   # offered while the cursor's step has a decision shown
            panel = self.decision
            return panel is not None and panel.display and self.side_shown
        return True

    def watch_side_shown(self, shown: bool) -> None:
        """The board (or the atoms) beside the table shown or hidden, at the cursor's change once shown; `c`
        and `d` are offered while it shows (bindings=True)."""
        self.side_box.display = shown
        row = self.table.cursor_row
        if shown and row is not None:
            self._follow_cursor(row)

    def watch_hide_static(self, hide: bool) -> None:
        """The rows of static facts left out or shown, in the table and in the atoms beside it."""
        side = self.side
        if isinstance(side, GraphSide):
            side.set_hide_static(hide)
        self._refilter()

    def _size_side(self) -> None:
        """The board's side: as wide as the board (and its border), at least the decision panel's bars;
        with a decision shown, roomier where the table keeps its natural widths (action and reward term
        names whole)."""
        if self.source.board is None:
            return
        panel = self.decision
        roomy = min(SIDE_ROOMY_WIDTH, self.size.width - TABLE_WIDTH) if panel is not None and panel.display else 0
        self.side_box.styles.width = max(SIDE_MIN_WIDTH, drawn_width(self.source.board) + 2, roomy)

    def on_resize(self) -> None:
        self._size_side()
        if self._board_choice is None:   # by default the board shows when there is room beside the table
            self.side_shown = self.size.width >= BOARD_MIN_WIDTH

    def action_toggle_board(self) -> None:
        self._board_choice = self.side_shown = not self.side_shown

    action_toggle_side = action_toggle_board

    def action_atoms_mode(self) -> None:
        side = self.side
        if isinstance(side, GraphSide):
            side.action_toggle_mode()

    def _follow_cursor(self, row: dict[str, Any]) -> None:
        """The board, or the atoms and the graph, at the change the cursor is on."""
        if self.filter is None:
            return
        side = self.side
        if isinstance(side, BoardView):
            side.show(self.filter.episode, int(row["t"]), int(row["seq"]))
        else:
            side.show(self.filter.episode, int(row["t"]), int(row["atom_id"]))
        panel = self.decision
        if panel is not None:
            panel.show(self.filter.episode, int(row["t"]))

    def focus_default(self) -> None:
        self.table.focus()

    @property
    def table(self) -> LazyTable:
        return self.query_one("#tr-table", LazyTable)

    @property
    def status(self) -> Static:
        return self.query_one("#tr-status", Static)

    def field(self, name: str) -> Input:
        """A filter's input line: range, atom, label, rule or goto."""
        return self.query_one(f"#tr-{name}", Input)

    # ---- what is shown -------------------------------------------------------------------------------
    def show_episode(self, episode: int, rule: str = "", at_t: int | None = None) -> None:
        self.field("rule").value = rule
        if self.filter is None or self.filter.episode != episode:
            for name in ("range", "atom", "label"):
                self.field(name).value = ""
        self._goto_t = at_t
        self.apply_filters(episode)
        self._read_game_later(episode)

    def apply_filters(self, episode: int | None = None, keep_seq: int | None = None,
                      atom_id: int | None = None) -> None:
        if episode is None:
            if self.filter is None:
                return
            episode = self.filter.episode
        try:
            t_from, t_to = parse_range(self.field("range").value)
        except ValueError as e:
            self.status.update(shown(str(e), "bold red"))
            return
        value = lambda name: self.field(name).value.strip()  # noqa: E731
        self.filter = TraceFilter(episode, t_from, t_to, value("atom"), value("label"),
                                  value("rule"), atom_id, self.hide_static, self._atom_text(atom_id))
        start = ("seq", keep_seq) if keep_seq is not None else ("t", self._goto_t) if self._goto_t is not None \
            else None
        self._goto_t = None
        self.trace = TraceSource(self.source, self.filter, start)
        self.status.update(f" {self.filter.describe()} · loading…")
        self.table.set_source(self.trace)

    def _atom_text(self, atom_id: int | None) -> str:
        """The atom's text for the status line (a point lookup in the atoms table, once per filter)."""
        if atom_id is None:
            return ""
        if self.filter is not None and self.filter.atom_id == atom_id:
            return self.filter.atom_text
        text = self.source.scalar("SELECT text FROM atoms WHERE atom = $atom", {"atom": atom_id})
        return "" if text is None else str(text)

    def on_lazy_table_loaded(self, event: LazyTable.Loaded) -> None:
        event.stop()
        if not self.table.count and self.filter is not None and (self.filter.atom or self.filter.label
                                                                  or self.filter.rule):
            self._explain_no_rows(self.filter)  # counts as landed once it has said why
            return
        self.jumps += 1     # a new filter landed (where it opens: TraceSource's start)
        self._update_status()

    def _explain_no_rows(self, flt: TraceFilter) -> None:
        """No rows under a filter naming an atom, label or rule: if a name matches nothing in the run, say
        so (did you mean, how to write an atom) in the table and the status line, instead of "no rows"."""
        def work() -> None:
            message = None
            try:
                for kind, pattern in (("atom", flt.atom), ("label", flt.label), ("cause", flt.rule)):
                    if pattern:
                        self.source.call(lambda con: check_name(con, kind, pattern))  # noqa: B023
            except UnknownName as e:
                message = str(e)
            self.app.call_from_thread(self._no_rows_explained, flt, message)

        self.run_worker(work, thread=True, group="trace-names", exclusive=True, exit_on_error=False)

    def _no_rows_explained(self, flt: TraceFilter, message: str | None) -> None:
        if flt is not self.filter:
            return
        if message is not None:
            self.table.error = message
            self.table.refresh()
        self.jumps += 1
        self._update_status()

    def _update_status(self) -> None:
        if self.filter is None:
            return
        table = self.table
        if table.error:      # e.g. a filter that matches nothing in the run: the message says how to write one
            self.status.update(shown(f" {table.error}", "bold red"))
            return
        where = f"row {table.cursor + 1:,} of {table.count:,}" if table.count else "no rows"
        row = table.cursor_row
        atom = f" · {self._place(row['atom'])}" if row else ""
        hidden = self.trace.hidden if self.trace is not None else 0
        static = f" · {hidden:,} static hidden (s shows)" if hidden else ""
        self.status.update(shown(f" {self.filter.describe()} · {where}{static}{atom}"))

    def _place(self, text: str) -> str:
        grid = self.trace.grid if self.trace is not None else None
        return text if grid is None else grid.with_coordinates(text) or text

    def action_toggle_static(self) -> None:
        self.hide_static = not self.hide_static

    def on_lazy_table_row_highlighted(self, event: LazyTable.RowHighlighted) -> None:
        event.stop()
        self._update_status()
        if event.row is not None and self.side_shown:
            self._follow_cursor(event.row)

    def on_graph_side_only_atom(self, event: GraphSide.OnlyAtom) -> None:
        """Enter on an atom beside the trace: only its changes, the cursor on its first."""
        event.stop()
        self.apply_filters(atom_id=event.atom_id)
        self.focus_default()

    def on_lazy_table_row_selected(self, event: LazyTable.RowSelected) -> None:
        event.stop()
        self.action_why()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        if event.input.id == "tr-goto":
            text = event.value.strip()
            if text.lstrip("-").isdigit():
                t = int(text)
                self._jump(lambda tr: tr.row_of_t(t))
            event.input.value = ""
        else:
            self._refilter(keep_atom=False)
        self.focus_default()

    # ---- moving ----------------------------------------------------------------------------------------
    def _jump(self, where: Any) -> None:
        """Move the cursor to the row index where(trace) computes (in a worker)."""
        trace = self.trace
        if trace is None:
            return

        def work() -> None:
            try:
                index = where(trace)
                page = None if index is None else (index // PAGE, trace.fetch(index // PAGE))
            except Exception as e:  # noqa: BLE001
                self.app.call_from_thread(self.notify, printable(str(e)), severity="error", markup=False)
                return
            if trace is not self.trace:
                return
            self.app.call_from_thread(self._landed, index, page)

        self.run_worker(work, thread=True, group="trace-jump", exclusive=True, exit_on_error=False)

    def _landed(self, index: int | None, page: tuple[int, list[dict[str, Any]]] | None) -> None:
        if index is None:
            self.notify("no further change of this atom")
        else:
            if page is not None:
                self.table.put_page(*page)   # fetched with the jump: no second round trip
            self.table.move_to(index)
        self.jumps += 1

    def action_focus(self, selector: str) -> None:
        self.query_one(selector, Input).focus()

    def action_next_change(self, direction: int) -> None:
        row = self.table.cursor_row
        if row is None:
            return
        atom, seq = int(row["atom_id"]), int(row["seq"])
        self._jump(lambda tr: tr.next_change(atom, seq, direction > 0))

    def action_focus_decision(self) -> None:
        panel = self.decision
        if panel is not None and panel.display:
            panel.focus()

    def on_decision_panel_shown(self, event: DecisionPanel.Shown) -> None:
        event.stop()
        self.refresh_bindings()     # `d` is offered while a decision shows
        self._size_side()

    def action_why(self) -> None:
        row = self.table.cursor_row
        if row is not None and self.filter is not None:
            self.post_message(ExplainChange(self.filter.episode, row["atom"], int(row["t"]), int(row["seq"])))

    # ---- the evaluation games of a training run -----------------------------------------------------------
    def _read_game(self, episode: int) -> None:
        """The header line of `episode` (in a worker): which evaluation game it is, if the run has any."""
        try:
            games = eval_games(self.source)
        except Exception:  # noqa: BLE001 - no header line is the answer; the trace itself still shows
            games = []
        game = next((g for g in games if g.episode == episode), None)
        self.app.call_from_thread(self._show_game, episode, game, bool(games))

    def _show_game(self, episode: int, game: EvalGame | None, training: bool) -> None:
        header = self.query_one("#tr-game", Static)
        header.display = training
        what = game.describe() if game is not None else \
            f"episode {episode}: a training episode, not an evaluation game"
        header.update(f" {what} · ]/[ next/previous")

    def action_eval_game(self, direction: int) -> None:
        """Move to the next (previous) evaluation game, keeping the filters and the cursor's timestep."""
        def work() -> None:
            try:
                games = eval_games(self.source)
            except Exception as e:  # noqa: BLE001
                self.app.call_from_thread(self.notify, printable(str(e)), severity="error", markup=False)
                return
            self.app.call_from_thread(self._step_game, games, direction)

        # not exclusive: each press is one step, taken from where the previous one landed (_step_game)
        self.run_worker(work, thread=True, group="eval-game", exit_on_error=False)

    def _step_game(self, games: list[EvalGame], direction: int) -> None:
        game = neighbour(games, None if self.filter is None else self.filter.episode, direction > 0)
        if game is None:
            self.notify("not a training run: it has no evaluation games (episodes of kind 'eval')" if not games
                        else f"no {'later' if direction > 0 else 'earlier'} evaluation game", severity="warning")
            return
        self._goto_t = self._cursor_t()
        self._show_game(game.episode, game, True)
        self.apply_filters(game.episode, atom_id=None if self.filter is None else self.filter.atom_id)

    def _cursor_t(self) -> int | None:
        """The timestep the cursor is on; while a trace opening at a timestep is still loading (quick `]`
        presses), the timestep it opens at, so that it is not lost to the empty table."""
        trace, table = self.trace, self.table
        if trace is not None and trace.start is not None and trace.start[0] == "t" \
                and not (table.ready and table.source is trace):
            return trace.start[1]
        row = table.cursor_row
        return None if row is None else int(row["t"])

    def action_only_atom(self) -> None:
        if self.filter is None:
            return
        row = self.table.cursor_row
        if self.filter.atom_id is not None:
            self.apply_filters(keep_seq=None if row is None else int(row["seq"]))
        elif row is not None:
            self.apply_filters(keep_seq=int(row["seq"]), atom_id=int(row["atom_id"]))

    def action_clear(self) -> None:
        for name in ("range", "atom", "label", "rule"):
            self.field(name).value = ""
        self._refilter(keep_atom=False)
