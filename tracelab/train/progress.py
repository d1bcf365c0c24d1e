"""The training progress bar (rich): step, ε, loss, last evaluation's win rate, steps/s, ETA. Shown on a
terminal only; elsewhere training is quiet apart from its start and end lines."""
from __future__ import annotations

import sys
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskProgressColumn, TextColumn, \
    TimeRemainingColumn


class TrainProgress:
    def __init__(self, total: int, start: int = 0, console: Console | None = None) -> None:
        self.console = console or Console(file=sys.stderr)
        self._bar = Progress(
            TextColumn("[bold]train"), BarColumn(), MofNCompleteColumn(), TaskProgressColumn(),
            TextColumn("ε {task.fields[eps]}  loss {task.fields[loss]}  win {task.fields[win]}"),
            TextColumn("{task.fields[rate]}"),
            TimeRemainingColumn(), console=self.console, transient=False)
        self._task = self._bar.add_task("train", total=total, completed=start, eps="-", loss="-", win="-",
                                        rate="")

    def __enter__(self) -> "TrainProgress":
        self._bar.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._bar.stop()

    def __call__(self, fig: dict[str, Any]) -> None:
        task = self._bar.tasks[0]
        speed = task.speed
        self._bar.update(self._task, completed=min(fig["step"], fig["steps"]), eps=f"{fig['epsilon']:.3f}",
                         loss="-" if fig["loss"] is None else f"{fig['loss']:.3g}",
                         win="-" if fig["win_rate"] is None else f"{100 * fig['win_rate']:.1f}%",
                         rate="" if not speed else f"{speed:,.0f} steps/s")
