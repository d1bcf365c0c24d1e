"""Stable-Baselines3 trainings logged into a tracelab run, live (docs/training.md, "Training with
Stable-Baselines3"): `TracelabCallback` writes what SB3's logger logs (rollout/ep_rew_mean, train/loss,
time/fps, ...), every training episode, and greedy evaluations every so many steps whose first games are
traced in full, so `tracelab tui RUN`, `tracelab why RUN ...` and `tracelab replay RUN` work on a run
trained by SB3's PPO, A2C, DQN, ... on a rules-declared env (a registered id or a spec file).

    from stable_baselines3 import PPO
    from tracelab.train.sb3 import TracelabCallback, make_vec_env
    model = PPO("MlpPolicy", make_vec_env("tracelab/FrozenLake-v1", n_envs=4), n_steps=256)
    with TracelabCallback("runs/ppo-lake", "tracelab/FrozenLake-v1", eval_every=10_000) as cb:
        model.learn(100_000, callback=cb)

The run's status is tracelab train's: `finished` when learn() reaches its total, `interrupted` when it
stops early (a callback stopped it, or Ctrl-C inside the `with`), `failed` on an error inside the
`with`, `crashed` when the process dies. Needs the `sb3` extra: pip install 'tracelab[sb3]'."""
from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

try:
    from stable_baselines3.common import env_util
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import KVWriter
except ImportError as e:  # pragma: no cover - the message is the point
    raise ImportError("tracelab.train.sb3 needs Stable-Baselines3: pip install 'tracelab[sb3]'") from e

from tracelab.store import layout
from tracelab.envs.declared.env_source import EnvSource
from tracelab.store.agent_rows import LOGITS, PolicyOutput
from tracelab.train.external_eval import EvalSettings
from tracelab.train.external_run import ExternalRun

MODEL_DIR, MODEL_NAME = "sb3", "model.zip"  # the trained model, beside the run's store files (SB3's own format)
MODEL_FILE = f"{MODEL_DIR}/{MODEL_NAME}"
PROGRESS = ("num_timesteps",)  # a model's attributes that count progress, not settings: not in the config


def env_maker(env: str, env_kwargs: Mapping[str, Any] | None = None) -> Callable[[], Any]:
    """What makes one env of `env`: a registered id (gym.make) or a spec file (tracelab.envs.make_env),
    with its keyword arguments, as `train --env` and TracelabCallback take it."""
    return EnvSource.given(str(env), dict(env_kwargs or {})).make


def make_vec_env(env: str, n_envs: int = 1, env_kwargs: Mapping[str, Any] | None = None, **sb3: Any) -> Any:
    """SB3's make_vec_env of `env`, an id or a spec file (SB3's own takes ids only: a path is a `Malformed
    environment ID`); `sb3`: its other arguments (seed, vec_env_cls, ...)."""
    return env_util.make_vec_env(env_maker(env, env_kwargs), n_envs=n_envs, **sb3)


class _RunOutput(KVWriter):
    """An output of SB3's logger: every dump of its values becomes the run's metric rows at that step."""

    def __init__(self, callback: "TracelabCallback") -> None:
        self.callback = callback

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, tuple[str, ...]], step: int = 0) -> None:
        self.callback.log(step, key_values)

    def close(self) -> None:
        pass


class ModelActor:
    """The callback's model as the evaluations' `Act` (its greedy actions), which can also `decide`: the
    actions with the values they were chosen from, recorded into the traced games."""

    def __init__(self, callback: "TracelabCallback") -> None:
        self._callback = callback

    def __call__(self, obs: Any) -> np.ndarray:
        return self._callback.greedy_actions(obs)

    def decide(self, obs: Any) -> tuple[np.ndarray, PolicyOutput | None]:
        return self._callback.greedy_decisions(obs)


