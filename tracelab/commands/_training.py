"""The part of `tracelab train` that both trainers share: Ctrl-C once finishes the step and stops (the
trainer writes what it keeps), Ctrl-C again aborts; a progress bar on a terminal; what a resume says; the
final summary's line on the evaluations' wall time."""
from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any


def train_until_stopped(trainer: Any, total: int, stop_at: int | None, keeps: str,
                        fields: Callable[[dict[str, Any]], dict[str, str]]) -> str:
    """trainer.train(stop_at) under the progress bar; `keeps` says what a first Ctrl-C writes, `fields`
    the figures beside ε and the loss. Returns the trainer's status; a second Ctrl-C raises
    KeyboardInterrupt. The SIGINT handler is the caller's again afterwards."""
    from tracelab.commands._progress import progress

    def stop(signum: int, frame: Any) -> None:
        if trainer.stop_requested:  # a second Ctrl-C: stop now
            raise KeyboardInterrupt
        trainer.stop_requested = True
        print(f"\nstopping: finishing the step, writing {keeps} (Ctrl-C again to abort)", file=sys.stderr)

    previous = signal.signal(signal.SIGINT, stop)
    try:
        with progress("train", total=total) as bar:  # draws on a terminal only
            bar.advance(trainer.step)

            def show(fig: dict[str, Any]) -> None:
                bar.advance(min(fig["step"], fig["steps"]) - bar.completed)
                bar.set_fields(ε=fig["epsilon"], loss="-" if fig["loss"] is None else fig["loss"], **fields(fig))

            trainer.progress = show
            return str(trainer.train(stop_at))
    finally:
        signal.signal(signal.SIGINT, previous)


def say_resumed(trainer: Any, writer: Any, run_dir: Path, resumed_from: str | None, same_run: bool) -> None:
    """After a restore: into the same run, a `resumed` metric row (which resume, at the checkpoint's step:
    the event, in the curves); then one line saying where training goes on."""
    if same_run:
        resumes = len(writer.meta["resumes"])
        trainer.write_metrics({"resumed": float(resumes)})
        print(f"resumed {run_dir} at step {trainer.step:,} in the same run (resume {resumes}; --run NEW would "
              f"branch into a new run)", file=sys.stderr)
    else:
        print(f"resumed from {resumed_from} at step {trainer.step:,}", file=sys.stderr)


def eval_time_line(metrics: Any) -> str | None:
    """The summary's line on the evaluations' wall time in this process (a trainer's MetricLog), e.g.
    `evaluations: 11 in 9.8 s, 14.2% of the training's 69.0 s (traced games 2.7 s, untraced 6.6 s)`;
    None when none ran."""
    share = metrics.eval_share()
    if not metrics.eval_count or share is None:
        return None
    parts = [f"{name} games {metrics.eval_part_seconds[name]:.1f} s" for name in ("traced", "untraced")
             if metrics.eval_part_seconds[name] > 0]
    return (f"evaluations: {metrics.eval_count} in {metrics.eval_seconds:.1f} s, {100 * share:.1f}% of the "
            f"training's {metrics.loop_seconds():.1f} s" + (f" ({', '.join(parts)})" if parts else ""))
