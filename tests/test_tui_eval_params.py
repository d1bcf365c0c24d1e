"""What an evaluation game was played against, as both viewers show it: the world's params that `tracelab eval
--run` and a training's traced evaluations record in its begin info (`{"kind": "eval", "params": {...}}`), for
any world, and an older run's `"opponent_p"` (RuleSim's) as before. The TUI's trace header (textual's pilot)
and the replay's step note (viewers/replay/plots.py) read them from real runs."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

os.environ["TEXTUAL_ANIMATIONS"] = "none"

from rulesim_policies import RULESIM_POLICY  # noqa: E402
from train_helpers import WALK_ARGS, random_env_policy, tiny_training_run  # noqa: E402
from tui_helpers import episodes_ready, loaded, run_app, wait_for  # noqa: E402

from tracelab import RULES_DIR  # noqa: E402
from tracelab.cli import main  # noqa: E402
from tracelab.envs.declared.env_source import EnvSource  # noqa: E402
from tracelab.store import open_run  # noqa: E402
from tracelab.viewers.replay.plots import eval_game_note  # noqa: E402
from tracelab.viewers.tui.trace import TracePane  # noqa: E402


def first_game_header(run: Path) -> str:
    """The trace header of the run's first evaluation game, as the TUI shows it: its first episode's, or the
    one `]` goes to from that training episode."""
    header: list[str] = []

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        await pilot.press("enter")
        pane = app.screen.query_one(TracePane)
        game = pane.query_one("#tr-game")

        async def header_says(*what: str) -> str:
            await wait_for(pilot, lambda: pane.filter is not None and loaded(pane.table) and game.display
                           and any(w in str(game.render()) for w in what))
            return str(game.render())

        if "a training episode" in await header_says("eval game", "a training episode"):
            await pilot.press("right_square_bracket")
        header.append(await header_says("eval game"))
    run_app([run], body, size=(120, 30))
    return header[0]


def begin_infos(run: Path) -> list[dict[str, Any]]:
    con = open_run(run)
    try:
        return [json.loads(b) for (b,) in con.execute("SELECT DISTINCT begin_info FROM episodes").fetchall()]
    finally:
        con.close()


def note_of_first_eval_game(run: Path) -> str | None:
    con = open_run(run)
    try:
        episode = con.execute("SELECT min(episode) FROM episodes WHERE kind = 'eval'").fetchone()[0]
        return eval_game_note(con, episode)
    finally:
        con.close()


def test_an_eval_run_of_a_toy_text_world_shows_its_params(tmp_path: Path) -> None:
    """FrozenLake8x8 on its ice without slips: its games begin with those params (no opponent: not the war
    game's), and both viewers say them; no training places them (no round, no train step)."""
    source = EnvSource("tracelab/FrozenLake8x8-v1", {"is_slippery": False})
    policy, _ = random_env_policy(tmp_path / "policy", source, seed=1)
    run = tmp_path / "lake"
    assert main(["eval", str(policy), "--games", "3", "--seed", "1", "--run", str(run)]) == 0
    assert begin_infos(run) == [{"kind": "eval", "params": {"map_name": "8x8", "is_slippery": False}}]
    header = first_game_header(run)
    assert header.startswith(" eval game 1/3 · is_slippery=false map_name=8x8 · ")
    assert "opponent" not in header and "round" not in header and "train step" not in header
    assert note_of_first_eval_game(run) == r"- an evaluation game, is\_slippery=false map\_name=8x8"


def test_an_eval_run_of_the_war_game_shows_its_opponents_p(tmp_path: Path) -> None:
    """GridWar's earlier policy plays against the method's opponent (p_toward 0.3): the level is one of the
    world's params, shown as the spec names it."""
    run = tmp_path / "war"
    assert main(["eval", str(RULESIM_POLICY), "--games", "2", "--seed", "3", "--run", str(run)]) == 0
    assert " eval game 1/2 · advanced=false p_toward=0.3 · " in first_game_header(run)
    assert note_of_first_eval_game(run) == r"- an evaluation game, advanced=false p\_toward=0.3"


def test_a_trainings_evaluation_games_show_the_params_they_play_fitting_the_header(tmp_path: Path) -> None:
    """train --env records its traced evaluations' params as eval --run does: the walk's many params are cut
    to fit the header's 80 columns, the replay's note has them whole."""
    run = tiny_training_run(tmp_path / "walk")
    header = first_game_header(run)
    game = header.split(" · ]/[")[0]
    assert game.startswith(" eval game 1/2 · round 0 · train step 200 · advanced=false ")
    assert "…" in game and len(game) == 80  # the params take the room the rest leaves
    note = note_of_first_eval_game(run)
    assert note.startswith("- an evaluation game of the training, at train step 200, round 0, advanced=false ")
    assert "p\\_toward=0.5" in note and f"win={WALK_ARGS['win']:g}" in note and "…" not in note


def test_an_older_run_with_opponent_p_still_shows_its_level(tmp_path: Path) -> None:
    """A run whose evaluation games began with `"opponent_p": P` (RuleSim's trainer wrote them so) and no
    params: both viewers show the level as before."""
    from tracelab.envs.declared.gym_env import DeclaredEnv
    from tracelab.envs.declared.play import play_episodes, random_policy
    from tracelab.envs.declared.recording import declared_run_config
    from tracelab.envs.declared.spec import load_spec
    from tracelab.store import TraceWriter

    spec = load_spec(RULES_DIR / "gridworld" / "war.toml", advanced=False)
    run = tmp_path / "old"
    writer = TraceWriter.open(run, {"command": "tracelab train", "scenario": "base", "seed": 0,
                                    "config": declared_run_config(spec)})
    ids = iter(range(10))
    env = DeclaredEnv(spec, trace_writer=writer, trace_episode_ids=lambda: next(ids))
    env.trace_info({"kind": "eval", "train_step": 500, "eval_round": 2, "opponent_p": 0.25})
    play_episodes(env, 1, 0, random_policy(env, 0))
    env.close()
    writer.close()
    assert " eval game 1/1 · round 2 · train step 500 · opponent p=0.25 · " in first_game_header(run)
    assert note_of_first_eval_game(run) == ("- an evaluation game of the training, at train step 500, round 2, "
                                       "opponent p=0.25 (its curves: `tracelab tui RUN`, 6 Training)")


def test_a_strangers_params_are_shown_safely_and_bounded() -> None:
    """A run is anyone's: control characters escaped, a long params cut, JSON that is nested too deep, has a
    number past int's digits or is no object reads as none (then an older run's level, if any)."""
    from tracelab.store.eval_params import MAX_PARAMS_TEXT, eval_params_text
    assert eval_params_text('{"name": "\\u001b[2J", "on": true, "p": 0.1}', None) == "name=\\x1b[2J on=true p=0.1"
    assert len(eval_params_text(json.dumps({"x": "y" * 1000}), None)) == MAX_PARAMS_TEXT
    assert eval_params_text("[" * 100_000 + "]" * 100_000, 0.3) == "opponent p=0.3"
    assert eval_params_text('{"a": ' + "9" * 5000 + "}", None) is None
    assert eval_params_text('"p_toward"', None) is None and eval_params_text("{}", None) is None
