"""`?`: the keys of every view, in a modal over the current screen."""
from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Markdown

HELP = """\
# tracelab tui — keys

**Everywhere**: `?` this help · `Ctrl+P` command palette · `q` quit · `Esc` cancel the running query,
else leave a text field, else back one view (Why → Trace → Episodes → Runs; a run reopened opens where it
was left) · `1`–`6` switch view (in a text field they are text: `Esc` or `Tab`
first) · the mouse selects rows, tabs, keys in the bottom bar and header columns (sort).

| view | keys |
|---|---|
| Runs | `Enter` open · `space` mark · `c` open the marked runs, curves overlaid in Training, SQL on them all · `r` refresh (also every 2 s) |
| 1 Episodes | `Enter` trace · `s` / `S` sort column / direction (or click a header) · `f` length filter (`10..50`, `>=20`) · `o` next outcome (all, each, all) · `e` evaluation games |
| 2 Trace | `Enter`/`w` why · `n` / `p` next / previous change of the atom · `g` go to timestep · `/` atom filter (also t range, label, rule; Enter applies) · `a` only this atom · `x` clear filters · `b` board · `]` / `[` next / previous evaluation game (training runs) |
| 2 Trace, a run without a board (a reasoning) | `b` the atoms true at the cursor's t and the graph around its atom, beside the trace · `c` true / changed at t · in the atoms (`Tab`): `/` filter (`exposed`, `exposed(*)`) · `Enter` only that atom's changes · its cursor picks the atom whose edges show · `s` static facts |
| 3 Why | `Enter`/click expand a node · `o` expand all · `c` collapse · `/` why-not (`RULE A=x,B=y at T`) |
| 4 Rules | `Enter` trace filtered by the rule · `e` per rule / per episode |
| 5 SQL | `Ctrl+R` run (read-only; cancels a running one) · `F2` saved queries with parameters · `F3` history (kept between sessions) · `F4` export the result (CSV, Parquet) · `Ctrl+T` results |
| 6 Training | curves re-read every second while a run is written · `v` evaluation games · `m` several runs: each run / their mean over a min–max band |

Truth values: green `[1,1]`, orange `[0,0]`, grey `[0,1]`, yellow anything else. Team colours: red and blue.
"""


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,question_mark,q", "dismiss(None)", "close")]

    def compose(self) -> ComposeResult:
        with VerticalScroll():
            yield Markdown(HELP)