class TracelabCallback(BaseCallback):
    def __init__(self, run_dir: str | Path, env_id: str, env_kwargs: Mapping[str, Any] | None = None, *,
                 eval_every: int = 10_000, eval_games: int = 50, trace_eval_games: int = 5, eval_envs: int = 16,
                 eval_p: float = 0.3, seed: int = 0, save_model: bool = True, verbose: int = 0) -> None:
        """`run_dir`: a new run directory; `env_id`, `env_kwargs`: the env the model trains on (a
        declared env's id such as tracelab/FrozenLake-v1, or a spec file), from which the evaluation games
        are made. Every `eval_every` steps (0: only at the end) and at the end, `eval_games` greedy games,
        the first `trace_eval_games` traced into the run (a world with a scripted opponent: against it at
        `eval_p`). `save_model`: the model into RUN/sb3/model.zip at
        the end."""
        super().__init__(verbose)
        self.run_dir = Path(run_dir)
        self.env_id, self.env_kwargs = env_id, dict(env_kwargs or {})
        self.settings = EvalSettings(every=eval_every, games=eval_games, traced=trace_eval_games, envs=eval_envs,
                                     level=eval_p, seed=seed)
        self.save_model = save_model
        self.run: ExternalRun | None = None
        self._output: _RunOutput | None = None
        self._total: int | None = None

    # ---- SB3's hooks ----
    def _on_training_start(self) -> None:
        if self.run is not None:
            raise RuntimeError(f"TracelabCallback: {self.run_dir} already holds this callback's training; "
                               f"give the next learn() a new callback (and run directory)")
        model = self.model
        self.run = ExternalRun(self.run_dir, self.env_id, self.env_kwargs, learner=learner_settings(model),
                               command=f"stable-baselines3 {type(model).__name__} (python: "
                                       f"tracelab.train.sb3.TracelabCallback)",
                               evaluation=self.settings, seed=model.seed)
        self._total = int(self.locals.get("total_timesteps", 0)) or None
        self._output = _RunOutput(self)
        model.logger.output_formats.append(self._output)

    def _on_step(self) -> bool:
        run = self.run
        assert run is not None
        step = self.num_timesteps
        run.steps(step, self.locals["rewards"], self.locals["dones"], self.locals["infos"])
        if run.due(step, step - self.training_env.num_envs):
            run.evaluate(ModelActor(self), step)
        return True

    def _on_training_end(self) -> None:
        run = self.run
        assert run is not None
        step = self.num_timesteps
        finished = self._total is None or step >= self._total
        try:
            if finished and run.eval_step != step:
                run.evaluate(ModelActor(self), step)
            # what SB3 logged after its last dump (PPO's last update: train/...), which it would write at
            # the next rollout's; the return of the episodes since the last row; the episodes
            run.metrics(step, self.model.logger.name_to_value)
            if self.save_model:  # through the store's resolver: never through a link planted in the run
                layout.make_run_dirs(self.run_dir, MODEL_DIR)
                with layout.new_file(layout.run_path(self.run_dir, MODEL_DIR, MODEL_NAME)) as f:
                    self.model.save(f)
        except BaseException:
            self._close("failed")
            raise
        self._close("finished" if finished else "interrupted")

    # ---- the run ----
    def log(self, step: int, values: Mapping[str, Any]) -> None:
        """SB3's logger dumped `values` at `step`."""
        if self.run is not None and not self.run.writer.closed:
            self.run.metrics(step, values)

    def greedy_actions(self, obs: Any) -> np.ndarray:
        """The model's deterministic actions for a batch of raw observations (normalised first when the
        model trains behind a VecNormalize)."""
        actions, _ = self.model.predict(self._normalized(obs), deterministic=True)
        return np.asarray(actions)

    def greedy_decisions(self, obs: Any) -> tuple[np.ndarray, PolicyOutput | None]:
        """greedy_actions and what the model chose them from, for a traced game's decisions: a DQN's
        Q-values; an actor-critic's (PPO, A2C) action logits (normalised log-probabilities, one block per
        sub-action of a MultiDiscrete space) and state value; None for another model."""
        # deferred: torch, loaded by SB3 already; not needed to import this module's names
        import torch
        actions = self.greedy_actions(obs)
        policy = self.model.policy
        tensor, _ = policy.obs_to_tensor(self._normalized(obs))
        with torch.no_grad():
            if hasattr(policy, "q_net"):  # DQN
                return actions, PolicyOutput(policy.q_net(tensor).cpu().numpy().astype(np.float32))
            if hasattr(policy, "get_distribution") and hasattr(policy, "predict_values"):
                dist = policy.get_distribution(tensor).distribution
                logits = torch.cat([d.logits for d in dist], dim=1) if isinstance(dist, list) else \
                    getattr(dist, "logits", None)
                if logits is not None:
                    value = policy.predict_values(tensor).reshape(-1).cpu().numpy()
                    return actions, PolicyOutput(logits.cpu().numpy().astype(np.float32), LOGITS, value)
        return actions, None

    def _normalized(self, obs: Any) -> Any:
        normalize = self.model.get_vec_normalize_env()
        return obs if normalize is None else normalize.normalize_obs(obs)

    def _close(self, status: str) -> None:
        if self._output is not None:
            formats = self.model.logger.output_formats
            if self._output in formats:
                formats.remove(self._output)
            self._output = None
        if self.run is not None:
            self.run.close(status)

    # ---- `with`: a training that raises closes the run as tracelab train's does ----
    def __enter__(self) -> "TracelabCallback":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        # learn()'s end closed the run already unless it raised (or the `with` left before learn() ended)
        status = "failed" if exc_type is not None and not issubclass(exc_type, (KeyboardInterrupt, SystemExit)) \
            else "interrupted"
        if self.run is not None and not self.run.writer.closed:
            self._close(status)


def learner_settings(model: Any) -> dict[str, Any]:
    """The model's class, policy and plain settings (numbers, text, flags), for the run's config."""
    plain = {k: v for k, v in vars(model).items() if not k.startswith("_") and k not in PROGRESS
             and isinstance(v, (int, float, str, bool)) and not isinstance(v, np.generic)}
    return {"library": "stable-baselines3", "algorithm": type(model).__name__,
            "policy": type(model.policy).__name__, **plain}
