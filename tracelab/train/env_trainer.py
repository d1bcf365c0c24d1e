"""DQN on any gymnasium env with Discrete actions (`tracelab train --env`): one agent, ε-greedy over the
batched worlds, transitions into replay, one update per world-step, target copies, evaluations, the run's
metrics and episodes, the final and the best policy.

It is the GridWar Trainer's loop (loop.py) without what is GridWar's (teams, the scripted opponent, slow
agents): the same TrainConfig and ε schedule, the same learners
(make_learner: fused or readable, behind the Learner protocol), the same replay buffer, the same update
and target-copy cadence, the same metric names where they mean the same thing. Observations are encoded
for the network by env_source.ObservationEncoder (a Discrete one is one-hot). Checkpoints and their
restore (replaying the worlds' episodes) are env_checkpoint.py's; a declared world's first evaluation games
are traced into the run (external_eval.DeclaredEvaluator), as GridWar's are."""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.store.writer import TraceWriter
from tracelab.train.config import TrainConfig
from tracelab.train.env_checkpoint import save_env_checkpoint
from tracelab.train.env_policy import EnvEvalResult, EnvPolicy, make_vector_env, play_env_games, save_env_policy
from tracelab.envs.declared.env_source import EnvSource
from tracelab.train.env_source import ObservationEncoder, action_count
from tracelab.train.learner_protocol import Learner
from tracelab.train.loop import acting_q, close_log, eval_seed, learn_pass, make_learner, write_metric_rows
from tracelab.train.policy import BEST_POLICY_DIR
from tracelab.train.qnet import NetSpec
from tracelab.train.tensorboard import MetricSink

Progress = Callable[[dict[str, Any]], None]


