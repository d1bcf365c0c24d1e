"""A training run by another library (Stable-Baselines3, ...) logged into a tracelab run, live, as
tracelab's own trainer logs its own (train/env_trainer.py, docs/training.md "What is logged, and where"):

- meta.json: the command, the env (the scenario or the declared world, its board and rule files), the
  learner's settings under `config`; status `running` until close() records finished / interrupted /
  failed (a killed process reads as `crashed`, from the writer's lock, as any run);
- `episodes`: every training episode (begin info `{"kind": "train", "train_step": N}`, outcome, return,
  length), without change rows (the library's env runs untraced);
- `metrics` at the training step: the library's own figures under its names, and `train_return` (the
  mean return of the training episodes that ended since the last row);
- evaluations (external_eval.py): `eval/...` metrics and the traced evaluation games.

The library's adapter (train/sb3.py) feeds it: `steps()` after every vector step, `metrics()` when the
library logs, `maybe_evaluate()`, then `close(status)`."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.store.writer import TraceWriter
from tracelab.train.external_eval import Act, EvalSettings, EvalTarget, Evaluator, eval_target


class ExternalRun:
    def __init__(self, run_dir: str | Path, env_id: str, env_kwargs: Mapping[str, Any] | None = None, *,
                 command: str, learner: Mapping[str, Any], evaluation: EvalSettings | None = None,
                 seed: int | None = None) -> None:
        """Opens the run (a directory that holds none yet). `learner`: the library's settings, kept as the
        run's config['learner']; `evaluation`: when and how it is evaluated (default EvalSettings())."""
        evaluation = evaluation or EvalSettings()
        self.target: EvalTarget = eval_target(env_id, env_kwargs)
        self.settings = evaluation
        described = self.target.run_meta()
        config = {**described.pop("config"), "learner": dict(learner), "eval": asdict(evaluation)}
        self.run_dir = Path(run_dir)
        self.writer = TraceWriter.open(self.run_dir, {"command": command, "seed": seed, "config": config,
                                                      **described})
        self._next_episode = 0
        self._evaluator: Evaluator | None = None
        self.eval_round = 0
        self.eval_step = -1          # the step of the last evaluation
        self.last_eval: dict[str, float] | None = None
        self._worlds = 0
        self._ep_id = np.zeros(0, np.int64)
        self._ep_len = np.zeros(0, np.int64)
        self._ep_return = np.zeros(0)
        self._begun: list[dict[str, Any]] = []
        self._ended: list[dict[str, Any]] = []
        self.returns_since_log: list[float] = []

    def new_episode_id(self) -> int:
        ep = self._next_episode
        self._next_episode += 1
        return ep

    # ---- training episodes ----
    def _begin(self, worlds: Sequence[int], step: int) -> None:
        for w in worlds:
            self._ep_id[w] = self.new_episode_id()
            self._begun.append({"episode": int(self._ep_id[w]), "world": int(w), "t_start": 0,
                                "info": {"kind": "train", "train_step": int(step)}})
        self._ep_len[list(worlds)] = 0
        self._ep_return[list(worlds)] = 0.0

    def steps(self, step: int, rewards: np.ndarray, dones: np.ndarray, infos: Sequence[Mapping[str, Any]]) -> None:
        """One step of every world of the library's vector env (same-step autoreset: a world that ended has
        begun its next episode). `step`: the training step after it. A world's return is the env's own
        (a Monitor wrapper's `episode` info when present: it is not scaled by a reward normaliser)."""
        n = len(rewards)
        if n != self._worlds:  # the first step: the worlds' first episodes began at the step before
            self._worlds = n
            self._ep_id, self._ep_len, self._ep_return = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n)
            self._begin(range(n), step - n)
        self._ep_len += 1
        self._ep_return += np.asarray(rewards, np.float64)
        ended = np.flatnonzero(dones).tolist()
        for w in ended:
            info = infos[w]
            truncated = bool(info.get("TimeLimit.truncated", False))
            monitored = info.get("episode")
            ret = float(monitored["r"]) if isinstance(monitored, Mapping) and "r" in monitored else \
                float(self._ep_return[w])
            self.returns_since_log.append(ret)
            self._ended.append({"episode": int(self._ep_id[w]), "steps": int(self._ep_len[w]), "reward": ret,
                                "outcome": self.target.outcome(info, not truncated, truncated)})
        if ended:
            self._begin(ended, step)

    def _flush_episodes(self) -> None:
        """The episode rows gathered since the last call, one table each (per-episode calls cost more)."""
        if self._begun or self._ended:
            self.writer.begin_episodes(self._begun)
            self.writer.end_episodes(self._ended)
        self._begun, self._ended = [], []

    # ---- metrics and evaluations ----
    def metrics(self, step: int, values: Mapping[str, Any]) -> None:
        """The library's figures at `step` (numbers only: text, images and the like are left out), with
        `train_return`, and the episodes that began or ended since the last call."""
        m = {k: float(v) for k, v in values.items()
             if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)}
        if self.returns_since_log:
            m["train_return"] = float(np.mean(self.returns_since_log))
            self.returns_since_log = []
        self._flush_episodes()
        if m:
            self.writer.write_metrics(step, m)

    def due(self, step: int, before: int) -> bool:
        """Whether an evaluation falls between training steps `before` and `step`."""
        every = self.settings.every
        return every > 0 and step // every > before // every

    def evaluate(self, act: Act, step: int) -> dict[str, float]:
        """An evaluation now (greedy games of `act`), its metrics written at `step`."""
        if self._evaluator is None:
            self._evaluator = self.target.evaluator(self.writer, self.new_episode_id, self.settings)
        m = self._evaluator.run(act, step, self.eval_round)
        self.writer.write_metrics(step, m)
        self.eval_round += 1
        self.eval_step, self.last_eval = step, m
        return m

    # ---- the end ----
    def close(self, status: str, step: int | None = None) -> None:
        """Close the run with `status` (finished, interrupted, failed): the games still running end as
        'aborted', as tracelab train's do."""
        if self.writer.closed:
            return
        try:
            if self._worlds:
                self._ended += [{"episode": int(self._ep_id[w]), "steps": int(self._ep_len[w]), "outcome": "aborted",
                                 "reward": float(self._ep_return[w])} for w in range(self._worlds)]
                self._worlds = 0
            self._flush_episodes()
            if self._evaluator is not None:
                self._evaluator.close()
        finally:
            self.writer.close(status=status)
