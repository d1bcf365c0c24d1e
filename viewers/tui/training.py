"""The Training view: live curves from the run's `metrics` (docs: HELPER_GUIDE's training-run contract):
win rate (eval/win_rate, per opponent setting), return (train_return, eval/mean_return), loss (tracelab's
`loss`, or Stable-Baselines3's `train/loss` in a run it trained) and epsilon.
It re-reads the metrics every second while the run is live, so the curves grow while `tracelab train`
writes, and once more when it closes. `v` shows the evaluation games in the Episodes view.

Other runs can be overlaid (`tracelab tui RUN RUN ...`, docs/tui.md): each metric is then drawn as the
runs' mean with a min–max band over them (run_overlay.mean_band), or, after `m`, one curve per run."""
from __future__ import annotations

from collections.abc import Sequence

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Vertical
from textual.reactive import reactive
from textual.widgets import Static, TabbedContent

from tracelab.viewers.tui.colours import BLUE_TEAM, PARTIAL, RED_TEAM, TRUE, UNKNOWN
from tracelab.viewers.tui.episodes import EpisodesPane
from tracelab.viewers.tui.plot import Band, BraillePlot, Series
from tracelab.viewers.tui.run_overlay import RunCurves, mean_band, run_labels
from tracelab.viewers.tui.source import LiveReads, RunSource, background

REFRESH_S = 1.0
PALETTE = (TRUE, BLUE_TEAM, PARTIAL, RED_TEAM, UNKNOWN)
# plot id, title, metric names (a name ending in '@' takes every suffix: eval/win_rate@p0.3, ...)
PLOTS = (("win-rate", "win rate", ("eval/win_rate", "eval/win_rate@", "eval/method_win_rate")),
         ("return", "return", ("train_return", "eval/mean_return", "eval/mean_return@")),
         ("loss", "loss", ("loss", "train/loss")),  # tracelab's DQN; Stable-Baselines3's (train/sb3.py)
         ("epsilon", "epsilon", ("epsilon",)))


def wanted(name: str, patterns: tuple[str, ...]) -> bool:
    return any(name.startswith(p) if p.endswith("@") else name == p for p in patterns)


class TrainingPane(Vertical, can_focus=True):
    BINDINGS = [Binding("v", "eval_games", "eval games"), Binding("m", "each_run", "each run / mean")]
    each_run = reactive(False, init=False)   # several runs: one curve per run instead of their mean and band

    def __init__(self, source: RunSource, overlaid: Sequence[RunSource] = ()) -> None:
        super().__init__()
        self.source = source
        labels = run_labels([source.path, *(o.path for o in overlaid)])
        self.runs = [RunCurves(s, label) for s, label in zip([source, *overlaid], labels)]
        self.updates = 0          # how many times new metrics were drawn (tests watch it)

    @property
    def live_reads(self) -> LiveReads:
        """When the view's own run is re-read (its overlaid runs have theirs: self.runs)."""
        return self.runs[0].live_reads

    def compose(self) -> ComposeResult:
        with Grid():
            for plot_id, title, _ in PLOTS:
                yield BraillePlot(title, id=f"plot-{plot_id}")
        yield Static(" reading metrics…", id="train-status", classes="status")

    def focus_default(self) -> None:
        self.focus()  # its keys (v, m) work while it has the focus

    def on_mount(self) -> None:
        self.poll()
        self.set_interval(REFRESH_S, self.poll)

    def poll(self) -> None:
        if not any(r.live_reads.due for r in self.runs) or not self.screen.is_current or not self.is_visible_tab:
            return
        if any(r.source.busy for r in self.runs):
            return  # another query holds a connection; try again on the next tick
        self.run_worker(background(self._read), thread=True, group="training", exclusive=True, exit_on_error=False)

    @property
    def is_visible_tab(self) -> bool:
        return self.screen.query_one(TabbedContent).active == "training"

    def _read(self) -> None:
        changed = [r.read() for r in self.runs]   # every run, even when the first one has not changed
        if any(changed):
            self.app.call_from_thread(self._draw)

    def _draw(self) -> None:
        for plot_id, _, patterns in PLOTS:
            plot = self.query_one(f"#plot-{plot_id}", BraillePlot)
            names = sorted({n for r in self.runs for n in r.curves if wanted(n, patterns)})
            if len(self.runs) == 1 or self.each_run:
                plot.set_series(self._each_curve(names))
            else:
                plot.set_series(*self._means_and_bands(names))
        self.updates += 1
        self.query_one("#train-status", Static).update(self._status())

    def _each_curve(self, names: list[str]) -> list[Series]:
        """One series per metric of each run; with several runs a colour per run, named 'run: metric'."""
        several = len(self.runs) > 1
        return [Series(f"{r.label}: {n}" if several else n,
                       PALETTE[(k if several else i) % len(PALETTE)], *r.curves[n])
                for k, r in enumerate(self.runs) for i, n in enumerate(names) if n in r.curves]

    def _means_and_bands(self, names: list[str]) -> tuple[list[Series], list[Band]]:
        """Per metric, the runs' mean as a line over their min–max band (a metric only one run has: its
        curve alone)."""
        series, bands = [], []
        for i, name in enumerate(names):
            colour = PALETTE[i % len(PALETTE)]
            have = [r.curves[name] for r in self.runs if name in r.curves]
            figures = mean_band(have)
            if figures is None:
                series.extend(Series(name, colour, *c) for c in have)
                continue
            steps, mean, low, high = figures
            bands.append(Band("", colour, steps, low, high))   # the status line says what the shade is
            series.append(Series(f"{name} mean", colour, steps, mean))
        return series, bands

    def _status(self) -> str:
        main = self.runs[0]
        rows, last = main.seen or (0, -1)
        live = "live, re-read every second" if self.source.live else self.source.state
        if len(self.runs) == 1:
            return (f" {rows:,} metric rows up to step {last:,} · {live} · v: evaluation games" if rows
                    else " this run has no metrics (not a training run)")
        empty = [r.label for r in self.runs if not r.seen or not r.seen[0]]
        drawn = "one curve per run" if self.each_run else "line: their mean, shade: min–max"
        return (f" {len(self.runs)} runs: {', '.join(r.label for r in self.runs)}"
                + (f" (no metrics: {', '.join(empty)})" if empty else "")
                + f" · {drawn} · m: {'mean and band' if self.each_run else 'each run'}")

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        return action != "each_run" or len(self.runs) > 1   # `m` only where there are runs to overlay

    def action_each_run(self) -> None:
        self.each_run = not self.each_run

    def watch_each_run(self) -> None:
        self._draw()

    async def action_eval_games(self) -> None:
        await self.screen.action_show("episodes")  # type: ignore[attr-defined]
        self.screen.query_one(EpisodesPane).action_eval_only()
