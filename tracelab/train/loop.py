"""RuleSim's GridWar trainer (issue 38: going). `tracelab train` trains through EnvTrainer
(env_trainer.py); this Trainer is left only for its last importers, tracelab/train/experiments/runner.py's
RuleSim arm and tracelab/bench/eval.py, which are moving off it; delete this module (and game_record.py)
when they have. Its checkpoints are written in RuleSim's format, which nothing resumes any more
(env_checkpoint.py refuses it in one line)."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.envs.common import ActionMasker
from tracelab.envs.tracer import outcome_name
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.opponent import scripted_actions
from tracelab.game.scenario import NOTHING, RED, Scenario
from tracelab.store.writer import TraceWriter
from tracelab.train.best_policy import BestPolicy
from tracelab.train.env_checkpoint import write_checkpoint
from tracelab.train.config import TrainConfig
from tracelab.train.evaluate import EvalResult, EvalTrace, evaluate
from tracelab.train.dqn import DQN
from tracelab.train.episode_log import EpisodeLog
from tracelab.train.exploration import Exploration
from tracelab.train.game_record import GameRecord
from tracelab.train.learner_protocol import Learner
from tracelab.train.metric_log import MetricLog
from tracelab.train.env_policy import BEST_POLICY_DIR, Policy, may_act, save_policy
from tracelab.train.rngs import Generators
from tracelab.train.train_loop import NetworkFactory, acting_q, load_shared_state, make_learner, train_loop
from tracelab.train.run_networks import network_groups, training_net
from tracelab.train.tensorboard import MetricSink
from tracelab.train.transitions import PendingTransitions
from tracelab.train.update_schedule import UpdateSchedule

Progress = Callable[[dict[str, Any]], None]
RULESIM_FORMAT = "tracelab-dqn-checkpoint/2"


def save_checkpoint(tr: Any, run_dir: Path) -> Path:
    """RuleSim's checkpoint format (refused by env_checkpoint.checkpoint_env: nothing resumes it)."""
    return write_checkpoint(run_dir, {"format": RULESIM_FORMAT, "config": tr.cfg.to_dict(),
                                      "scenario_toml": tr.scenario.to_toml(), "run": str(run_dir), **tr.state()})


def _agent_rewards(info: dict, done: np.ndarray) -> np.ndarray:
    """Each red agent's reward of the step, [W, N]. Worlds that ended were reset within the step (SAME_STEP
    autoreset), so their top-level info is the new episode's (zeros): their terminal step's rewards, the
    win or loss term included, are in final_info."""
    if not done.any():
        return info["agent_reward"]
    return np.where(done[:, None], info["final_info"]["agent_reward"], info["agent_reward"])


