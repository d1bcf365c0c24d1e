"""Makes docs/images/env-frame.png and docs/images/env-game.gif: the frames `render_mode="rgb_array"`
returns, from a real game of a 3v3 advanced scenario (two hits to kill, so the health bars show): red
plays random allowed actions, blue the scripted opponent, seed 7.

    python docs/images/env_frames.py
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from gymnasium.wrappers import RenderCollection
from PIL import Image

from tracelab.envs.gym_env import GridWarEnv
from tracelab.game.scenario import Scenario

OUT = Path(__file__).parent
SCENARIO = Scenario(name="advanced3v3", width=9, height=9, red_base=(8, 0), blue_base=(0, 8),
                    mountains=((3, 4), (4, 4), (5, 4), (4, 3), (4, 5)), agents_per_team=3,
                    red_starts=((8, 0), (7, 0), (8, 1)), blue_starts=((0, 8), (1, 8), (0, 7)),
                    advanced=True, health=2.0, damage=1.0)


def main() -> None:
    env = RenderCollection(GridWarEnv(SCENARIO, backend="reference", render_mode="rgb_array"))
    rng = np.random.default_rng(7)
    _, info = env.reset(seed=7)
    picked = None
    while True:
        action = [rng.choice(np.flatnonzero(m)) for m in info["action_mask"]]
        _, _, terminated, truncated, info = env.step(action)
        state = env.unwrapped.sim.state
        hurt = (state.health[0] < SCENARIO.health).any() & state.alive[0].any()
        if picked is None and hurt and (state.bullet_dir[0] >= 0).any():
            picked = env.unwrapped.render()  # the first frame with a wound and a bullet in flight
        if terminated or truncated:
            break
    frames = env.render()
    Image.fromarray(picked if picked is not None else frames[-1]).save(OUT / "env-frame.png")
    images = [Image.fromarray(f) for f in frames]
    images[0].save(OUT / "env-game.gif", save_all=True, append_images=images[1:], duration=250, loop=0)
    print(f"{len(frames)} frames of {frames[0].shape}: {OUT / 'env-frame.png'}, {OUT / 'env-game.gif'}")


if __name__ == "__main__":
    main()
