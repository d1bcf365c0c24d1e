"""The Training view: live curves from the run's `metrics` (docs: HELPER_GUIDE's training-run contract):
win rate (eval/win_rate, per opponent setting), return (train_return, eval/mean_return), loss and epsilon.
It re-reads the metrics every second while the run is live, so the curves grow while `tracelab train`
writes, and once more when it closes. `v` shows the evaluation games in the Episodes view."""
from __future__ import annotations

from collections import defaultdict

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Vertical
from textual.widgets import Static, TabbedContent

from tracelab.viewers.tui.colours import BLUE_TEAM, PARTIAL, RED_TEAM, TRUE, UNKNOWN
from tracelab.viewers.tui.plot import BraillePlot, Series
from tracelab.viewers.tui.source import LiveReads, RunSource

REFRESH_S = 1.0
PALETTE = (TRUE, BLUE_TEAM, PARTIAL, RED_TEAM, UNKNOWN)
# plot id, title, metric names (a name ending in '@' takes every suffix: eval/win_rate@p0.3, ...)
PLOTS = (("win-rate", "win rate", ("eval/win_rate", "eval/win_rate@", "eval/method_win_rate")),
         ("return", "return", ("train_return", "eval/mean_return", "eval/mean_return@")),
         ("loss", "loss", ("loss",)),
         ("epsilon", "epsilon", ("epsilon",)))


def wanted(name: str, patterns: tuple[str, ...]) -> bool:
    return any(name.startswith(p) if p.endswith("@") else name == p for p in patterns)


class TrainingPane(Vertical, can_focus=True):
    BINDINGS = [Binding("v", "eval_games", "eval games")]
    DEFAULT_CSS = """
    TrainingPane Grid { grid-size: 2 2; grid-gutter: 0; height: 1fr; }
    """

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.updates = 0          # how many times new metrics were drawn (tests watch it)
        self._seen: tuple[int, int] | None = None
        self.live_reads = LiveReads(source)

    def compose(self) -> ComposeResult:
        with Grid():
            for plot_id, title, _ in PLOTS:
                yield BraillePlot(title, id=f"plot-{plot_id}")
        yield Static(" reading metrics…", id="train-status", classes="status")

    def focus_default(self) -> None:
        self.focus()  # its keys (v) work while it has the focus

    def on_mount(self) -> None:
        self.poll()
        self.set_interval(REFRESH_S, self.poll)

    def poll(self) -> None:
        if not self.live_reads.due or not self.screen.is_current or not self.is_visible_tab:
            return
        if self.source.busy:
            return  # another query holds the connection; try again on the next tick
        self.run_worker(self._read, thread=True, group="training", exclusive=True, exit_on_error=False)

    @property
    def is_visible_tab(self) -> bool:
        return self.screen.query_one(TabbedContent).active == "training"

    def _read(self) -> None:
        with self.live_reads.read() as last:
            r = self.source.rows("SELECT count(*) AS n, coalesce(max(step), -1) AS last FROM metrics")[0]
            mark = (int(r["n"]), int(r["last"]))
            if mark == self._seen and not last:
                return
            rows = self.source.rows("SELECT name, step, value FROM metrics ORDER BY name, step, time, value")
            self.app.call_from_thread(self._draw, rows, mark)

    def _draw(self, rows: list[dict], mark: tuple[int, int]) -> None:
        self._seen = mark
        by_name: dict[str, tuple[list[float], list[float]]] = defaultdict(lambda: ([], []))
        for r in rows:
            xs, ys = by_name[r["name"]]
            xs.append(r["step"])
            ys.append(float("nan") if r["value"] is None else r["value"])
        for plot_id, _, patterns in PLOTS:
            names = sorted(n for n in by_name if wanted(n, patterns))
            series = [Series(n, PALETTE[i % len(PALETTE)], *by_name[n]) for i, n in enumerate(names)]
            self.query_one(f"#plot-{plot_id}", BraillePlot).set_series(series)
        self.updates += 1
        live = "live, re-read every second" if self.source.live else self.source.state
        self.query_one("#train-status", Static).update(
            f" {mark[0]:,} metric rows up to step {mark[1]:,} · {live} · v: evaluation games"
            if mark[0] else " this run has no metrics (not a training run)")

    async def action_eval_games(self) -> None:
        from tracelab.viewers.tui.episodes import EpisodesPane
        await self.screen.action_show("episodes")  # type: ignore[attr-defined]
        self.screen.query_one(EpisodesPane).action_eval_only()
