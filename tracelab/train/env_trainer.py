"""tracelab's DQN trainer, on any gymnasium env with Discrete actions (`tracelab train`: a world's spec, a
registered id): ε-greedy over the batched worlds, transitions into replay, one update per
world-step, target copies, evaluations, the run's metrics and episodes, checkpoints, the final and the
best policy.

Its state is owned by parts that each save and load themselves (EnvTrainer.state; a checkpoint is their
states side by side, env_checkpoint.py): `rngs` (every generator, from the seed), `exploration` (ε and the
random actions), `learner` (network and optimiser, with its replay buffer: make_learner, fused or
readable, behind the Learner protocol), `schedule` (when updates and target copies are due), `pending` (a
team's open transitions), `episodes` (the worlds' episodes and their rows in the run), `actions_log` (the
worlds' actions since their reset, to rebuild them), `metrics` and `best` (the best evaluation's network).
The loop is train_loop.py's. Observations are encoded for the network by env_source.ObservationEncoder (a
Discrete one is one-hot); a declared world's first evaluation games are traced into the run
(external_eval.DeclaredEvaluator).

Several agents a team (a declared world whose `[agents] names` are several: the war game's 5v5, its non-Markov
scenario): one network for all of them (parameter sharing, env_policy.TeamPolicy: each agent's observation and its
one-hot index is a row of the batch), every world stepped by one engine call (DeclaredVectorEnv's team
mode). An agent's transition (transitions.py) runs from a step where it decides (the spec's `[agents]
decides`: alive, a slow agent on its even steps) to its next decision, the end of the episode or its
death (`[agents] alive`: no bootstrap), earning its own reward (the spec's per-agent reward) discounted by
the steps it spans; an agent that does not decide does nothing and adds no transition."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.store.writer import TraceWriter
from tracelab.errors import UserError
from tracelab.train.config import TrainConfig, flag_of
from tracelab.train.env_checkpoint import ActionLog, replay_actions, save_env_checkpoint
from tracelab.train.env_policy import (BEST_POLICY_DIR, EnvEvalResult, EnvPolicy, TeamPolicy, declares_outcomes,
                                       make_vector_env, play_env_games, save_env_policy, world_spec_of)
from tracelab.envs.declared.env_source import EnvSource
from tracelab.train.env_source import ObservationEncoder, TeamEncoder, action_count
from tracelab.train.external_eval import DeclaredEvaluator, EvalSettings
from tracelab.train.dqn import DQN
from tracelab.train.learner_protocol import Learner
from tracelab.train.best_policy import BestPolicy
from tracelab.train.episode_log import EpisodeLog
from tracelab.train.exploration import Exploration
from tracelab.train.train_loop import NetworkFactory, acting_q, load_shared_state, make_learner, train_loop
from tracelab.train.metric_log import MetricLog
from tracelab.train.rngs import Generators
from tracelab.train.transitions import PendingTransitions
from tracelab.train.tensorboard import MetricSink
from tracelab.train.update_schedule import UpdateSchedule

SHARED = "shared"  # the one network's name (policy.json's `networks`)
Progress = Callable[[dict[str, Any]], None]


class EnvTrainer:
    def __init__(self, cfg: TrainConfig, source: EnvSource, writer: TraceWriter | None = None,
                 run_dir: Path | None = None, progress: Progress | None = None,
                 metric_sinks: Sequence[MetricSink] = (), eval_source: EnvSource | None = None,
                 network: NetworkFactory | None = None, learner_class: type[DQN] | None = None,
                 spec: Any = None) -> None:
        """`eval_source`: the env evaluations play, if not `source` (the same world at other params); the
        rest is the Python API (docs/training.md, "The learner"): `network` trains the readable learner on
        this module instead of the MLP cfg.hidden describes (its policy files say `custom`), `learner_class`
        is the readable learner's class (a subclass of DQN with another loss, say); `metric_sinks` receive
        the metrics besides the run (e.g. TensorBoard, train --tensorboard); `spec`: `source`'s WorldSpec if
        loaded already (not parsed again)."""
        torch.set_num_threads(cfg.threads)
        self.cfg, self.source, self.writer, self.run_dir, self.progress = cfg, source, writer, run_dir, progress
        self.eval_source = eval_source or source
        self.worlds = w = cfg.envs
        # a declared world's own batched engine where its spec allows (else SyncVectorEnv, and why)
        self.env, self.vector_note = make_vector_env(source, w, by_term=cfg.decompose, kernel=cfg.kernel, spec=spec)
        # a checkpoint replays the worlds from their reset (env_checkpoint.py); a team's, each agent's
        self.actions_log = ActionLog(w * getattr(self.env, "n_agents", 1))
        declared = world_spec_of(self.env)  # a declared world names its actions
        self.agents = n = getattr(self.env, "n_agents", 1)
        if n == 1:
            self.encoder: Any = ObservationEncoder(self.env.single_observation_space, source.name)
            self.n_actions = action_count(self.env.single_action_space, source.name)
        else:  # a team: each agent's observation and index a row (env_policy.TeamPolicy)
            if cfg.decompose:
                raise UserError(f"{source.name}: --decompose trains one agent; this world has {n}")
            self.encoder = TeamEncoder(ObservationEncoder(self.env.agent_observation_space, source.name), n)
            self.n_actions = len(declared.action_names)
        self.declared = declared is not None
        self.counts_wins = declares_outcomes(self.env)  # its [end] win / loss: the method's counting
        self.action_names = list(declared.action_names) if declared is not None else \
            [str(a) for a in range(self.n_actions)]
        self.rngs = Generators(cfg.seed)
        self.exploration = Exploration(cfg, self.rngs.numpy)
        self.net = cfg.network(self.encoder.size, self.n_actions, declared.reward_terms if declared else ())
        for env in self.env.envs if self.net.terms else ():  # --decompose: each step's reward by term
            env.unwrapped.world.keep_reward_terms = True
        if cfg.explore_scripted > 0 and (declared is None or declared.script is None or n == 1 and
                                         not hasattr(self.env, "script")):
            raise UserError(f"{flag_of('explore_scripted')} {cfg.explore_scripted}: {source.name} declares no "
                            f"scripted choice ([agents] script, docs/worlds.md) in a batched declared env")
        self.learner_kind = cfg.learner_choice()
        self.custom_network = network is not None
        if network is not None or learner_class is not None:
            if cfg.learner == "fused":
                raise UserError("a network module or a learner class trains with the readable learner, not "
                                "--learner fused")
            self.learner_kind = "readable"
        self.learner: Learner = make_learner(self.learner_kind, self.net, cfg, self.rngs.torch, network,
                                             learner_class or DQN)
        # a custom module acts through torch (TorchQ), a described one in numpy
        rows = EnvPolicy(acting_q(self.learner, None if self.custom_network else self.net), self.encoder, cfg.mask)
        self.policy: Any = rows if n == 1 else TeamPolicy(rows, n)
        # a team's open transitions (world, agent): from a decision to the next, the end, or a death
        self.pending = PendingTransitions(w, n, self.encoder.size, cfg.gamma) if n > 1 else None
        # --slow-every-step: every living agent decides every step (the world ignores what it may not do)
        self.decides = "alive" if cfg.slow_every_step else "decides"
        self.schedule = UpdateSchedule(cfg, w)
        self.episodes = EpisodeLog(w, writer, logging=False)  # begins are written once train() starts
        self.metrics = MetricLog(writer, metric_sinks)
        # by the method's win rate where the world declares a win, else the mean return (EnvEvalResult.selection)
        self.best = BestPolicy()
        self.step = 0
        self.eval_round = 0
        self.eval_step = -1
        self.last_eval: EnvEvalResult | None = None
        self.stop_requested = False
        self._eval_env: Any = None
        self._evaluator: Any = None  # a declared world's, tracing the first games of each evaluation
        self.env_seed = self.rngs.env_seed()
        self.obs, self.info = self.env.reset(seed=self.env_seed)
        self.episodes.begin(np.arange(w), self.step)

    def _flag(self, info: dict[str, Any], key: str) -> np.ndarray:
        """A team's `decides` or `alive` [W, agents] (every agent, where the spec does not declare it)."""
        return info[key] if key in info else np.ones((self.worlds, self.agents), bool)

    @property
    def best_eval(self) -> tuple[float, int] | None:
        """(the selection's value, step) of the best evaluation so far (EnvEvalResult.selection)."""
        return self.best.eval

    # ---- one pass: every world makes one step ----
    def epsilon(self) -> float:
        return self.exploration.epsilon(self.step)

    def _masks(self) -> np.ndarray | None:
        return self.info.get("action_mask") if self.cfg.mask else None

    def _choose(self) -> np.ndarray:
        masks = self._masks()
        explore, random = self.exploration.draw(self.step, (self.worlds,), self.n_actions, masks)
        random = self._scripted(random, masks)
        if explore.all():
            return random
        return np.where(explore, random, self.policy.act(self.obs, masks))

    def _scripted(self, random: np.ndarray, masks: np.ndarray | None) -> np.ndarray:
        """--explore-scripted: that share of the exploring actions is the world's scripted choice (the
        spec's `[agents] script`: one of the actions it names, uniformly; none named: the random one)."""
        if self.cfg.explore_scripted <= 0:
            return random
        named = self.env.script()
        rng = self.exploration.rng
        scripted = np.where(named.any(axis=-1), np.argmax(rng.random(named.shape) * named, axis=-1), random)
        return self.exploration.mix_in(random, scripted, masks)

    def env_step(self) -> None:
        if self.agents > 1:
            return self.team_step()
        cfg = self.cfg
        actions = self._choose()
        obs_now = self.encoder(self.obs)
        obs, reward, terminated, truncated, info = self.env.step(actions)
        self.actions_log.add(actions)
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
        learned = reward  # --decompose: each world's step reward by term, [W, terms] (they sum to `reward`)
        if self.net.terms:
            learned = np.stack([env.unwrapped.world.last_reward_terms[0] for env in self.env.envs])
        self.learner.buffer.add(obs_now, actions, (learned * cfg.reward_scale).astype(np.float32),
                                self.encoder(next_obs), (cfg.gamma * ~terminated).astype(np.float32), allowed)
        self.episodes.add_step(reward)
        self.step += self.worlds
        self.obs, self.info = obs, info
        if done.any():
            self._end_games(done, terminated, info)

    def team_step(self) -> None:
        """Every world one step of every agent: the deciding agents ε-greedy, the others doing nothing (-1);
        the transitions that close (the agent decides again, dies, or its episode ends) into the replay."""
        cfg, w, n = self.cfg, self.worlds, self.agents
        masks = self._masks()
        acting = self._flag(self.info, self.decides)
        explore, random = self.exploration.draw(self.step, (w, n), self.n_actions, masks)
        random = self._scripted(random, masks)
        greedy = acting & ~explore
        actions = random
        if greedy.any():
            actions = np.where(greedy, self.policy.act(self.obs, masks), random)
        actions = np.where(acting, actions, -1)
        x = self.encoder(self.obs).reshape(w, n, -1)
        self.pending.start(acting, [x[:, j] for j in range(n)], actions)
        obs, reward, terminated, truncated, info = self.env.step(actions)
        self.actions_log.add(actions.reshape(-1))
        self.pending.earn(info["agent_reward"] * cfg.reward_scale)
        done = terminated | truncated
        true_next, alive = obs, self._flag(info, "alive")
        if done.any():  # SAME_STEP autoreset: an ended world's last state is in final_obs / final_info
            true_next, alive = np.array(obs, copy=True), alive.copy()
            true_next[done] = info["final_obs"][done]
            if "alive" in info:
                alive[done] = info["final_info"]["alive"][done]
        decides = self._flag(info, self.decides)
        dead = ~alive
        closed = self.pending.close(done[:, None] | dead | decides, terminated[:, None] | dead)
        if len(closed["action"]):
            cw, ca = closed["world"], closed["agent"]
            allowed = None
            if cfg.mask and "action_mask" in info:  # s' mask bounds the target's max; an ended world's: all
                allowed = info["action_mask"][cw, ca].astype(bool)
                allowed[done[cw]] = True
            next_x = self.encoder(true_next).reshape(w, n, -1)[cw, ca]
            self.learner.buffer.add(closed["obs"], closed["action"], closed["reward"], next_x, closed["discount"],
                                    allowed)
        self.episodes.add_step(reward)
        self.step += w
        self.obs, self.info = obs, info
        if done.any():
            self._end_games(done, terminated, info)

    def _end_games(self, done: np.ndarray, terminated: np.ndarray, info: dict[str, Any]) -> None:
        ended = np.flatnonzero(done)
        named = info.get("final_info", {}).get("outcome")  # win / loss, where the world declares them
        self.episodes.end(ended, [str(named[k]) if named is not None and named[k] else
                                  "terminated" if terminated[k] else "truncated" for k in ended.tolist()])
        self.episodes.begin(ended, self.step)

    # ---- logging, evaluation, policies ----
    def log_metrics(self) -> dict[str, float]:
        m: dict[str, float] = {"epsilon": self.epsilon()}
        loss = self.learner.take_loss()
        if loss is not None:
            m["loss"] = loss
        q = self.learner.q_max_mean()
        if q is not None:
            m["q_max_mean"] = q / self.cfg.reward_scale
        self.metrics.complete(m, self.step, self.learner.updates, self.episodes.take_returns())
        self.episodes.flush()
        self.write_metrics(m)
        return m

    def write_metrics(self, values: dict[str, float]) -> None:
        self.metrics.write(self.step, values)

    def run_eval(self) -> EnvEvalResult:
        cfg = self.cfg
        if self.writer is not None and cfg.trace_eval_games and self.declared:
            if self._evaluator is None:
                settings = EvalSettings(cfg.eval_every, cfg.eval_games, cfg.trace_eval_games, cfg.eval_envs,
                                        seed=cfg.seed)
                self._evaluator = DeclaredEvaluator(self.eval_source, self.writer, self.episodes.new_id, settings)
            result = self._evaluator.play(self.policy, self.step, self.eval_round)
        else:
            if self._eval_env is None:
                self._eval_env, _ = make_vector_env(self.eval_source, min(cfg.eval_envs, cfg.eval_games),
                                                   kernel=cfg.kernel)
            result = play_env_games(self._eval_env, self.policy, cfg.eval_games, self.rngs.eval_seed(self.eval_round))
        self.write_metrics(result.metrics())
        self.eval_round += 1
        self.last_eval, self.eval_step = result, self.step
        if self.best.consider(result.selection()[1], self.step, {SHARED: self.learner.online_weights()}):
            self.write_best_policy()
        return result

    def write_best_policy(self) -> None:
        """RUN/policy-best/ from the kept parameters (also after a resume into a new run)."""
        if self.run_dir is None or self.best.eval is None:
            return
        value, step = self.best.eval
        metric = "eval/method_win_rate" if self.counts_wins else "eval/mean_return"
        self._save(self.run_dir / BEST_POLICY_DIR, self.best.weights[SHARED], step, {"metric": metric, "value": value})

    def _save(self, path: Path, weights: dict[str, torch.Tensor], step: int,
              selected_by: dict[str, Any] | None = None) -> Path:
        trained = {"run": str(self.run_dir) if self.run_dir else None, "step": step,
                   "config": self.cfg.to_dict(), **({"selected_by": selected_by} if selected_by else {})}
        return save_env_policy(path, self.source, weights, self.network_json(), self.encoder, self.action_names,
                               self.cfg.mask, trained)

    def network_json(self) -> dict[str, Any]:
        """policy.json's `network`: the architecture, or what a custom module is (no file rebuilds one)."""
        if not self.custom_network:
            return self.net.to_json()
        module = self.learner.q_network  # type: ignore[attr-defined]  # the readable learner's
        return {"inputs": self.net.inputs, "outputs": self.net.actions, "custom": repr(module)[:4000]}

    def save_policy(self, path: Path) -> Path:
        return self._save(path, self.learner.online_weights(), self.step)

    # ---- the loop ----
    def train(self, stop_at: int | None = None) -> str:
        """Train until cfg.steps, or until stop_requested (Ctrl-C) or step `stop_at` (train_loop.train_loop),
        each pass one env_step of every world; returns "finished" or "interrupted"."""
        return train_loop(self, stop_at, self.env_step, [self.learner], save_env_checkpoint)

    # ---- checkpoints: the parts' states side by side (env_checkpoint.py writes and checks them) ----
    def state(self) -> dict[str, Any]:
        """Everything that decides what happens next, as tensors, arrays and plain values (some arrays are
        the parts' live ones: save_env_checkpoint copies them)."""
        episodes = self.episodes.state()
        return {
            "step": self.step, "eval_round": self.eval_round, "eval_step": self.eval_step,
            "learner": self.learner_kind, "custom_network": self.custom_network,
            "learners": {SHARED: self.learner.state()},
            **self.rngs.state(), **self.schedule.state(), **self.metrics.state(), **self.best.state(), **episodes,
            "games": {**episodes["games"], "obs": self.encoder(self.obs)},
            "env_seed": self.env_seed, "env_actions": self.actions_log.array(),
            **({"pending": self.pending.state()} if self.pending is not None else {}),
        }

    def load_state(self, st: dict[str, Any]) -> None:
        """Continue from `state()`'s output (checked by env_checkpoint.load_env_checkpoint); the worlds are
        rebuilt by replaying their actions from the reset. ValueError when the replay does not end in the saved
        observations (another env, or version of it, than the checkpoint's)."""
        load_shared_state(self, {SHARED: self.learner}, st)
        g = st["games"]
        self.env_seed = int(st["env_seed"])
        self.actions_log.load(st["env_actions"])
        actions = self.actions_log.array()
        obs, self.info = replay_actions(self.env, self.env_seed,
                                        actions if self.agents == 1 else actions.reshape(len(actions), -1, self.agents))
        if not np.array_equal(self.encoder(obs), g["obs"]):
            raise ValueError("replaying the checkpoint's games did not reproduce their observations: another env "
                             "(or version of it) than the one it was written with, or an edited file")
        self.obs = obs
        if self.pending is not None:
            self.pending.load_state(st["pending"])

    def renumber_games(self, first_free: int) -> None:
        """After a restore into the checkpoint's own run: the games go on under new episode ids
        (EpisodeLog.renumber)."""
        self.episodes.renumber(first_free)

    def figures(self) -> dict[str, Any]:
        ev = self.last_eval
        return {"step": self.step, "steps": self.cfg.steps, "epsilon": self.epsilon(), "loss": self.metrics.last_loss,
                "mean_return": None if ev is None else ev.mean_return,
                "win_rate": None if ev is None else ev.win_rate,
                "success_rate": None if ev is None else ev.success_rate}

    def close(self) -> None:
        self.env.close()
        if self._eval_env is not None:
            self._eval_env.close()
        if self._evaluator is not None:
            self._evaluator.close()