class EnvTrainer:
    def __init__(self, cfg: TrainConfig, source: EnvSource, writer: TraceWriter | None = None,
                 run_dir: Path | None = None, progress: Progress | None = None,
                 metric_sinks: Sequence[MetricSink] = ()) -> None:
        torch.set_num_threads(cfg.threads)
        self.cfg, self.source, self.writer, self.run_dir, self.progress = cfg, source, writer, run_dir, progress
        self.metric_sinks = list(metric_sinks)  # besides the run: e.g. TensorBoard (train --tensorboard)
        self.worlds = w = cfg.envs
        self.env = make_vector_env(source, w, replayable=True)  # a checkpoint replays its worlds
        single = self.env.single_observation_space
        self.encoder = ObservationEncoder(single, source.name)
        self.n_actions = action_count(self.env.single_action_space, source.name)
        declared = getattr(self.env.envs[0].unwrapped, "world_spec", None)  # a declared world names its actions
        self.declared = declared is not None
        self.action_names = list(declared.action_names) if declared is not None else \
            [str(a) for a in range(self.n_actions)]
        self.rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0]))  # exploration, sampling
        self.torch_gen = torch.Generator().manual_seed(cfg.seed)
        self.net = NetSpec(self.encoder.size, cfg.hidden_sizes, self.n_actions, cfg.dueling)
        self.learner_kind, self.learner_note = cfg.learner_choice()
        self.learner: Learner = make_learner(self.learner_kind, self.net, cfg, self.torch_gen)
        self.policy = EnvPolicy(acting_q(self.learner, self.net), self.encoder, cfg.mask)
        self.step = 0
        self.update_credit = 0.0
        self.synced_block = 0
        self.eval_round = 0
        self.next_episode = 0
        self.ep_id = np.zeros(w, np.int64)
        self.ep_len = np.zeros(w, np.int64)
        self.ep_return = np.zeros(w)
        self.returns_since_log: list[float] = []
        self._begun: list[dict[str, Any]] = []
        self._ended: list[dict[str, Any]] = []
        self.last_eval: EnvEvalResult | None = None
        self.best_eval: tuple[float, int] | None = None  # (mean return, step) of the best evaluation
        self.best_weights: dict[str, torch.Tensor] = {}
        self.last_loss: float | None = None
        self.logged_step = self.eval_step = -1
        self.stop_requested = False
        self._eval_env: Any = None
        self._evaluator: Any = None  # a declared world's, tracing the first games of each evaluation
        self.obs, self.info = self.env.reset(seed=int(np.random.SeedSequence([cfg.seed, 2]).generate_state(1)[0]))
        self._begin(np.arange(w))
        self._rate_mark = (time.perf_counter(), 0, 0)

    # ---- episodes ----
    def _begin(self, worlds: np.ndarray) -> None:
        for k in worlds.tolist():
            self.ep_id[k] = self.new_episode_id()
            self._begun.append({"episode": int(self.ep_id[k]), "world": k, "t_start": 0,
                                "info": {"kind": "train", "train_step": self.step}})
        self.ep_len[worlds] = 0
        self.ep_return[worlds] = 0.0

    def new_episode_id(self) -> int:
        """The run's next episode id (training games and traced evaluation games share them)."""
        self.next_episode += 1
        return self.next_episode - 1

    def resume_games(self, first_free: int | None = None) -> None:
        """After a restore: the games in progress begin in the run again. `first_free`: the run is the
        checkpoint's own, which holds them already (ended 'aborted' at the stop): they go on under new ids
        from there, their begin info naming the id each continues."""
        self._begun = []
        if first_free is not None:
            self.next_episode = max(self.next_episode, first_free)
        for k in range(self.worlds):
            info: dict[str, Any] = {"kind": "train", "train_step": self.step}
            if first_free is not None:
                info["continues"] = int(self.ep_id[k])
                self.ep_id[k] = self.new_episode_id()
            self._begun.append({"episode": int(self.ep_id[k]), "world": k, "t_start": 0, "info": info})

    def _flush_episodes(self) -> None:
        if self.writer is not None and (self._begun or self._ended):
            self.writer.begin_episodes(self._begun)
            self.writer.end_episodes(self._ended)
        self._begun, self._ended = [], []

    # ---- one pass: every world makes one step ----
    def epsilon(self) -> float:
        return 1.0 if self.step < self.cfg.warmup else self.cfg.epsilon(self.step)

    def _masks(self) -> np.ndarray | None:
        return self.info.get("action_mask") if self.cfg.mask else None

    def _choose(self) -> np.ndarray:
        w, a = self.worlds, self.n_actions
        masks = self._masks()
        explore = self.rng.random(w) < self.epsilon()
        if masks is None:
            random = self.rng.integers(0, a, w)
        else:  # uniform among the allowed actions
            random = np.argmax(self.rng.random((w, a)) * masks, axis=1)
        if explore.all():
            return random
        return np.where(explore, random, self.policy.act(self.obs, masks))

    def env_step(self) -> None:
        cfg = self.cfg
        actions = self._choose()
        obs_now = self.encoder(self.obs)
        obs, reward, terminated, truncated, info = self.env.step(actions)
        done = terminated | truncated
        next_obs = obs
        if done.any():  # SAME_STEP autoreset: a world that ended shows its new start; its last state is final_obs
            next_obs = np.array(obs, copy=True)
            for k in np.flatnonzero(done).tolist():
                next_obs[k] = info["final_obs"][k]
        allowed = None
        if cfg.mask and "action_mask" in info:  # what may be done in s' bounds the target's max (replay.py)
            allowed = info["action_mask"].astype(bool).copy()
            allowed[done] = True  # a reset world's mask is its new start's: max over every action
        self.learner.buffer.add(obs_now, actions, (reward * cfg.reward_scale).astype(np.float32),
                                self.encoder(next_obs), (cfg.gamma * ~terminated).astype(np.float32), allowed)
        self.ep_len += 1
        self.ep_return += reward
        self.step += self.worlds
        self.obs, self.info = obs, info
        if done.any():
            ended = np.flatnonzero(done)
            for k in ended.tolist():
                self.returns_since_log.append(float(self.ep_return[k]))
                self._ended.append({"episode": int(self.ep_id[k]), "steps": int(self.ep_len[k]),
                                    "outcome": "terminated" if terminated[k] else "truncated",
                                    "reward": float(self.ep_return[k])})
            self._begin(ended)

    def learn(self) -> None:
        learn_pass(self, [self.learner])

    # ---- logging, evaluation, policies ----
    def _crossed(self, every: int, before: int) -> bool:
        return every > 0 and self.step // every > before // every

    def log_metrics(self) -> dict[str, float]:
        now = time.perf_counter()
        m: dict[str, float] = {"epsilon": self.epsilon()}
        loss = self.learner.take_loss()
        if loss is not None:
            m["loss"] = self.last_loss = loss
        q = self.learner.q_max_mean()
        if q is not None:
            m["q_max_mean"] = q / self.cfg.reward_scale
        return close_log(self, m, now, self.learner.updates)

    def write_metrics(self, values: dict[str, float]) -> None:
        write_metric_rows(self, values)

    def run_eval(self) -> EnvEvalResult:
        cfg = self.cfg
        if self.writer is not None and cfg.trace_eval_games and self.declared:
            if self._evaluator is None:
                from tracelab.train.external_eval import DeclaredEvaluator, EvalSettings
                settings = EvalSettings(cfg.eval_every, cfg.eval_games, cfg.trace_eval_games, cfg.eval_envs,
                                        seed=cfg.seed)
                self._evaluator = DeclaredEvaluator(self.source, self.writer, self.new_episode_id, settings)
            result = self._evaluator.play(self.policy, self.step, self.eval_round)
        else:
            if self._eval_env is None:
                self._eval_env = make_vector_env(self.source, min(cfg.eval_envs, cfg.eval_games))
            result = play_env_games(self._eval_env, self.policy, cfg.eval_games,
                                    eval_seed(cfg.seed, self.eval_round))
        self.write_metrics(result.metrics())
        self.eval_round += 1
        self.last_eval, self.eval_step = result, self.step
        if self.best_eval is None or result.mean_return > self.best_eval[0]:
            self.best_eval = (result.mean_return, self.step)
            self.best_weights = {k: v.clone() for k, v in self.learner.online_weights().items()}
            self.write_best_policy()
        return result

    def write_best_policy(self) -> None:
        """RUN/policy-best/ from the kept parameters (also after a resume into a new run)."""
        if self.run_dir is None or self.best_eval is None:
            return
        value, step = self.best_eval
        self._save(self.run_dir / BEST_POLICY_DIR, self.best_weights, step,
                   {"metric": "eval/mean_return", "value": value})

    def _save(self, path: Path, weights: dict[str, torch.Tensor], step: int,
              selected_by: dict[str, Any] | None = None) -> Path:
        trained = {"run": str(self.run_dir) if self.run_dir else None, "step": step,
                   "config": self.cfg.to_dict(), **({"selected_by": selected_by} if selected_by else {})}
        return save_env_policy(path, self.source, weights, self.net.to_json(), self.encoder, self.action_names,
                               self.cfg.mask, trained)

    def save_policy(self, path: Path) -> Path:
        return self._save(path, self.learner.online_weights(), self.step)

    # ---- the loop ----
    def train(self, stop_at: int | None = None) -> str:
        cfg = self.cfg
        last_progress = 0.0
        end = cfg.steps if stop_at is None else min(cfg.steps, stop_at)
        while self.step < end and not self.stop_requested:
            before = self.step
            self.env_step()
            self.learn()
            if self._crossed(cfg.log_every, before):
                self.log_metrics()
            if self._crossed(cfg.eval_every, before):
                self.run_eval()
            if self.run_dir is not None and self._crossed(cfg.checkpoint_every, before):
                self._flush_episodes()  # the run holds every episode the checkpoint has counted
                save_env_checkpoint(self, self.run_dir)
            if self.progress is not None and time.monotonic() - last_progress > 0.2:
                last_progress = time.monotonic()
                self.progress(self.figures())
        status = "interrupted" if self.step < cfg.steps else "finished"
        if status == "finished":
            if self.logged_step != self.step:
                self.log_metrics()
            if self.eval_step != self.step:
                self.run_eval()
        self._ended += [{"episode": int(self.ep_id[k]), "steps": int(self.ep_len[k]), "outcome": "aborted",
                         "reward": float(self.ep_return[k])} for k in range(self.worlds)]
        self._flush_episodes()
        if self.run_dir is not None:
            save_env_checkpoint(self, self.run_dir)
            self.save_policy(self.run_dir / "policy")
        if self.progress is not None:
            self.progress(self.figures())
        return status

    def figures(self) -> dict[str, Any]:
        ev = self.last_eval
        return {"step": self.step, "steps": self.cfg.steps, "epsilon": self.epsilon(), "loss": self.last_loss,
                "mean_return": None if ev is None else ev.mean_return,
                "success_rate": None if ev is None else ev.success_rate}

    def close(self) -> None:
        self.env.close()
        if self._eval_env is not None:
            self._eval_env.close()
        if self._evaluator is not None:
            self._evaluator.close()
