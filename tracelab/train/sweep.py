"""A hyperparameter search with Ray Tune (tracelab sweep, docs/scaling.md "Sweeps"): each trial is an
ordinary training run in the store (OUT/trial-NNN, the experiments' train_seed: an env, `--set
env=SPEC_OR_ID`, or the war game's scenario) whose evaluations Tune
reads as they are written, through a metric sink of the trainer; the scheduler (FIFO, or ASHA stopping
weak trials at their evaluations) and the search are Tune's.

A trial runs its training on a thread of Tune's actor, in step with Tune: the sink hands each evaluation
to Tune and waits for the next step() call. A trial Tune stops (ASHA, Ctrl-C) is stopped through its
Trainer in the actor's cleanup(), which waits for the run to close: the run ends 'interrupted' at the
step of its last evaluation, with a checkpoint (train --resume continues it)."""
from __future__ import annotations

import logging
import os
import queue
import re
import threading
import time
from collections.abc import Mapping
from contextlib import redirect_stdout
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ray import tune

from tracelab.envs.declared.env_source import EnvSource
from tracelab.store.meta import current_meta
from tracelab.train.config import TrainConfig
from tracelab.train.experiments.runner import train_seed
from tracelab.train.sweep_spec import Axis, SweepSpec

CLOSE_WAIT_S = 300       # a stopped trial's last pass, checkpoint and policy before its actor goes
ASHA_REDUCTION = 2       # each rung keeps the best half (sweeps here are a few to a few dozen trials)
HEARTBEAT_S = 2.0        # a trial reports at least this often (its evaluations may be far apart)
TUNE_DIR = "tune"        # Tune's own records of the sweep, under --out


def trial_dir(out: Path, trial_id: str) -> Path:
    """OUT/trial-NNN from Tune's trial id (<experiment>_NNNNN: numbered in the order of the search)."""
    return out / f"trial-{int(trial_id.rsplit('_', 1)[-1]):03d}"


def search_space(axes: tuple[Axis, ...]) -> dict[str, Any]:
    """Tune's param_space of the searched fields."""
    def domain(a: Axis) -> Any:
        if a.kind == "grid":
            return tune.grid_search(list(a.values))
        if a.kind == "choice":
            return tune.choice(list(a.values))
        if a.kind == "randint":
            return tune.randint(a.values[0], a.values[1] + 1)  # Tune's upper bound is exclusive, ours not
        return (tune.loguniform if a.kind == "loguniform" else tune.uniform)(*a.values)
    return {a.name: domain(a) for a in axes}


class _TuneSink:
    """The trainer's metric sink in a trial: keeps the latest value of every metric, and on each write
    holding `metric` (an evaluation) hands them all to the trial's step() and waits until Tune asks for
    the next one, or the trial is stopped."""

    def __init__(self, metric: str, results: queue.Queue, go: threading.Semaphore, stopped: threading.Event):
        self.metric, self.results, self.go, self.stopped = metric, results, go, stopped
        self.latest: dict[str, float] = {}

    def write(self, step: int, values: Mapping[str, float]) -> None:
        self.latest.update(values)
        if self.metric in values and not self.stopped.is_set():
            self.results.put({**self.latest, "step": step})
            self.go.acquire()

    def flush(self) -> None:
        pass


class TracelabTrial(tune.Trainable):
    """One trial: TrainConfig(fixed + the trial's values) trained into OUT/trial-NNN."""

    def setup(self, config: dict[str, Any], fixed: dict[str, Any], world: EnvSource | Any, out: str,
              metric: str, command: str) -> None:
        """`world`: what train_seed trains, an env or the war game's scenario."""
        cfg = TrainConfig(**{**fixed, **config})
        self.steps = cfg.steps
        self.results: queue.Queue = queue.Queue()
        self.go = threading.Semaphore(0)
        self.stopped = threading.Event()
        self.trainer: Any = None
        self.first = True
        sink = _TuneSink(metric, self.results, self.go, self.stopped)
        run_dir = trial_dir(Path(out), self.trial_id)

        def train() -> None:
            try:
                train_seed(cfg, world, run_dir, command, (), cfg.eval_games, [sink], self._started)
                self.results.put(None)  # trained to the end
            except BaseException as e:  # noqa: BLE001  (handed to Tune's thread: the trial errors)
                self.results.put(e)
        self.thread = threading.Thread(target=train, name=f"tracelab-trial-{run_dir.name}", daemon=True)
        self.thread.start()

    def _started(self, trainer: Any) -> None:
        self.trainer = trainer
        if self.stopped.is_set():
            trainer.stop_requested = True

    def step(self) -> dict[str, Any]:
        """The trial's next evaluation; or, after HEARTBEAT_S without one, the step it is at (no metric:
        the scheduler passes it by). Tune's actor runs one call at a time, so returning now and then is
        what lets a stop (ASHA, Ctrl-C) reach cleanup() between evaluations far apart."""
        if not self.first:
            self.go.release()  # the training goes on to its next evaluation
        self.first = False
        try:
            item = self.results.get(timeout=HEARTBEAT_S)
        except queue.Empty:
            self.first = True  # the training is not waiting: nothing to release next time
            return {"step": self.trainer.step if self.trainer is not None else 0}
        if isinstance(item, BaseException):
            raise item
        if item is None:  # the metric never came (evaluations off): what Tune sees ends here
            return {"done": True}
        return {**item, "done": item["step"] >= self.steps}

    def cleanup(self) -> None:
        """Stop the training (ASHA, Ctrl-C, the end) and wait for its run to close."""
        self.stopped.set()
        if self.trainer is not None:
            self.trainer.stop_requested = True
        self.go.release()
        self.thread.join(CLOSE_WAIT_S)


