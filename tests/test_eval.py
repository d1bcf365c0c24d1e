"""`tracelab eval`: outcome counts on policies whose games are known in advance, the method's counting,
the CLI's table, JSON and traced run, and `tracelab play --policy`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tracelab.cli import main
from tracelab.game.scenario import Scenario
from tracelab.store import open_run
from tracelab.train.evaluate import EvalResult, GameRecord, evaluate
from tracelab.train.env_policy import Policy, save_policy
from tracelab.train.qnet import NetSpec, NumpyQ

# red starts one step below blue's base; blue needs 6 moves to red's base
NEAR = Scenario(name="near", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), red_starts=((0, 2),))
# blue is 14 moves from red's base and the game stops after 10 steps
FAR = Scenario(name="far", width=8, height=8, red_base=(7, 0), blue_base=(0, 7), max_steps=10)
# both start on one cell with shots: each shoots the other point blank at once (blue: scripted)
DUEL = Scenario(name="duel", width=8, height=8, red_base=(7, 0), blue_base=(0, 7), advanced=True,
                red_starts=((3, 3),), blue_starts=((3, 3),))


def constant_weights(scenario: Scenario, action_id: int) -> tuple[NetSpec, dict[str, np.ndarray]]:
    """A network that always prefers one action: zero weights, a bias of 1 on it."""
    net = NetSpec(4 if not scenario.advanced else 7, (8,), scenario.n_actions)
    weights = {k: np.zeros(shape, np.float32) for k, shape in net.state_dict_shapes().items()}
    weights["2.bias"][scenario.action_ids.index(action_id)] = 1.0
    return net, weights


def constant_policy(scenario: Scenario, action_id: int) -> Policy:
    return Policy(scenario, [NumpyQ(*constant_weights(scenario, action_id))], [0], stack_previous=False)


def test_capture_wins_are_wins_both_ways():
    r = evaluate(constant_policy(NEAR, 0), NEAR, games=30, backend="rules", seed=1, opponent_p=0.3,
                 stack_previous=False, envs=7)
    assert (r.games, r.wins, r.losses, r.draws, r.truncated) == (30, 30, 0, 0, 0)
    assert (r.method_wins, r.method_losses, r.method_non_wins) == (30, 0, 0)
    assert r.actions_per_win == 1.0 and r.win_rate == 1.0 and r.mean_return == 250 - 2


def test_truncations_are_their_own_count_and_losses_for_the_method():
    r = evaluate(constant_policy(FAR, 8), FAR, games=12, backend="reference", seed=0, opponent_p=1.0,
                 stack_previous=False, envs=5)
    assert (r.wins, r.losses, r.draws, r.truncated) == (0, 0, 0, 12)
    assert (r.method_wins, r.method_losses, r.method_non_wins) == (0, 12, 0)
    assert r.actions_per_win is None and r.mean_return == -2 * 10


def test_mutual_kills_are_draws_and_method_non_wins():
    from tracelab.game.scenario import SHOOT_RIGHT
    r = evaluate(constant_policy(DUEL, SHOOT_RIGHT), DUEL, games=6, backend="rules", seed=0, opponent_p=0.3,
                 stack_previous=False, envs=3)
    assert (r.wins, r.losses, r.draws, r.truncated) == (0, 0, 6, 0)
    assert (r.method_wins, r.method_losses, r.method_non_wins) == (0, 0, 6)


def test_the_methods_counting_of_elimination_wins_and_long_games():
    games = [GameRecord("win", 12, 240.0, 12, capture=True),      # a win both ways
             GameRecord("win", 9, 600.0, 9, capture=False),       # elimination: the method's non-win
             GameRecord("win", 250, 0.0, 250, capture=True),      # won after the method's cut: its loss
             GameRecord("truncated", 300, -600.0, 300, capture=False),
             GameRecord("draw", 20, 0.0, 20, capture=False),
             GameRecord("loss", 30, -310.0, 30, capture=False)]
    r = EvalResult.of(games)
    assert (r.wins, r.losses, r.draws, r.truncated) == (3, 1, 1, 1)
    assert (r.method_wins, r.method_losses, r.method_non_wins) == (1, 3, 2)
    assert r.actions_per_win == pytest.approx((12 + 9 + 250) / 3) and r.method_actions_per_win == 12
    assert r.metrics()["eval/method_win_rate"] == pytest.approx(1 / 6)


def _saved(tmp_path, scenario: Scenario, action_id: int):
    import torch
    net, weights = constant_weights(scenario, action_id)
    return save_policy(tmp_path / "policy", scenario, {"shared": {k: torch.from_numpy(v) for k, v in weights.items()}},
                       {"shared": [0]}, net.to_json(), False, False, {"run": None, "step": 0})


SAMPLE_POLICY = Path(__file__).resolve().parent.parent / "sample_runs" / "base-train" / "policy"


def test_eval_command_plays_a_one_agent_policy_on_its_spec(capsys):
    """GridWar's trainer's policy evaluated on rules/gridworld/war.toml: the spec's outcomes counted."""
    assert main(["eval", str(SAMPLE_POLICY), "--games", "8", "--envs", "4", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["env"]["name"].endswith("war.toml") and figures["scenario"] == "base"
    assert figures["games"] == 8 == figures["wins"] + figures["losses"] + figures["draws"] + figures["truncated"]
    assert figures["wins"] >= 6  # it wins nearly all its games against the method's opponent (p = 0.3)
    assert main(["eval", str(SAMPLE_POLICY), "--games", "4", "--envs", "2"]) == 0
    assert "win rate" in capsys.readouterr().out


def test_eval_command_traced_run(tmp_path, capsys):
    path = _saved(tmp_path, NEAR, 0)
    run = tmp_path / "evalrun"
    assert main(["eval", str(path), "--games", "5", "--json", "--run", str(run), "--seed", "3"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["games"] == figures["wins"] == figures["method_wins"] == 5 and figures["scenario"] == "near"
    con = open_run(run)
    rows = con.execute("SELECT kind, outcome, steps FROM episodes ORDER BY episode").fetchall()
    moved = con.execute("SELECT count(DISTINCT episode) FROM firings WHERE rule = 'm_go'").fetchone()[0]
    con.close()
    assert rows == [("eval", "win", 1)] * 5 and moved == 5


def test_eval_command_errors_are_one_line(tmp_path, capsys):
    assert main(["eval", str(tmp_path / "nothing-here"), "--games", "3"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error:") and "no policy" in err and "Traceback" not in err
    path = _saved(tmp_path, NEAR, 0)
    assert main(["eval", str(path), "--scenario", "advanced", "--games", "3"]) == 1
    assert "does not match" in capsys.readouterr().err


def test_play_plays_and_traces_a_saved_policy(tmp_path, capsys):
    run = tmp_path / "played"
    assert main(["play", "--policy", str(SAMPLE_POLICY), "--episodes", "3", "--run", str(run)]) == 0
    assert "played 3 episodes of base" in capsys.readouterr().out
    con = open_run(run)
    steps = con.execute("SELECT count(*) FROM steps WHERE agent = 'red-agent-1'").fetchone()[0]
    # each step's decision is the policy's greedy choice among its Q-values
    greedy = con.execute("SELECT count(*) FROM raw.decisions "
                         "WHERE list_position(values, list_max(values)) - 1 = action").fetchone()[0]
    con.close()
    assert steps > 0 and greedy == steps


def test_eval_plays_a_teams_policy_on_its_spec(tmp_path, capsys):
    """A 2v2 policy of GridWar's trainer's format (one network for both agents, always "up"), evaluated
    on war.toml at agents_per_team = 2: every game counted, by the spec's outcomes."""
    from dataclasses import replace

    import torch

    from tracelab.game.scenario import builtin_scenario
    team = replace(builtin_scenario("base"), agents_per_team=2, red_starts=None, blue_starts=None, max_steps=12)
    net = NetSpec(8, (8,), team.n_actions)  # the team's view: 4 numbers an agent
    weights = {k: np.zeros(shape, np.float32) for k, shape in net.state_dict_shapes().items()}
    weights["2.bias"][0] = 1.0
    path = save_policy(tmp_path / "pol", team, {"shared": {k: torch.from_numpy(v) for k, v in weights.items()}},
                       {"shared": [0, 1]}, net.to_json(), False, False, {"run": None, "step": 0})
    assert main(["eval", str(path), "--games", "3", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["env"]["kwargs"]["agents_per_team"] == 2 and figures["games"] == 3
    # walking up from (7, 0) never reaches blue's base: lost to the opponent, or cut at 12 steps
    assert figures["wins"] == 0 and figures["losses"] + figures["truncated"] == 3
