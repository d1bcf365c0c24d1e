"""The training loop: ε-greedy red agents in the batched env, transitions into replay, one update per
world-step, target copies, live logging into a trace-store run, evaluations, checkpoints.

A training step is one world-step (one env transition of one world); with `envs` worlds one pass of the
loop makes `envs` steps and `envs * updates_per_step` updates per network. Everything that decides what
happens next (networks, Adam, buffers, the three generators, the worlds' games, the open transitions,
the logging accumulators) is in the checkpoint, so a resumed run continues exactly as an uninterrupted
one would (tests/test_train.py)."""
from __future__ import annotations

import time
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.envs.common import ActionMasker
from tracelab.envs.tracer import outcome_name
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.observe import obs_size
from tracelab.game.opponent import scripted_actions
from tracelab.game.scenario import NOTHING, RED, Scenario
from tracelab.store.writer import TraceWriter
from tracelab.train.config import TrainConfig
from tracelab.train.evaluate import EvalResult, EvalTrace, evaluate
from tracelab.train.dqn import DQN, make_q_network
from tracelab.train.learner import DQNLearner
from tracelab.train.learner_protocol import Learner
from tracelab.train.network import Shape
from tracelab.train.policy import BEST_POLICY_DIR, Policy, may_act, save_policy
from tracelab.train.qnet import NetSpec, NumpyQ, QFunction, TorchQ
from tracelab.train.replay import ReplayBuffer
from tracelab.train.tensorboard import MetricSink
from tracelab.train.transitions import PendingTransitions

Progress = Callable[[dict[str, Any]], None]
NetworkFactory = Callable[[int, int], torch.nn.Module]  # (observation size, actions) -> a Q-network


def network_groups(scenario: Scenario, split: bool) -> dict[str, list[int]]:
    """Network name -> red agents it plays: one shared network, or (split) one for the fast and one for
    the slow agents."""
    n = scenario.agents_per_team
    if not split:
        return {"shared": list(range(n))}
    slow = scenario.slow_mask[RED]
    groups = {"fast": [j for j in range(n) if not slow[j]], "slow": [j for j in range(n) if slow[j]]}
    return {k: v for k, v in groups.items() if v}


def training_net(cfg: TrainConfig, scenario: Scenario) -> NetSpec:
    """The networks' architecture: the observation (stacked in the non-Markov setup), hidden layers, actions."""
    return NetSpec(obs_size(scenario, cfg.non_markov), cfg.hidden_sizes, scenario.n_actions, cfg.dueling)


def make_learner(kind: str, net: NetSpec, cfg: TrainConfig, generator: torch.Generator,
                 network: NetworkFactory | None = None, learner_class: type[DQN] = DQN) -> Learner:
    """The fused learner for `net` (one tanh layer), or the readable one (`learner_class`: DQN or a
    subclass) on `network`'s module (default: the module `net` describes, drawn from `generator`)."""
    if kind == "fused":
        return DQNLearner(Shape(net.inputs, net.hidden[0], net.actions), lr=cfg.lr, batch=cfg.batch,
                          buffer=cfg.buffer, generator=generator, masked=cfg.mask)
    module = network(net.inputs, net.actions) if network is not None else \
        make_q_network(net.inputs, net.hidden, net.actions, net.dueling, generator)
    return learner_class(module, ReplayBuffer(cfg.buffer, net.inputs, net.actions, cfg.batch, cfg.mask),
                         lr=cfg.lr, double_dqn=cfg.double_dqn)


def acting_q(learner: Learner, net: NetSpec | None) -> QFunction:
    """Greedy acting's Q-values from the learner's live online weights: in numpy for a described network,
    through torch for a custom module (net None)."""
    if net is None:
        return TorchQ(learner.q_network)  # type: ignore[attr-defined]  # only the readable learner takes one
    return NumpyQ(net, {k: v.numpy() for k, v in learner.online_weights().items()})


def eval_seed(seed: int, round_no: int) -> int:
    return int(np.random.SeedSequence([seed, 1, round_no]).generate_state(1)[0])


def _agent_rewards(info: dict, done: np.ndarray) -> np.ndarray:
    """Each red agent's reward of the step, [W, N]. Worlds that ended were reset within the step (SAME_STEP
    autoreset), so their top-level info is the new episode's (zeros): their terminal step's rewards, the
    win or loss term included, are in final_info."""
    if not done.any():
        return info["agent_reward"]
    return np.where(done[:, None], info["final_info"]["agent_reward"], info["agent_reward"])


