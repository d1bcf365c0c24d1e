"""Stable-Baselines3's PPO on a tracelab env, logged live into a tracelab run (docs/training.md, "Training
with Stable-Baselines3"). Needs the sb3 extra: pip install 'tracelab[sb3]'.

    python examples/sb3_ppo.py --env tracelab/GridWar-base-v0 --steps 100000 --run runs/ppo-base
    tracelab tui runs/ppo-base          # while it trains: key 6, the Training view

Then `tracelab why runs/ppo-base ATOM -e EPISODE` on an evaluation game (kind 'eval' in the episodes view)
and `tracelab replay runs/ppo-base --episode EPISODE`."""
from __future__ import annotations

import argparse

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecNormalize

from tracelab.train.sb3 import TracelabCallback, make_vec_env


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="tracelab/GridWar-base-v0",
                   help="a GridWar id, a declared env's id (tracelab/FrozenLake-v1) or a spec file")
    p.add_argument("--run", required=True, help="a new run directory")
    p.add_argument("--steps", type=int, default=100_000)
    p.add_argument("--n-envs", type=int, default=8)
    p.add_argument("--n-steps", type=int, default=256, help="PPO's rollout length per env")
    p.add_argument("--eval-every", type=int, default=10_000)
    p.add_argument("--eval-games", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--normalize-reward", action="store_true",
                   help="train on SB3's VecNormalize'd rewards (GridWar's are in the hundreds); the run's returns "
                        "stay the env's own")
    args = p.parse_args()

    torch.set_num_threads(1)  # a small MLP: one thread is fastest, and the machine stays usable
    env = make_vec_env(args.env, n_envs=args.n_envs, seed=args.seed)
    if args.normalize_reward:
        env = VecNormalize(env, norm_obs=False, norm_reward=True)
    model = PPO("MlpPolicy", env, n_steps=args.n_steps, batch_size=256, seed=args.seed, device="cpu")
    with TracelabCallback(args.run, args.env, eval_every=args.eval_every, eval_games=args.eval_games,
                          seed=args.seed) as callback:
        model.learn(args.steps, callback=callback)
    print(f"{args.run}: {callback.run.last_eval}")


if __name__ == "__main__":
    main()
