"""What a user reaches for (issue 27 §10, §3): the envs' rgb_array frames (through gymnasium's own
wrappers, into a GIF), `eval`'s 95% intervals and progress bar, and the experiment plots' seed mean and
band."""
from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import RenderCollection

import tracelab.envs.gym_env  # noqa: F401  (registers the env ids)
from tracelab.cli import main
from tracelab.envs.parallel_env import GridWarParallelEnv
from tracelab.envs.render_rgb import AGENT, CELL, MOUNTAIN, BoardPainter
from tracelab.game.scenario import Scenario, builtin_scenario
from tracelab.game.state import GameState

from test_eval import FAR, NEAR, _saved
from test_progress import run_on_a_terminal


def _play(env: gym.Env, seed: int, steps: int) -> None:
    _, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        mask = info["action_mask"]
        _, _, term, trunc, info = env.step(int(rng.choice(np.flatnonzero(mask))))
        if term or trunc:
            break


def test_render_collection_gathers_rgb_frames_that_change_as_agents_move():
    sc = builtin_scenario("base")
    env = RenderCollection(gym.make("tracelab/GridWar-base-v0", render_mode="rgb_array", backend="reference"))
    assert "rgb_array" in env.metadata["render_modes"] and env.metadata["render_fps"] > 0
    _play(env, seed=0, steps=6)
    frames = env.render()
    assert len(frames) >= 2
    for f in frames:
        assert f.shape == (sc.height * CELL, sc.width * CELL, 3) and f.dtype == np.uint8
    assert any(not np.array_equal(a, b) for a, b in zip(frames, frames[1:]))  # agents moved
    env.close()


def test_check_env_passes_with_rgb_array_and_frames_are_deterministic():
    env = gym.make("tracelab/GridWar-advanced-v0", render_mode="rgb_array", backend="reference")
    check_env(env.unwrapped)
    a = gym.make("tracelab/GridWar-advanced-v0", render_mode="rgb_array", backend="reference")
    b = gym.make("tracelab/GridWar-advanced-v0", render_mode="rgb_array", backend="reference")
    _play(a, 4, 10)
    _play(b, 4, 10)
    assert a.render().tobytes() == b.render().tobytes()


def test_a_frame_draws_mountains_and_agents_in_their_cells():
    sc = Scenario(name="pic", width=5, height=4, red_base=(4, 0), blue_base=(0, 3), mountains=((2, 1),),
                  red_starts=((1, 0),))
    frame = BoardPainter(sc)(GameState.initial(sc, 1))
    assert frame.shape == (4 * CELL, 5 * CELL, 3)

    def centre(x: int, y: int) -> tuple[int, ...]:  # the top row of the image is the game's highest y
        return tuple(frame[(sc.height - 1 - y) * CELL + CELL // 2, x * CELL + CELL // 2])
    assert centre(2, 1) == MOUNTAIN
    assert centre(1, 0) == tuple(AGENT[0]) and centre(0, 3) == tuple(AGENT[1])


def test_agents_sharing_a_cell_are_all_drawn():
    sc = Scenario(name="two", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), agents_per_team=2)
    frame = BoardPainter(sc)(GameState.initial(sc, 1))  # both red agents start on red's base
    row, col, q = (sc.height - 1) * CELL, 3 * CELL, CELL // 4
    assert tuple(frame[row + q, col + q]) == tuple(AGENT[0]) == tuple(frame[row + q, col + 3 * q])


def test_frames_make_a_gif_and_record_video_when_moviepy_is_there(tmp_path):
    from PIL import Image
    env = RenderCollection(gym.make("tracelab/GridWar-base-v0", render_mode="rgb_array", backend="reference"))
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
    video = RecordVideo(gym.make("tracelab/GridWar-base-v0", render_mode="rgb_array", backend="reference"),
                        str(tmp_path / "videos"), episode_trigger=lambda e: True, disable_logger=True)
    _play(video, 2, 8)
    video.close()
    assert list((tmp_path / "videos").glob("*.mp4"))


def test_pettingzoo_env_renders_rgb_array():
    env = GridWarParallelEnv("base", backend="reference", render_mode="rgb_array")
    assert "rgb_array" in env.metadata["render_modes"]
    env.reset(seed=0)
    before = env.render()
    env.step({a: 0 for a in env.agents})  # everyone moves up
    after = env.render()
    assert before.shape == after.shape and before.dtype == np.uint8 and not np.array_equal(before, after)


def test_eval_prints_and_writes_95_percent_intervals(tmp_path, capsys):
    path = _saved(tmp_path, NEAR, 0)
    assert main(["eval", str(path), "--games", "9", "--envs", "4"]) == 0
    out = capsys.readouterr().out
    # 9 wins of 9: Wilson's interval is [70.1%, 100%]
    assert "win rate [95% CI]" in out and "100.0% [70.1%, 100.0%]" in out and "mean return [95% CI]" in out
    assert main(["eval", str(path), "--games", "9", "--envs", "4", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["method_win_rate_ci95"] == pytest.approx([0.7008, 1.0], abs=1e-3)
    assert figures["mean_return_ci95"] == pytest.approx([248.0, 248.0])


def test_eval_on_a_terminal_shows_progress(tmp_path):
    path = _saved(tmp_path, FAR, 0)
    code, text = run_on_a_terminal(["eval", str(path), "--games", "60", "--envs", "2", "--backend", "reference"],
                                   columns=160)
    assert code == 0, text
    assert "evaluating on far" in text and "games/s" in text and "win rate 0.0%" in text


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