def best_evaluation(results: Any, metric: str, mode: str) -> tuple[float | None, int | None, float | None]:
    """A trial's best evaluation by `metric` (the earliest of equals), its step, and the metric's last
    value; from Tune's results of the trial (a DataFrame; heartbeats have no metric). The best, not the
    last: DQN's greedy policy can get worse late in training, and every run keeps the policy of its best
    evaluation (RUN/policy-best, by eval/method_win_rate)."""
    if results is None or metric not in results.columns:
        return None, None, None
    rows = results[results[metric].notna()]
    if rows.empty:
        return None, None, None
    values = rows[metric].to_numpy(float)
    at = int(values.argmax() if mode == "max" else values.argmin())
    return float(values[at]), int(rows["step"].iloc[at]), float(values[-1])


@dataclass
class SweepResult:
    best_dir: Path | None
    best_config: dict[str, Any]
    best_value: float | None
    trials: list[dict[str, Any]]      # per trial: run, config, its best value, that step, the last value, error


def wait_for_trials_to_close(out: Path, ceiling_s: float = CLOSE_WAIT_S) -> None:
    """Tune's fit() returns once every trial has reported its end, before the trials' actors have run
    cleanup() to its end (the run's last pass, checkpoint and policy: seconds under load); Ray's shutdown
    after it would kill them mid-close and leave their runs `crashed`. So wait on the runs' own state
    (`running` until closed), with a generous ceiling."""
    deadline = time.monotonic() + ceiling_s
    for run in sorted(out.glob("trial-*")):
        while (run / "meta.json").is_file() and current_meta(run)["status"] == "running" \
                and time.monotonic() < deadline:
            time.sleep(0.2)


def run_sweep(spec: SweepSpec, world: EnvSource | Any, out: Path, command: str) -> SweepResult:
    """The search (Ray initialised by the caller): trials under `out`, Tune's records in out/tune, what
    Tune prints in out/tune.log."""
    given, out = out, out.absolute()  # Tune's actors work in folders of their own
    out.mkdir(parents=True, exist_ok=True)
    scheduler = None
    if spec.scheduler == "asha":
        cfg = spec.base_config()
        scheduler = tune.schedulers.ASHAScheduler(time_attr="step", max_t=cfg.steps, grace_period=cfg.eval_every,
                                                  reduction_factor=ASHA_REDUCTION)
    trainable = tune.with_parameters(TracelabTrial, fixed=spec.fixed, world=world, out=str(out),
                                     metric=spec.metric, command=command)
    tuner = tune.Tuner(
        tune.with_resources(trainable, {"cpu": 1}),
        param_space=search_space(spec.axes),
        tune_config=tune.TuneConfig(metric=spec.metric, mode=spec.mode, num_samples=spec.samples,
                                    scheduler=scheduler),
        run_config=tune.RunConfig(storage_path=str(out), name=TUNE_DIR, verbose=0,
                                  failure_config=tune.FailureConfig(max_failures=0),
                                  # the runs hold checkpoints of their own (RUN/checkpoint)
                                  checkpoint_config=tune.CheckpointConfig(checkpoint_at_end=False)))
    # Tune prints tables whatever `verbose` and logs a failed trial's traceback: into out/tune.log (the
    # command names each trial's error in one line)
    tune_logger = logging.getLogger("ray.tune")
    level = tune_logger.level
    os.environ["TUNE_DISABLE_STRICT_METRIC_CHECKING"] = "1"  # heartbeats carry no metric (TracelabTrial.step)
    with open(out / "tune.log", "a") as log, redirect_stdout(log):
        handler = logging.StreamHandler(log)
        tune_logger.addHandler(handler)
        tune_logger.propagate, tune_logger.level = False, logging.WARNING
        try:
            grid = tuner.fit()
        finally:
            tune_logger.removeHandler(handler)
            tune_logger.propagate, tune_logger.level = True, level
    wait_for_trials_to_close(out)
    trials = []
    for r in grid:
        trial_id = r.metrics.get("trial_id") or re.search(r"_([0-9a-f]+_\d{5})_", Path(r.path).name).group(1)
        value, step, last = best_evaluation(r.metrics_dataframe, spec.metric, spec.mode)
        trials.append({"run": trial_dir(given, trial_id), "config": dict(r.config), "value": value, "step": step,
                       "last": last, "error": None if r.error is None else str(r.error).strip().splitlines()[-1]})
    evaluated = [t for t in trials if t["value"] is not None]
    if not evaluated:
        return SweepResult(None, {}, None, trials)
    sign = 1 if spec.mode == "max" else -1
    best = max(evaluated, key=lambda t: sign * t["value"])
    return SweepResult(best["run"], best["config"], best["value"], trials)