def learn_pass(tr: Any, learners: Collection[Learner]) -> None:
    """After a pass of the loop: `worlds * updates_per_step` updates per learner once warm-up is over and
    every buffer holds a minibatch (the fraction carried over in `tr.update_credit`), and the target
    copies every `target_every` steps. `tr`: a trainer (GridWar's, or env_trainer's) with cfg, step,
    worlds, rng, update_credit and synced_block."""
    cfg = tr.cfg
    if tr.step < cfg.warmup or any(lr.buffer.size < cfg.batch for lr in learners):
        return
    tr.update_credit += tr.worlds * cfg.updates_per_step
    k = int(tr.update_credit)
    tr.update_credit -= k
    for learner in learners:
        for _ in range(k):
            learner.update(tr.rng)
    block = tr.step // cfg.target_every
    if block > tr.synced_block:
        for learner in learners:
            learner.sync_target()
        tr.synced_block = block


def close_log(tr: Any, m: dict[str, float], now: float, updates: int) -> dict[str, float]:
    """What every log of a trainer adds to its figures `m` (the mean training return since the last log,
    env steps and updates per second), then its episodes and metric rows written; returns `m`."""
    t0, step0, upd0 = tr._rate_mark
    if tr.returns_since_log:
        m["train_return"] = float(np.mean(tr.returns_since_log))
        tr.returns_since_log = []
    dt = max(now - t0, 1e-9)
    m["env_steps_per_s"] = (tr.step - step0) / dt
    m["updates_per_s"] = (updates - upd0) / dt
    tr._rate_mark = (now, tr.step, updates)
    tr.logged_step = tr.step
    tr._flush_episodes()
    tr.write_metrics(m)
    return m


def write_metric_rows(tr: Any, values: dict[str, float]) -> None:
    """Metric rows at the trainer's current step: into its run (`tr.writer`), and into every other sink."""
    if tr.writer is not None:
        tr.writer.write_metrics(tr.step, values)
    for sink in tr.metric_sinks:
        sink.write(tr.step, values)
        sink.flush()