def env_run_meta(cfg: TrainConfig, source: EnvSource, command: str,
                 resumed_from: dict[str, Any] | None = None, world: Any = None,
                 spec: Any = None) -> dict[str, Any]:
    """The meta of a run that trains on `source` (`train --env`, a sweep's trial): the env and the
    training's settings; for a declared world whose evaluations are traced, what `why`, `tui` and
    `replay` read of it (its rule files, its spec and rules by path, size and hash, what sets each external
    fact, its board: DeclaredTarget's; the texts go in the run's `sources` table with its traced games).
    `world`: a registration's training of `source` (the war game's ScenarioTraining): the run takes its
    `name` and keeps its `run_config()`. `spec`: `source`'s WorldSpec where the caller loaded it already
    (probe_env's: parsing war.toml again cost train ~0.2 s of CPU before its first step)."""
    # deferred: loads the engine (numba), which a gymnasium id's training does not need
    from tracelab.envs.declared.play import load_declared
    from tracelab.train.external_eval import DeclaredTarget

    settings = cfg.to_dict() if world is None else {**cfg.to_dict(), **world.run_config()}
    meta = {"command": command, "scenario": source.name if world is None else world.name, "seed": cfg.seed,
            "config": {**settings, "env": source.to_json(), "resumed_from": resumed_from}}
    if not cfg.trace_eval_games:
        return meta
    try:
        spec = spec if spec is not None else load_declared(source)
    except UserError:  # not a declared world: its evaluations are not traced
        return meta
    described = DeclaredTarget(source, spec).run_meta()
    return {**meta, "rule_files": described["rule_files"], "config": {**described["config"], **meta["config"]}}
