"""The parts of `tracelab train` (train.py) around its trainer: where a
run goes and what --resume may change; the session around a training, which closes the trainer, the
TensorBoard sink and the run whatever happens; Ctrl-C once finishes the step and stops (the trainer writes
what it keeps), Ctrl-C again aborts; a progress bar on a terminal; what a resume says; the final summary's
line on the evaluations' wall time."""
from __future__ import annotations

import argparse
import shlex
import signal
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from tracelab.commands._progress import progress
from tracelab.errors import UserError
from tracelab.store import TraceWriter
from tracelab.store.meta import current_meta, now_iso
from tracelab.store.writer import RunSealed
from tracelab.train.config import flag_of
from tracelab.train.determinism import use_deterministic_algorithms
from tracelab.train.tensorboard import TensorBoardSink, run_log_dir

# what --resume may change (the rest is the checkpoint's): the threads and the kernel change no result; the
# budget (steps) may be raised, which moves the ε schedule's fractions with it
RESUMABLE_FLAGS = {"threads", "kernel", "steps"}


def train_until_stopped(trainer: Any, total: int, stop_at: int | None, keeps: str,
                        fields: Callable[[dict[str, Any]], dict[str, str]]) -> str:
    """trainer.train(stop_at) under the progress bar; `keeps` says what a first Ctrl-C writes, `fields`
    the figures beside ε and the loss. Returns the trainer's status; a second Ctrl-C raises
    KeyboardInterrupt. The SIGINT handler is the caller's again afterwards."""
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


def where_to_train(args: argparse.Namespace, resuming: bool, name: str) -> tuple[Path, bool, Path | None]:
    """(the run directory, whether it is the resumed run's own, the TensorBoard log directory or None): a
    resume continues its run unless --run names another; a new run is runs/<exp-name>-<name>-<time>. The
    TensorBoard directory is checked before training (the install hint, a log directory already used)."""
    if resuming:
        default_run = str(args.resume)
    else:
        default_run = f"runs/{args.exp_name or 'train'}-{name}-{time.strftime('%Y%m%d-%H%M%S')}"
    run_dir = Path(args.run or default_run)
    same_run = resuming and same_directory(run_dir, Path(args.resume))
    tensorboard = None
    if args.tensorboard:
        tensorboard = run_log_dir(Path(args.tensorboard), run_dir.resolve().name, appending=same_run)
    return run_dir, same_run, tensorboard


def check_resume_flags(given: dict[str, Any]) -> None:
    """--resume takes the checkpoint's config: a UserError naming the flags it may not change."""
    extra = sorted(set(given) - RESUMABLE_FLAGS)
    if extra:
        raise UserError(f"--resume continues the checkpoint's config; drop {', '.join(flag_of(k) for k in extra)}")


def check_budget(run: str, step: int, steps: int, given: bool, env: str = "") -> None:
    """--resume: the budget must lie past the checkpoint (a UserError naming how to go on otherwise; `env`:
    the --env flags the command needs, for an --env run)."""
    if given and steps < step:
        raise UserError(f"--total-timesteps {steps:,} is below the checkpoint's step {step:,} of {run}: give "
                        f"a budget above it")
    if step >= steps:
        raise UserError(f"nothing to resume: {run}'s checkpoint is at step {step:,} of its {steps:,}; to train "
                        f"on, raise the budget: tracelab train --resume {shlex.quote(run)}{env} --total-timesteps N "
                        f"(N > {step})")


def same_directory(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def reopen_run(run_dir: Path, cfg: Any, step: int, command: str) -> Any:
    """The checkpoint's own run, reopened for appending: its config takes the (maybe raised) budget and
    meta.json's `resumes` records this resume (when, at which step, after which status)."""
    before = current_meta(run_dir)
    resume = {"at": now_iso(), "step": step, "after": before.get("status"), "steps": cfg.steps,
              "command": command}
    changes = {"config": {**before.get("config", {}), **cfg.to_dict()},
               "resumes": [*before.get("resumes", []), resume]}
    try:
        return TraceWriter.reopen(run_dir, changes)
    except RunSealed as e:
        raise UserError(f"{e}; resume into a new run: tracelab train --resume {shlex.quote(str(run_dir))} "
                        f"--run NEW") from None


@dataclass
class TrainingSession:
    """What a training opened, for training_session to close: `sink` the TensorBoard sink if any; set
    `trainer` once made and `status` ("failed" until the training says otherwise)."""
    writer: Any
    trainer: Any = None
    sink: Any = None
    status: str = "failed"

    @property
    def metric_sinks(self) -> list[Any]:
        """Where the trainer sends its metrics besides the run."""
        return [self.sink] if self.sink is not None else []


@contextmanager
def training_session(writer: Any, torch_deterministic: bool, tensorboard: Path | None = None,
                     purge_step: int | None = None) -> Iterator[TrainingSession]:
    """Around a training into `writer`'s run: torch's deterministic algorithms as the config says, a
    TensorBoard sink writing into `tensorboard` if given (from `purge_step` on, for a resumed run); Ctrl-C
    (a second one, or one before the trainer's handler) ends it as "interrupted". Whatever happens, the
    SIGINT handler and torch's mode are put back, the trainer, the sink and the run closed, the run with
    the session's status."""
    was_deterministic = torch.are_deterministic_algorithms_enabled()
    use_deterministic_algorithms(torch_deterministic)
    previous = signal.getsignal(signal.SIGINT)
    session = TrainingSession(writer)
    try:
        if tensorboard is not None:
            session.sink = TensorBoardSink(tensorboard, purge_step=purge_step)
        yield session
    except KeyboardInterrupt:
        session.status = "interrupted"
    finally:
        signal.signal(signal.SIGINT, previous)
        use_deterministic_algorithms(was_deterministic)
        if session.trainer is not None:
            session.trainer.close()
        if session.sink is not None:
            session.sink.close()
        writer.close(status=session.status)


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
