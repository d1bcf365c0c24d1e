"""The tiny game and settings the training tests run on (tests/test_train.py, tests/test_strangers_train.py),
and reading a run and stopping a training the way a user does (tests/test_train_env_resume.py)."""
from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

from patience import PATIENCE, wait_until
from store_helpers import run_rows  # noqa: F401 - re-exported for the training tests

from tracelab.envs.declared.env_source import EnvSource
from tracelab.game.scenario import Rewards, Scenario

# A 4x4 walk: red starts on its base (3,0) and wins by reaching blue's (0,3) in 6 moves; blue walks towards
# red's base half the time (p_toward 0.5), so the best policy almost always wins. Small rewards keep Q-values
# small. GridWar's spec plays it as war.toml's map walk4 with these params (WALK_ARGS); WALK is RefSim's
# scenario of it, which tests/test_gridwar_spec.py holds the spec equal to step by step.
WALK = Scenario(name="walk4", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), max_steps=30,
                rewards=Rewards(win=10, loss=-10, valid_action=-0.1, unsafe=-1, invalid=-0.5, hit_opponent=0,
                                got_shot=0))
WALK_ARGS = {"map": "walk4", "max_steps": WALK.max_steps, **asdict(WALK.rewards)}
WALK_ID = "tracelab/GridWar-base-v0"


def walk_source(p_toward: float = 0.5, **params: object) -> EnvSource:
    """The walk as `train --env tracelab/GridWar-base-v0 --env-arg map=walk4 ...` names it."""
    return EnvSource(WALK_ID, {**WALK_ARGS, "p_toward": p_toward, **params})


def walk_argv(p_toward: float = 0.5) -> list[str]:
    """The walk's --env and --env-arg flags (a run of it is resumed naming its env again)."""
    return ["--env", *shlex.split(walk_source(p_toward).describe())]


SMALL = dict(warmup=100, envs=4, batch=32, buffer=2000, target_every=100, log_every=100, eval_every=200,
             eval_games=8, trace_eval_games=2, eval_envs=3, checkpoint_every=200, lr=3e-3,
             reward_scale=1.0)  # the walk's rewards (-1, 10) are near 1 already: seen as they are


def random_env_policy(path: Path, source: EnvSource, seed: int):  # -> (Path, EnvPolicy)
    """A policy of train --env on `source` with seeded random weights (16 hidden units), saved at `path`."""
    import numpy as np
    import torch

    from tracelab.train.env_policy import EnvPolicy, save_env_policy
    from tracelab.train.env_source import probe_env
    from tracelab.train.qnet import NetSpec, NumpyQ
    encoder, n_actions, spec = probe_env(source)
    net = NetSpec(encoder.size, (16,), n_actions)
    rng = np.random.default_rng(seed)
    weights = {k: rng.normal(0, 1, shape).astype(np.float32) for k, shape in net.state_dict_shapes().items()}
    path = save_env_policy(path, source, {k: torch.from_numpy(v) for k, v in weights.items()},
                           net.to_json(), encoder, list(spec.action_names), False, {"run": None, "step": 0})
    return path, EnvPolicy(NumpyQ(net, weights), encoder)


def walk_config(steps: int = 200, seed: int = 1, **options: object):  # -> TrainConfig
    """The TrainConfig of a tiny training of the walk (SMALL, overridden by `options`)."""
    from tracelab.train.config import TrainConfig
    return TrainConfig(steps=steps, seed=seed, **{**SMALL, **options})


def train_walk(cfg, run: Path, stop_at: int | None = None, source: EnvSource | None = None, **kwargs: object) -> int:
    """`tracelab train --env` of the walk (or `source`) into `run` from Python (train_env_into); its exit
    status (130: stopped at `stop_at` as by Ctrl-C)."""
    from tracelab.commands.train import train_env_into
    from tracelab.train.env_source import probe_env
    source = source or walk_source()
    return train_env_into(cfg, source, run, probe_env(source)[0].describe(), stop_at=stop_at, **kwargs)


def walk_trainer(cfg, source: EnvSource | None = None, **kwargs: object):  # -> EnvTrainer
    """An EnvTrainer of the walk (or `source`), not writing a run (close it)."""
    from tracelab.train.env_trainer import EnvTrainer
    return EnvTrainer(cfg, source or walk_source(), **kwargs)


def tiny_training_run(run: Path, steps: int = 200, seed: int = 1, **options: object) -> Path:
    """A finished training run of the walk into `run` (a few seconds): checkpoint, policy, policy-best."""
    assert train_walk(walk_config(steps, seed, **options), run) == 0
    return run


def has_trained(run: Path) -> bool:
    """Whether a training has logged a loss into `run`: it is training, not starting."""
    try:
        return bool(run_rows(run, "SELECT count(*) FROM metrics WHERE name = 'loss'")[0][0])
    except Exception:  # noqa: BLE001 - not created yet, or between flushes
        return False


def training(proc: subprocess.Popen, runs: list[Path]) -> bool:
    """Whether every run in `runs` has logged a loss; fails at once if `proc` (their training) ended."""
    assert proc.poll() is None, f"the training ended first: {proc.stderr.read() if proc.stderr else ''}"
    return all(has_trained(r) for r in runs)


def ctrl_c_once_training(argv: list[str], run: Path) -> tuple[int, str, str]:
    """`tracelab *argv` (a training into `run`) in a subprocess, sent one SIGINT once a `loss` metric is in
    the run; (its exit status, stdout, stderr)."""
    proc = subprocess.Popen([sys.executable, "-m", "tracelab.cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        wait_until(lambda: training(proc, [run]), f"a loss logged into {run}", poll=0.3)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=PATIENCE)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, out, err