class Trainer:
    """GridWar's DQN trainer. Its state is owned by parts that each save and load themselves (a
    checkpoint is their states side by side, checkpoint.py): `rngs` (every generator, from the seed),
    `exploration` (ε and the random actions), `learners` (networks, optimiser, each with its replay
    buffer), `schedule` (when updates and target copies are due), `pending` (the agents' open
    transitions), `episodes` (the worlds' episodes and their rows in the run), `games` (the actions
    played, to rebuild the worlds), `metrics` (the metric rows and what every log adds) and `best` (the
    best evaluation's networks). The trainer itself keeps the step and the evaluation rounds."""

    def __init__(self, cfg: TrainConfig, scenario: Scenario, writer: TraceWriter | None = None,
                 run_dir: Path | None = None, progress: Progress | None = None,
                 network: NetworkFactory | None = None, learner_class: type[DQN] | None = None,
                 metric_sinks: Sequence[MetricSink] = ()) -> None:
        """Python API (docs/training.md, "The learner"): `network` trains the readable learner on this
        module instead of the MLP cfg.hidden describes (its policy files say `custom`); `learner_class` is
        the readable learner's class (a subclass of DQN with another loss, say); `metric_sinks` receive
        the metrics besides the run (e.g. TensorBoard, train --tensorboard)."""
        torch.set_num_threads(cfg.threads)
        self.cfg, self.scenario, self.writer, self.run_dir, self.progress = cfg, scenario, writer, run_dir, progress
        self.stack = cfg.non_markov
        w, n = cfg.envs, scenario.agents_per_team
        self.worlds, self.agents = w, n
        self.rngs = Generators(cfg.seed)
        self.exploration = Exploration(cfg, self.rngs.numpy)
        # copy=False: the observation a step returns is the env's buffer, rewritten by the next step. What
        # outlives a step is copied where it is kept: the open transitions copy the agents' views
        # (PendingTransitions.start), the replay buffer copies obs and next obs into its rows, a checkpoint
        # copies self.obs; self.obs itself is only read before the next step (acting, choosing)
        self.env = GridWarVectorEnv(w, scenario, backend=cfg.backend, stack_previous=self.stack,
                                    opponent_p=cfg.opponent_p, kernel=cfg.kernel, copy=False)
        self.masker = ActionMasker(scenario)
        self.net = training_net(cfg, scenario)
        self.custom_network = network is not None
        self.learner_kind, self.learner_note = cfg.learner_choice()
        if network is not None or learner_class is not None:
            if cfg.learner == "fused":
                raise ValueError("a network module or a learner class trains with the readable learner, not "
                                 "learner fused")
            self.learner_kind, self.learner_note = "readable", None
        self.groups = network_groups(scenario, cfg.split_networks)
        self.learners: dict[str, Learner] = {
            name: make_learner(self.learner_kind, self.net, cfg, self.rngs.torch, network, learner_class or DQN)
            for name in self.groups}
        owner = {j: i for i, agents in enumerate(self.groups.values()) for j in agents}
        described = None if self.custom_network else self.net
        self.policy = Policy(scenario, [acting_q(lr, described) for lr in self.learners.values()],
                             [owner[j] for j in range(n)], self.stack, cfg.mask)
        self.schedule = UpdateSchedule(cfg, w)
        self.pending = PendingTransitions(w, n, self.net.inputs, cfg.gamma)
        self.ids = np.asarray(scenario.action_ids, np.int64)
        self.nothing = scenario.action_ids.index(NOTHING)
        self.action_index = np.zeros(NOTHING + 1, np.int64)  # spec action id -> index into action_ids
        self.action_index[self.ids] = np.arange(len(self.ids))
        self.episodes = EpisodeLog(w, writer, logging=False)  # episode begins are written once train() starts
        self.games = GameRecord(w, scenario.max_steps, n)
        self.metrics = MetricLog(writer, metric_sinks)
        self.best = BestPolicy()  # by the method's win rate against --eval-p
        self.step = 0
        self.eval_round = 0
        self.eval_step = -1
        self.last_eval: EvalResult | None = None
        self.stop_requested = False
        self._eval_env: GridWarVectorEnv | None = None
        self._masks: np.ndarray | None = None  # the shield's mask of the current state (--mask), from the step
        self._eval_trace: EvalTrace | None = None
        self.obs, _ = self.env.reset(seed=self.rngs.env_seed())
        self.acting = self.may_act()
        self.episodes.begin(np.arange(w), self.step)

    # ---- the loop ----
    def train(self, stop_at: int | None = None) -> str:
        """Train until cfg.steps, or until stop_requested (Ctrl-C) or step `stop_at` (as an interruption
        there would); returns "finished" or "interrupted"."""
        def collect_and_store() -> None:
            closed, true_next = self.collect()  # every world one ε-greedy step
            self.store(closed, true_next)        # the transitions that closed, into their network's replay

        return train_loop(self, stop_at, collect_and_store, self.learners.values(), save_checkpoint)

    # ---- collect: every world makes one step ----
    def collect(self) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """One ε-greedy step of every world; returns the agents' transitions it closed (PendingTransitions
        .close) and the worlds' true next observations (a world that ended: its last one, not its reset)."""
        cfg, w, n = self.cfg, self.worlds, self.agents
        masks = None
        if cfg.mask:  # the shield's mask of this state: read after the previous step, or now
            masks = self._masks if self._masks is not None else self.masker.for_sim(self.env.sim, RED)
        actions = self.choose(masks)
        self.pending.start(self.acting, self._views(self.obs), actions)
        obs, reward, terminated, truncated, info = self.env.step(actions[:, 0] if n == 1 else actions)
        self.games.record(self.episodes.lengths, self.ids[actions], info["opponent_actions"].reshape(w, n))
        self.episodes.add_step(reward)
        done = terminated | truncated
        self.pending.earn((reward[:, None] if n == 1 else _agent_rewards(info, done)) * cfg.reward_scale)
        true_next = obs
        if done.any():
            true_next = obs.copy()
            true_next[done] = info["final_obs"][done]
        acting_next = self.may_act()
        dead = true_next[:, 0:2 * n:2] < 0  # an agent's own x is -1 once it is dead
        closed = self.pending.close(done[:, None] | dead | acting_next, terminated[:, None] | dead)
        # s' mask, and the next act's: the env computed it for its info (a reset world's is its new start's)
        self._masks = info["action_mask"].reshape(w, n, -1) if cfg.mask else None
        if len(closed["action"]) and cfg.mask:  # what the shield allows in s' bounds the target's max (replay.py)
            allowed = self._masks[closed["world"], closed["agent"]].astype(bool)
            # a world that ended has been reset: its next state's mask is gone; a terminated
            # transition has no bootstrap, a truncated one takes the max over all actions
            allowed[done[closed["world"]]] = True
            closed["next_allowed"] = allowed
        self.obs, self.acting = obs, acting_next
        self.step += w
        if done.any():
            ended = np.flatnonzero(done)
            final = info["final_info"]
            self.episodes.end(ended, [outcome_name(final["winner"][k], bool(truncated[k])) for k in ended.tolist()])
            self.episodes.begin(ended, self.step)
        return closed, true_next

    def choose(self, masks: np.ndarray | None) -> np.ndarray:
        """The acting agents' actions [W, N]: ε-greedy, exploring uniformly (over the allowed actions with
        masks) or partly by the scripted policy (--explore-scripted); the others do nothing."""
        explore, random = self.exploration.draw(self.step, (self.worlds, self.agents), self.net.actions, masks)
        if self.cfg.explore_scripted > 0:
            # the scripted base policy played for red, always towards blue's base where it can (the
            # opponent's policy with p = 1), drawn from the exploration stream: a resumed run draws the same
            s = self.env.sim.state
            spec = scripted_actions(s.pos, s.alive, s.ammo, "red", self.scenario, self.exploration.rng, 1.0)
            random = self.exploration.mix_in(random, self.action_index[spec], masks)
        greedy_rows = self.acting & ~explore
        actions = random
        if greedy_rows.any():
            actions = np.where(greedy_rows, self.policy.act(self.obs, greedy_rows, masks), random)
        return np.where(self.acting, actions, self.nothing)

    def _views(self, team_obs: np.ndarray) -> list[np.ndarray]:
        return [self.policy.agent_obs(team_obs, j) for j in range(self.agents)]

    def may_act(self) -> np.ndarray:
        """Which red agents decide this step (see policy.may_act and --slow-every-step)."""
        return may_act(self.scenario, self.env.sim.state, self.cfg.slow_every_step)

    # ---- store ----
    def store(self, closed: dict[str, np.ndarray], true_next: np.ndarray) -> None:
        """Closed transitions into their network's buffer, with next_obs in the agent's own view."""
        if not len(closed["action"]):
            return
        allowed = closed.get("next_allowed")
        if self.agents == 1:
            self.learners["shared"].buffer.add(closed["obs"], closed["action"], closed["reward"],
                                               true_next[closed["world"]], closed["discount"], allowed)
            return
        next_obs = np.empty_like(closed["obs"])
        for j in range(self.agents):
            rows = closed["agent"] == j
            next_obs[rows] = self.policy.agent_obs(true_next[closed["world"][rows]], j)
        for name, agents in self.groups.items():
            sel = np.isin(closed["agent"], agents)
            self.learners[name].buffer.add(closed["obs"][sel], closed["action"][sel], closed["reward"][sel],
                                           next_obs[sel], closed["discount"][sel],
                                           None if allowed is None else allowed[sel])

    # ---- log ----
    def epsilon(self) -> float:
        return self.exploration.epsilon(self.step)

    def log_metrics(self) -> dict[str, float]:
        """The learners' figures since the last log, with the training returns and rates; the episodes
        ended since then go to the run first."""
        m: dict[str, float] = {"epsilon": self.epsilon()}
        losses = {name: lr.take_loss() for name, lr in self.learners.items()}
        known = [v for v in losses.values() if v is not None]
        if known:
            m["loss"] = float(np.mean(known))
            if len(losses) > 1:
                m.update({f"loss/{k}": v for k, v in losses.items() if v is not None})
        qs = [q for q in (lr.q_max_mean() for lr in self.learners.values()) if q is not None]
        if qs:
            m["q_max_mean"] = float(np.mean(qs)) / self.cfg.reward_scale  # in the game's reward units
        updates = sum(lr.updates for lr in self.learners.values())
        self.metrics.complete(m, self.step, updates, self.episodes.take_returns())
        self.episodes.flush()
        self.write_metrics(m)
        return m

    def write_metrics(self, values: dict[str, float]) -> None:
        self.metrics.write(self.step, values)

    # ---- evaluate ----
    def run_eval(self) -> EvalResult:
        cfg = self.cfg
        if self._eval_env is None:
            self._eval_env = GridWarVectorEnv(min(cfg.eval_envs, cfg.eval_games), self.scenario,
                                              backend=cfg.backend, stack_previous=self.stack,
                                              opponent_p=cfg.eval_p, kernel=cfg.kernel, copy=False)
        traced = min(cfg.trace_eval_games, cfg.eval_games) if self.writer is not None else 0
        if traced and self._eval_trace is None:
            self._eval_trace = EvalTrace(self.writer, self.scenario, cfg.backend, self.stack, traced,
                                         cfg.eval_p, self.episodes.new_id, cfg.kernel)
        info = {"kind": "eval", "train_step": self.step, "eval_round": self.eval_round, "opponent_p": cfg.eval_p}
        result = evaluate(self.policy, self.scenario, games=cfg.eval_games, backend=cfg.backend,
                          seed=self.rngs.eval_seed(self.eval_round), opponent_p=cfg.eval_p,
                          stack_previous=self.stack, trace=self._eval_trace if traced else None,
                          trace_info=info, env=self._eval_env)
        self.write_metrics(result.metrics())
        self.eval_round += 1
        self.last_eval, self.eval_step = result, self.step
        weights = {name: lr.online_weights() for name, lr in self.learners.items()}
        if self.best.consider(result.method_win_rate, self.step, weights):
            self.write_best_policy()
        return result

    @property
    def best_eval(self) -> tuple[float, int] | None:
        """(the method's win rate, step) of the best evaluation so far."""
        return self.best.eval

    # ---- policies ----
    def write_best_policy(self) -> None:
        """RUN/policy-best/ from the kept parameters (also after --resume into a new run)."""
        if self.run_dir is None or self.best.eval is None:
            return
        value, step = self.best.eval
        save_policy(self.run_dir / BEST_POLICY_DIR, self.scenario, self.best.weights, self.groups,
                    self.network_json(), self.stack, self.cfg.mask, self._trained(step, {
                        "metric": "eval/method_win_rate", "value": value, "opponent_p": self.cfg.eval_p}))

    def network_json(self) -> dict[str, Any]:
        """policy.json's `network`: the architecture, or what a custom module is (it cannot be rebuilt from
        a file)."""
        if not self.custom_network:
            return self.net.to_json()
        module = next(iter(self.learners.values())).q_network  # type: ignore[attr-defined]
        return {"inputs": self.net.inputs, "outputs": self.net.actions, "custom": repr(module)[:4000]}

    def _trained(self, step: int, selected_by: dict[str, Any] | None = None) -> dict[str, Any]:
        out = {"run": str(self.run_dir) if self.run_dir else None, "step": step, "config": self.cfg.to_dict()}
        return out if selected_by is None else {**out, "selected_by": selected_by}

    def save_policy(self, path: Path) -> Path:
        return save_policy(path, self.scenario, {k: lr.online_weights() for k, lr in self.learners.items()},
                           self.groups, self.network_json(), self.stack, self.cfg.mask, self._trained(self.step))

    # ---- checkpoints: the parts' states side by side ----
    def state(self) -> dict[str, Any]:
        """Everything that decides what happens next, as tensors, arrays and plain values (some arrays are
        the parts' live ones: save_checkpoint copies them)."""
        episodes = self.episodes.state()
        return {
            "step": self.step, "eval_round": self.eval_round, "eval_step": self.eval_step,
            "learner": self.learner_kind, "custom_network": self.custom_network,
            "learners": {name: lr.state() for name, lr in self.learners.items()},
            **self.rngs.state(), "env_rng": self.env.sim.rng.bit_generator.state,
            **self.schedule.state(), **self.metrics.state(), **self.best.state(), **episodes,
            "games": {**episodes["games"], **self.games.state(), "obs": self.obs},
            "pending": self.pending.state(),
        }

    def load_state(self, st: dict[str, Any]) -> None:
        """Continue from `state()`'s output (checked by checkpoint.load_checkpoint); the worlds are rebuilt
        by replaying their games."""
        load_shared_state(self, self.learners, st)
        self.games.load_state(st["games"])
        self.games.replay_into(self.env.sim, self.episodes.lengths)
        self.env.sim.rng.bit_generator.state = st["env_rng"]
        obs = self.env.sim.observe(RED)
        if not np.array_equal(obs, st["games"]["obs"]):
            raise RuntimeError("restoring the checkpoint's games did not reproduce their observations: it was "
                               "written with another simulator, or edited")
        self.obs = obs
        self.acting = self.may_act()
        self.pending.load_state(st["pending"])

    def renumber_games(self, first_free: int) -> None:
        """After a restore into the checkpoint's own run: the games go on under new episode ids
        (EpisodeLog.renumber)."""
        self.episodes.renumber(first_free)

    def figures(self) -> dict[str, Any]:
        """What the progress bar shows."""
        return {"step": self.step, "steps": self.cfg.steps, "epsilon": self.epsilon(),
                "loss": self.metrics.last_loss,
                "win_rate": None if self.last_eval is None else self.last_eval.win_rate}

    def close(self) -> None:
        self.env.close()
        if self._eval_env is not None:
            self._eval_env.close()
        if self._eval_trace is not None:
            self._eval_trace.close()
