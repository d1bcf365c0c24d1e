"""The training loop and what it builds (EnvTrainer, env_trainer.py): the learner (fused or readable, behind
the Learner protocol), greedy acting's Q-values from it, the loop itself read as CleanRL's (collect, store,
update, then log, evaluate and checkpoint when due), its end, and what a restore puts back of the parts.

A training step is one world-step (one env transition of one world); with `envs` worlds one pass of the
loop makes `envs` steps and `envs * updates_per_step` updates. Everything that decides what happens next
is owned by the trainer's parts, each saving and loading itself, and is in the checkpoint, so a resumed
run continues exactly as an uninterrupted one would (tests/test_train_parts.py, test_train_env_resume.py)."""
from __future__ import annotations

import time
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

import torch

from tracelab.train.config import TrainConfig
from tracelab.train.dqn import DQN, DecomposedDQN, make_q_network
from tracelab.train.learner import DQNLearner
from tracelab.train.learner_protocol import Learner
from tracelab.train.qnet import NetSpec, NumpyQ, QFunction, TorchQ
from tracelab.train.replay import ReplayBuffer

NetworkFactory = Callable[[int, int], torch.nn.Module]  # (observation size, actions) -> a Q-network


def make_learner(kind: str, net: NetSpec, cfg: TrainConfig, generator: torch.Generator,
                 network: NetworkFactory | None = None, learner_class: type[DQN] = DQN) -> Learner:
    """The fused learner for `net` (one tanh layer), or the readable one (`learner_class`: DQN or a
    subclass) on `network`'s module (default: the module `net` describes, drawn from `generator`)."""
    if kind == "fused":
        return DQNLearner(net, lr=cfg.lr, batch=cfg.batch,
                          buffer=cfg.buffer, generator=generator, masked=cfg.mask)
    module = network(net.inputs, net.actions) if network is not None else \
        make_q_network(net, generator)
    if net.terms:  # --decompose: a head per reward term, a reward per term in the buffer
        learner_class = DecomposedDQN
    return learner_class(module, ReplayBuffer(cfg.buffer, net.inputs, net.actions, cfg.batch, cfg.mask,
                                              max(1, len(net.terms))), lr=cfg.lr, double_dqn=cfg.double_dqn)


def acting_q(learner: Learner, net: NetSpec | None) -> QFunction:
    """Greedy acting's Q-values from the learner's live online weights: in numpy for a described network,
    through torch for a custom module (net None)."""
    if net is None:
        return TorchQ(learner.q_network)  # type: ignore[attr-defined]  # only the readable learner takes one
    return NumpyQ(net, {k: v.numpy() for k, v in learner.online_weights().items()})


def end_training(tr: Any) -> str:
    """After the trainer's loop: "finished" or "interrupted"; a finished run's
    final figures, unless its last pass just wrote them; the games still open end 'aborted'."""
    status = "interrupted" if tr.step < tr.cfg.steps else "finished"
    if status == "finished":
        if tr.metrics.logged_step != tr.step:
            tr.log_metrics()
        if tr.eval_step != tr.step:
            timed_eval(tr)
    tr.episodes.abort_open()
    return status


def timed_eval(tr: Any) -> None:
    """A trainer's evaluation (run_eval), and its wall time into the run's metrics at the same step
    (MetricLog.evaluation_timed: this evaluation's seconds, its traced and untraced games', and the
    evaluations' share of the training's wall time)."""
    t0 = time.perf_counter()
    result = tr.run_eval()
    seconds = time.perf_counter() - t0
    tr.write_metrics(tr.metrics.evaluation_timed(seconds, getattr(result, "seconds", {})))


def train_loop(tr: Any, stop_at: int | None, collect_and_store: Callable[[], None],
               learners: Collection[Learner], save_checkpoint: Callable[[Any, Path], None]) -> str:
    """The trainer's loop (EnvTrainer's), top to bottom: every
    world makes one step and its closed transitions are stored (`collect_and_store`); the updates and
    target copies that are due; the log, the evaluation and the checkpoint at their intervals. Until
    cfg.steps, stop_requested (Ctrl-C) or step `stop_at` (as an interruption there would); returns
    "finished" or "interrupted"."""
    cfg = tr.cfg
    last_progress = 0.0
    tr.episodes.start_logging(tr.step)
    end = cfg.steps if stop_at is None else min(cfg.steps, stop_at)
    tr.metrics.loop_started()
    try:
        while tr.step < end and not tr.stop_requested:
            before = tr.step
            collect_and_store()
            tr.schedule.run(tr.step, learners, tr.rngs.numpy)  # updates, target copies
            if _crossed(cfg.log_every, before, tr.step):
                tr.log_metrics()
            if _crossed(cfg.eval_every, before, tr.step):
                timed_eval(tr)
            if tr.run_dir is not None and _crossed(cfg.checkpoint_every, before, tr.step):
                tr.episodes.flush()  # the run holds every episode the checkpoint has counted
                save_checkpoint(tr, tr.run_dir)
            if tr.progress is not None and time.monotonic() - last_progress > 0.2:
                last_progress = time.monotonic()
                tr.progress(tr.figures())
        status = end_training(tr)
        if tr.run_dir is not None:
            save_checkpoint(tr, tr.run_dir)
            tr.save_policy(tr.run_dir / "policy")
    finally:
        tr.metrics.loop_stopped()
    if tr.progress is not None:
        tr.progress(tr.figures())
    return status


def _crossed(every: int, before: int, step: int) -> bool:
    """A multiple of `every` lies in (before, step]: the interval's work is due."""
    return every > 0 and step // every > before // every


def load_shared_state(tr: Any, learners: dict[str, Learner], st: dict[str, Any]) -> None:
    """What a trainer's load_state restores of its parts: the learners (by network
    name; ValueError when the checkpoint is another learner's), the step and evaluation rounds, and the
    parts (UpdateSchedule, MetricLog, BestPolicy, Generators, EpisodeLog)."""
    kind = st.get("learner", "fused")  # absent: written before there were two learners
    if tr.learner_kind != kind:
        raise ValueError(f"the checkpoint holds the {kind} learner's state; this trainer runs the "
                         f"{tr.learner_kind} one")
    for name, lr in learners.items():
        lr.load_state(st["learners"][name])
    tr.step, tr.eval_round, tr.eval_step = int(st["step"]), int(st["eval_round"]), int(st["eval_step"])
    tr.schedule.load_state(st)
    tr.metrics.load_state(st)
    tr.best.load_state(st)
    tr.write_best_policy()  # a resumed run into a new directory keeps it too
    tr.rngs.load_state(st)
    tr.episodes.load_state(st)