class Trainer:
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
        self.metric_sinks = list(metric_sinks)  # besides the run: e.g. TensorBoard (train --tensorboard)
        self.stack = cfg.non_markov
        w, n = cfg.envs, scenario.agents_per_team
        self.worlds, self.agents = w, n
        self.rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0]))  # exploration, sampling
        self.torch_gen = torch.Generator().manual_seed(cfg.seed)                 # network initialisation
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
            name: make_learner(self.learner_kind, self.net, cfg, self.torch_gen, network, learner_class or DQN)
            for name in self.groups}
        owner = {j: i for i, agents in enumerate(self.groups.values()) for j in agents}
        described = None if self.custom_network else self.net
        self.policy = Policy(scenario, [acting_q(lr, described) for lr in self.learners.values()],
                             [owner[j] for j in range(n)], self.stack, cfg.mask)
        self.pending = PendingTransitions(w, n, self.net.inputs, cfg.gamma)
        self.ids = np.asarray(scenario.action_ids, np.int64)
        self.nothing = scenario.action_ids.index(NOTHING)
        self.action_index = np.zeros(NOTHING + 1, np.int64)  # spec action id -> index into action_ids
        self.action_index[self.ids] = np.arange(len(self.ids))
        # the games in progress, for logging and for replaying them when a checkpoint is restored
        self.history = np.zeros((w, scenario.max_steps, 2, n), np.int16)  # spec ids: red, blue per step
        self.ep_len = np.zeros(w, np.int64)
        self.ep_return = np.zeros(w)
        self.ep_id = np.zeros(w, np.int64)
        self.ep_start = np.zeros(w, np.int64)  # training step at which each world's episode began
        self._logging_episodes = False          # episode begins are written once train() starts
        self._begun: list[dict[str, Any]] = []  # episode rows not yet handed to the writer
        self._ended: list[dict[str, Any]] = []
        self._continues: dict[int, int] = {}    # a game's new episode id -> the one it had (same-run resume)
        self.next_episode = 0
        self.step = 0
        self.update_credit = 0.0
        self.synced_block = 0
        self.eval_round = 0
        self.returns_since_log: list[float] = []
        self.last_eval: EvalResult | None = None
        self.logged_step = self.eval_step = -1
        self.best_eval: tuple[float, int] | None = None  # (method's win rate, step) of the best evaluation
        self.best_weights: dict[str, dict[str, torch.Tensor]] = {}  # its online networks' state dicts
        self.last_loss: float | None = None
        self.stop_requested = False
        self._eval_env: GridWarVectorEnv | None = None
        self._masks: np.ndarray | None = None  # the shield's mask of the current state (--mask), from the step
        self._eval_trace: EvalTrace | None = None
        self.obs, _ = self.env.reset(seed=int(np.random.SeedSequence([cfg.seed, 2]).generate_state(1)[0]))
        self.acting = self.may_act()
        self._begin_episodes(np.arange(w))
        self._rate_mark = (time.perf_counter(), 0, 0)

    # ---- episodes ----
    def new_episode_id(self) -> int:
        ep = self.next_episode
        self.next_episode += 1
        return ep

    def _begin_episodes(self, worlds: np.ndarray) -> None:
        for w in worlds.tolist():
            self.ep_id[w] = self.new_episode_id()
        self.ep_start[worlds] = self.step
        self.ep_len[worlds] = 0
        self.ep_return[worlds] = 0.0
        if self._logging_episodes:
            self._write_begins(worlds)

    def _write_begins(self, worlds: np.ndarray) -> None:
        if self.writer is None:
            return
        for w in worlds.tolist():
            info = {"kind": "train", "train_step": int(self.ep_start[w])}
            if self.ep_len[w]:
                info["resumed_at"] = self.step  # begun in the run this one resumes
                if int(self.ep_id[w]) in self._continues:
                    info["continues"] = self._continues[int(self.ep_id[w])]
            self._begun.append({"episode": int(self.ep_id[w]), "world": w, "t_start": 0, "info": info})

    def renumber_games(self, first_free: int) -> None:
        """After a restore into the run the checkpoint came from: that run already holds the games in
        progress (ended 'aborted' at the stop) and, after a crash, episodes begun past the checkpoint. The
        games go on under new ids from `first_free` on; the begin info of one already under way names the
        id it continues."""
        self.next_episode = max(self.next_episode, first_free)
        for w in range(self.worlds):
            old = int(self.ep_id[w])
            self.ep_id[w] = self.new_episode_id()
            self._continues[int(self.ep_id[w])] = old

    def _flush_episodes(self) -> None:
        """Hand the episode rows gathered since the last call to the writer, one table each (per-episode
        calls cost more than a pass of the loop)."""
        if self.writer is not None and (self._begun or self._ended):
            self.writer.begin_episodes(self._begun)
            self.writer.end_episodes(self._ended)
        self._begun, self._ended = [], []

    def _end_open_episodes(self) -> None:
        """The games still running when training stops end as 'aborted' (a resumed run begins them again)."""
        if self.writer is None or not self._logging_episodes:
            return
        self._ended += [{"episode": int(self.ep_id[w]), "steps": int(self.ep_len[w]), "outcome": "aborted",
                         "reward": float(self.ep_return[w])} for w in range(self.worlds)]
        self._flush_episodes()
        self._logging_episodes = False

    def _end_episodes(self, worlds: np.ndarray, final: dict[str, Any], truncated: np.ndarray) -> None:
        for w in worlds.tolist():
            self.returns_since_log.append(float(self.ep_return[w]))
            if self.writer is not None:
                self._ended.append({"episode": int(self.ep_id[w]), "steps": int(self.ep_len[w]),
                                    "outcome": outcome_name(final["winner"][w], bool(truncated[w])),
                                    "reward": float(self.ep_return[w])})

    # ---- one pass: every world makes one step ----
    def epsilon(self) -> float:
        return 1.0 if self.step < self.cfg.warmup else self.cfg.epsilon(self.step)

    def _choose(self, masks: np.ndarray | None) -> np.ndarray:
        w, n, a = self.worlds, self.agents, self.net.actions
        explore = self.rng.random((w, n)) < self.epsilon()
        if masks is None:
            random = self.rng.integers(0, a, (w, n))
        else:  # uniform among the allowed actions
            random = np.argmax(self.rng.random((w, n, a)) * masks, axis=2)
        if self.cfg.explore_scripted > 0:
            random = self._scripted_exploration(random, masks)
        greedy_rows = self.acting & ~explore
        actions = random
        if greedy_rows.any():
            actions = np.where(greedy_rows, self.policy.act(self.obs, greedy_rows, masks), random)
        return np.where(self.acting, actions, self.nothing)

    def _scripted_exploration(self, random: np.ndarray, masks: np.ndarray | None) -> np.ndarray:
        """--explore-scripted: a share of the exploring actions comes from the scripted base policy played for
        red, always towards blue's base where it can (the opponent's policy with p = 1, drawn from the
        exploration generator, so a resumed run draws the same). With --mask a forbidden scripted action
        (its random fallback) keeps the uniform allowed one."""
        s = self.env.sim.state
        spec = scripted_actions(s.pos, s.alive, s.ammo, "red", self.scenario, self.rng, 1.0)
        scripted = self.action_index[spec]
        take = self.rng.random(random.shape) < self.cfg.explore_scripted
        if masks is not None:
            take &= np.take_along_axis(masks, scripted[..., None], axis=2)[..., 0].astype(bool)
        return np.where(take, scripted, random)

    def _views(self, team_obs: np.ndarray) -> list[np.ndarray]:
        return [self.policy.agent_obs(team_obs, j) for j in range(self.agents)]

    def env_step(self) -> None:
        cfg, w, n = self.cfg, self.worlds, self.agents
        masks = None
        if cfg.mask:  # the shield's mask of this state: read after the previous step, or now
            masks = self._masks if self._masks is not None else self.masker.for_sim(self.env.sim, RED)
        actions = self._choose(masks)
        self.pending.start(self.acting, self._views(self.obs), actions)
        obs, reward, terminated, truncated, info = self.env.step(actions[:, 0] if n == 1 else actions)
        rows = np.arange(w)
        self.history[rows, self.ep_len, 0] = self.ids[actions]
        # (-1 in worlds that ended: their history is dropped with the episode anyway)
        self.history[rows, self.ep_len, 1] = info["opponent_actions"].reshape(w, n)
        self.ep_len += 1
        self.ep_return += reward
        done = terminated | truncated
        self.pending.earn((reward[:, None] if n == 1 else _agent_rewards(info, done)) * cfg.reward_scale)
        true_next = obs
        if done.any():
            true_next = obs.copy()
            true_next[done] = info["final_obs"][done]
        acting_next = self.may_act()
        dead = true_next[:, 0:2 * n:2] < 0  # an agent's own x is -1 once it is dead
        out = self.pending.close(done[:, None] | dead | acting_next, terminated[:, None] | dead)
        # s' mask, and the next act's: the env computed it for its info (a reset world's is its new start's)
        self._masks = info["action_mask"].reshape(w, n, -1) if cfg.mask else None
        if len(out["action"]):
            if cfg.mask:  # what the shield allows in s' bounds the target's max (replay.py)
                allowed = self._masks[out["world"], out["agent"]].astype(bool)
                # a world that ended has been reset: its next state's mask is gone; a terminated
                # transition has no bootstrap, a truncated one takes the max over all actions
                allowed[done[out["world"]]] = True
                out["next_allowed"] = allowed
            self._store(out, true_next)
        self.obs, self.acting = obs, acting_next
        self.step += w
        if done.any():
            ended = np.flatnonzero(done)
            self._end_episodes(ended, info["final_info"], truncated)
            self._begin_episodes(ended)

    def _store(self, out: dict[str, np.ndarray], true_next: np.ndarray) -> None:
        """Closed transitions into their network's buffer, with next_obs in the agent's own view."""
        allowed = out.get("next_allowed")
        if self.agents == 1:
            self.learners["shared"].buffer.add(out["obs"], out["action"], out["reward"], true_next[out["world"]],
                                               out["discount"], allowed)
            return
        next_obs = np.empty_like(out["obs"])
        for j in range(self.agents):
            rows = out["agent"] == j
            next_obs[rows] = self.policy.agent_obs(true_next[out["world"][rows]], j)
        for name, agents in self.groups.items():
            sel = np.isin(out["agent"], agents)
            self.learners[name].buffer.add(out["obs"][sel], out["action"][sel], out["reward"][sel], next_obs[sel],
                                           out["discount"][sel], None if allowed is None else allowed[sel])

    def learn(self) -> None:
        learn_pass(self, self.learners.values())

    # ---- logging, evaluation, checkpoints ----
    def _crossed(self, every: int, before: int) -> bool:
        return every > 0 and self.step // every > before // every

    def log_metrics(self) -> dict[str, float]:
        now = time.perf_counter()
        updates = sum(lr.updates for lr in self.learners.values())
        m: dict[str, float] = {"epsilon": self.epsilon()}
        losses = {name: lr.take_loss() for name, lr in self.learners.items()}
        known = [v for v in losses.values() if v is not None]
        if known:
            m["loss"] = float(np.mean(known))
            self.last_loss = m["loss"]
            if len(losses) > 1:
                m.update({f"loss/{k}": v for k, v in losses.items() if v is not None})
        qs = [q for q in (lr.q_max_mean() for lr in self.learners.values()) if q is not None]
        if qs:
            m["q_max_mean"] = float(np.mean(qs)) / self.cfg.reward_scale  # in the game's reward units
        return close_log(self, m, now, updates)

    def write_metrics(self, values: dict[str, float]) -> None:
        write_metric_rows(self, values)

    def run_eval(self) -> EvalResult:
        cfg = self.cfg
        if self._eval_env is None:
            self._eval_env = GridWarVectorEnv(min(cfg.eval_envs, cfg.eval_games), self.scenario,
                                              backend=cfg.backend, stack_previous=self.stack,
                                              opponent_p=cfg.eval_p, kernel=cfg.kernel, copy=False)
        traced = min(cfg.trace_eval_games, cfg.eval_games) if self.writer is not None else 0
        if traced and self._eval_trace is None:
            self._eval_trace = EvalTrace(self.writer, self.scenario, cfg.backend, self.stack, traced,
                                         cfg.eval_p, self.new_episode_id, cfg.kernel)
        info = {"kind": "eval", "train_step": self.step, "eval_round": self.eval_round, "opponent_p": cfg.eval_p}
        result = evaluate(self.policy, self.scenario, games=cfg.eval_games, backend=cfg.backend,
                          seed=eval_seed(cfg.seed, self.eval_round), opponent_p=cfg.eval_p,
                          stack_previous=self.stack, trace=self._eval_trace if traced else None,
                          trace_info=info, env=self._eval_env)
        self.write_metrics(result.metrics())
        self.eval_round += 1
        self.last_eval, self.eval_step = result, self.step
        self._keep_if_best(result)
        return result

    def may_act(self) -> np.ndarray:
        """Which red agents decide this step (see policy.may_act and --slow-every-step)."""
        return may_act(self.scenario, self.env.sim.state, self.cfg.slow_every_step)

    def _keep_if_best(self, result: EvalResult) -> None:
        """DQN's greedy policy can get worse late in training (the last, low-ε stretch forgets losing
        games); the run keeps the policy of its best evaluation (the method's win rate against --eval-p,
        the earliest of equals) in RUN/policy-best/, beside the final one in RUN/policy/."""
        if self.best_eval is not None and result.method_win_rate <= self.best_eval[0]:
            return
        self.best_eval = (result.method_win_rate, self.step)
        self.best_weights = {name: {k: v.clone() for k, v in lr.online_weights().items()}
                             for name, lr in self.learners.items()}
        self.write_best_policy()

    def write_best_policy(self) -> None:
        """RUN/policy-best/ from the kept parameters (also after --resume into a new run)."""
        if self.run_dir is None or self.best_eval is None:
            return
        value, step = self.best_eval
        save_policy(self.run_dir / BEST_POLICY_DIR, self.scenario, self.best_weights, self.groups,
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

    # ---- the loop ----
    def train(self, stop_at: int | None = None) -> str:
        """Train until cfg.steps, or until stop_requested (Ctrl-C) or step `stop_at` (as an interruption
        there would); returns "finished" or "interrupted"."""
        from tracelab.train.checkpoint import save_checkpoint
        cfg = self.cfg
        last_progress = 0.0
        if not self._logging_episodes:
            self._logging_episodes = True
            self._write_begins(np.arange(self.worlds))
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
                save_checkpoint(self, self.run_dir)
            if self.progress is not None and time.monotonic() - last_progress > 0.2:
                last_progress = time.monotonic()
                self.progress(self.figures())
        status = "interrupted" if self.step < cfg.steps else "finished"
        if status == "finished":  # the final figures, unless the last pass just wrote them
            if self.logged_step != self.step:
                self.log_metrics()
            if self.eval_step != self.step:
                self.run_eval()
        self._end_open_episodes()
        if self.run_dir is not None:
            save_checkpoint(self, self.run_dir)
            self.save_policy(self.run_dir / "policy")
        if self.progress is not None:
            self.progress(self.figures())
        return status

    def figures(self) -> dict[str, Any]:
        """What the progress bar shows."""
        return {"step": self.step, "steps": self.cfg.steps, "epsilon": self.epsilon(), "loss": self.last_loss,
                "win_rate": None if self.last_eval is None else self.last_eval.win_rate}

    def close(self) -> None:
        self.env.close()
        if self._eval_env is not None:
            self._eval_env.close()
        if self._eval_trace is not None:
            self._eval_trace.close()
