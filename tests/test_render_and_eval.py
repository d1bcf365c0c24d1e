"""What a user reaches for (issue 27 §10, §3): the envs' rgb_array frames (through gymnasium's own
wrappers, into a GIF; GridWar's drawn from its spec's [board]), `eval`'s 95% intervals and progress bar,
and the experiment plots' seed mean and band."""
from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import RenderCollection

import tracelab.envs  # noqa: F401  (registers the env ids)
from tracelab.cli import main
from tracelab.envs.declared.render import CELL
from tracelab.train.experiments.stats import wilson

from rulesim_policies import RULESIM_POLICY as SAMPLE_POLICY
from test_progress import run_on_a_terminal


def _play(env: gym.Env, seed: int, steps: int) -> None:
    _, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        mask = info.get("action_mask", np.ones(env.action_space.n))
        _, _, term, trunc, info = env.step(int(rng.choice(np.flatnonzero(mask))))
        if term or trunc:
            break


def test_render_collection_gathers_rgb_frames_of_the_board():
    env = RenderCollection(gym.make("tracelab/GridWar-base-v0", render_mode="rgb_array"))
    assert "rgb_array" in env.metadata["render_modes"] and env.metadata["render_fps"] > 0
    _play(env, seed=0, steps=6)
    frames = env.render()
    assert len(frames) >= 2
    for f in frames:
        assert f.shape == (8 * CELL, 8 * CELL, 3) and f.dtype == np.uint8
    env.close()


def test_check_env_passes_with_rgb_array_and_frames_are_deterministic():
    env = gym.make("tracelab/GridWar-advanced-v0", render_mode="rgb_array")
    check_env(env.unwrapped)
    a = gym.make("tracelab/GridWar-advanced-v0", render_mode="rgb_array")
    b = gym.make("tracelab/GridWar-advanced-v0", render_mode="rgb_array")
    _play(a, 4, 10)
    _play(b, 4, 10)
    assert a.render().tobytes() == b.render().tobytes()


def test_frames_make_a_gif_and_record_video_when_moviepy_is_there(tmp_path):
    """A world whose board marks its agent (FrozenLake's `at`): frames that change make an animated GIF.
    (GridWar's board draws no agents yet: its frames are all alike, docs/envs.md.)"""
    from PIL import Image
    env = RenderCollection(gym.make("tracelab/FrozenLake-v1", render_mode="rgb_array", is_slippery=False))
    _play(env, 1, 8)
    frames = [Image.fromarray(f) for f in env.render()]
    frames[0].save(tmp_path / "game.gif", save_all=True, append_images=frames[1:], duration=250, loop=0)
    with Image.open(tmp_path / "game.gif") as gif:
        assert gif.n_frames >= 2 and gif.size == (frames[0].width, frames[0].height)
    try:
        import moviepy  # noqa: F401  (gymnasium's video writer, not a tracelab dependency)
    except ImportError:
        return
    from gymnasium.wrappers import RecordVideo
    video = RecordVideo(gym.make("tracelab/FrozenLake-v1", render_mode="rgb_array", is_slippery=False),
                        str(tmp_path / "videos"), episode_trigger=lambda e: True, disable_logger=True)
    _play(video, 2, 8)
    video.close()
    assert list((tmp_path / "videos").glob("*.mp4"))


def test_eval_prints_and_writes_95_percent_intervals(capsys):
    assert main(["eval", str(SAMPLE_POLICY), "--games", "9", "--envs", "4", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    wins = int(figures["wins"])
    low, high = figures["method_win_rate_ci95"]
    assert (low, high) == pytest.approx(list(wilson(wins, 9))) and low < wins / 9 <= high
    assert figures["mean_return_ci95"][0] <= figures["mean_return"] <= figures["mean_return_ci95"][1]
    assert main(["eval", str(SAMPLE_POLICY), "--games", "9", "--envs", "4"]) == 0
    out = capsys.readouterr().out
    # the same games: the table shows the JSON's win rate and its Wilson interval
    assert f"win rate        {100 * wins / 9:.1f}% [{100 * low:.1f}%, {100 * high:.1f}%]" in out


def test_eval_on_a_terminal_shows_progress():
    code, text = run_on_a_terminal(["eval", str(SAMPLE_POLICY), "--games", "60", "--envs", "2"], columns=160)
    assert code == 0, text
    assert "evaluating on base" in text and "games/s" in text and "win rate" in text


def test_learning_curves_draw_the_seed_mean_and_a_band(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from tracelab.train.experiments.plots import draw_learning_curves, learning_curves, seed_mean_band
    steps = np.array([1000, 2000, 3000])
    seeds = [(0, steps, np.array([0.1, 0.2, 0.3])), (1, steps, np.array([0.3, 0.4, 0.5])),
             (2, steps[:2], np.array([0.2, 0.3]))]  # a seed cut short: the mean stops where it stops
    at, mean, low, high = seed_mean_band(seeds)
    assert list(at) == [1000, 2000] and mean == pytest.approx([0.2, 0.3])
    assert (low < mean).all() and (high > mean).all()
    arms = [{"label": "arm", "published": None, "seeds": seeds}]
    fig, ax = plt.subplots()
    draw_learning_curves(ax, arms, ylabel="win rate", title="t", percent=True)
    labels = [line.get_label() for line in ax.get_lines()]
    assert "arm, mean of 3 seeds" in labels and len(ax.collections) == 1  # the band
    band = ax.collections[0].get_paths()[0].vertices
    assert band[:, 1].min() >= 0.0 and band[:, 1].max() <= 100.0  # clipped to rates
    plt.close(fig)
    assert learning_curves(tmp_path / "w.png", arms, metric="m", ylabel="y", title="t", percent=True).exists()
