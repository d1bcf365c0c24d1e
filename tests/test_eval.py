"""`tracelab eval`: every policy played on its world's spec, GridWar's earlier policies (RuleSim's format)
on their scenario's; the method's counting (wins, losses, draws, truncations, the win rate and its Wilson
interval, per opponent p), the CLI's table, JSON and traced run, and `tracelab play --policy`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from train_helpers import walk_argv, walk_source

from tracelab.cli import main
from tracelab.game.scenario import Scenario
from tracelab.store import open_run
from tracelab.train.env_policy import EnvEvalResult, EnvPolicy, evaluate_env, save_env_policy, save_policy
from tracelab.train.env_source import probe_env
from tracelab.train.experiments.stats import wilson
from tracelab.train.qnet import NetSpec, NumpyQ

# red starts one step below blue's base on a 4x4 board: no spec plays it (RuleSim's scenario file)
NEAR = Scenario(name="near", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), red_starts=((0, 2),))
# GridWar's earlier trainer's policy (RuleSim's format): sample_runs/base-train's until 2026-11-29
SAMPLE_POLICY = Path(__file__).resolve().parent / "data" / "rulesim" / "base-policy"


def constant_weights(net: NetSpec, action: int) -> dict[str, np.ndarray]:
    """A network that always prefers one action: zero weights, a bias of 1 on it."""
    weights = {k: np.zeros(shape, np.float32) for k, shape in net.state_dict_shapes().items()}
    weights["2.bias"][action] = 1.0
    return weights


def _saved(tmp_path, scenario: Scenario, action_id: int) -> Path:
    """A policy of GridWar's earlier trainer (RuleSim's format) always taking one action."""
    import torch
    net = NetSpec(4 if not scenario.advanced else 7, (8,), scenario.n_actions)
    weights = constant_weights(net, scenario.action_ids.index(action_id))
    return save_policy(tmp_path / "policy", scenario, {"shared": {k: torch.from_numpy(v) for k, v in weights.items()}},
                       {"shared": [0]}, net.to_json(), False, False, {"run": None, "step": 0})


def _walk_policy(tmp_path) -> tuple[Path, EnvPolicy]:
    """A policy of train --env on the 4x4 walk (tests/train_helpers.py), seeded random weights: it wins some
    games and loses others against the opponent."""
    import torch
    source = walk_source()
    encoder, n_actions, spec = probe_env(source)
    net = NetSpec(encoder.size, (16,), n_actions)
    rng = np.random.default_rng(3)
    weights = {k: rng.normal(0, 1, shape).astype(np.float32) for k, shape in net.state_dict_shapes().items()}
    path = save_env_policy(tmp_path / "walk-policy", source, {k: torch.from_numpy(v) for k, v in weights.items()},
                           net.to_json(), encoder, list(spec.action_names), False, {"run": None, "step": 0})
    return path, EnvPolicy(NumpyQ(net, weights), encoder)


def test_the_methods_counting_of_a_spec_worlds_games():
    """A win is the world's declared win; a game cut short counts as a loss for the method (a non-win) and a
    truncation for tracelab; a game ended by neither is a draw; the method's win rate is the win rate."""
    r = EnvEvalResult()
    for ret, steps, terminated, truncated, outcome in [(240.0, 12, True, False, "win"), (230.0, 22, True, False, "win"),
                                                       (-310.0, 30, True, False, "loss"),
                                                       (0.0, 20, True, False, "terminated"),
                                                       (-600.0, 200, False, True, "truncated")]:
        r.add(ret, steps, terminated, truncated, outcome)
    m = r.metrics()
    assert (r.wins, r.losses, r.draws, r.truncated, r.games) == (2, 1, 1, 1, 5)
    assert m["eval/win_rate"] == m["eval/method_win_rate"] == pytest.approx(2 / 5)
    assert m["eval/actions_per_win"] == pytest.approx(17.0)
    d = r.to_dict()
    assert d["method_win_rate_ci95"] == d["win_rate_ci95"] == list(wilson(2, 5))


def test_eval_command_plays_a_one_agent_policy_on_its_spec(capsys):
    """GridWar's earlier trainer's policy evaluated on its scenario's spec (tracelab/GridWar-base-v0)."""
    assert main(["eval", str(SAMPLE_POLICY), "--games", "8", "--envs", "4", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["env"] == {"name": "tracelab/GridWar-base-v0", "kwargs": {"p_toward": 0.3}}
    assert figures["scenario"] == "base" and figures["opponent_p"] == 0.3
    assert figures["games"] == 8 == figures["wins"] + figures["losses"] + figures["draws"] + figures["truncated"]
    assert figures["wins"] >= 6  # it wins nearly all its games against the method's opponent (p = 0.3)
    assert main(["eval", str(SAMPLE_POLICY), "--games", "4", "--envs", "2"]) == 0
    assert "win rate" in capsys.readouterr().out


def test_eval_run_traces_every_game_and_counts_them_as_the_run_records_them(tmp_path, capsys):
    """eval --run on GridWar's earlier policy: every game in the run with its decisions and reward terms; the
    figures printed are the run's episodes counted (wins, Wilson interval, mean return)."""
    run = tmp_path / "evalrun"
    assert main(["eval", str(SAMPLE_POLICY), "--games", "5", "--json", "--run", str(run), "--seed", "3"]) == 0
    figures = json.loads(capsys.readouterr().out)
    con = open_run(run)
    try:
        episodes = con.execute("SELECT kind, outcome, reward FROM episodes ORDER BY episode").fetchall()
        decided = con.execute("SELECT count(DISTINCT episode), count(*) FROM decisions").fetchone()
        steps = con.execute("SELECT count(*) FROM steps").fetchone()[0]
        terms = con.execute("SELECT count(DISTINCT episode) FROM rewards").fetchone()[0]
    finally:
        con.close()
    assert [k for k, _, _ in episodes] == ["eval"] * 5 and decided == (5, steps) and terms == 5
    wins = sum(o == "win" for _, o, _ in episodes)
    assert figures["games"] == 5 and figures["wins"] == wins and figures["run"] == str(run)
    assert figures["method_win_rate"] == pytest.approx(wins / 5)
    assert figures["method_win_rate_ci95"] == pytest.approx(list(wilson(wins, 5)))
    assert figures["mean_return"] == pytest.approx(np.mean([r for *_, r in episodes]))


def test_eval_of_a_spec_policy_counts_as_the_experiments_do_per_opponent_p(tmp_path, capsys):
    """A policy of train --env on GridWar's spec, evaluated at each opponent p: the figures (games, wins, the
    method's win rate and its Wilson interval) are the spec path's evaluation's (evaluate_env, as the
    experiments' final evaluations count them) of the same games, against that p."""
    path, policy = _walk_policy(tmp_path)
    rates = []
    for p in (0.0, 1.0):
        assert main(["eval", str(path), *walk_argv(), "--opponent-p", str(p), "--games", "12", "--num-envs", "4",
                     "--seed", "5", "--json"]) == 0
        figures = json.loads(capsys.readouterr().out)
        source = walk_source(p_toward=p)
        expected = evaluate_env(policy, source, 12, 5, 4).to_dict()
        assert figures["env"] == source.to_json() and figures["opponent_p"] == p
        for key in ("games", "wins", "losses", "draws", "truncated", "method_win_rate", "mean_return"):
            assert figures[key] == pytest.approx(expected[key]), key
        assert figures["method_win_rate_ci95"] == pytest.approx(list(wilson(int(expected["wins"]), 12)))
        rates.append((figures["wins"], figures["mean_return"]))
    assert rates[0] != rates[1]  # the opponent's p changes the games


def test_eval_command_errors_are_one_line(tmp_path, capsys):
    def error(argv: list[str]) -> str:
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.startswith("tracelab: error:") and len(err.strip().splitlines()) == 1 and "Traceback" not in err
        return err

    assert "no policy" in error(["eval", str(tmp_path / "nothing-here"), "--games", "3"])
    path = _saved(tmp_path, NEAR, 0)
    # an earlier policy of a scenario no spec plays: refused, saying how to go on
    err = error(["eval", str(path), "--games", "3"])
    assert "RuleSim" in err and "near" in err and "[data.maps]" in err
    assert "does not match" in error(["eval", str(SAMPLE_POLICY), "--scenario", "advanced", "--games", "3"])
    assert "drop --backend" in error(["eval", str(SAMPLE_POLICY), "--backend", "reference", "--games", "3"])
    walk, _ = _walk_policy(tmp_path)
    assert "has none" in error(["eval", str(walk), "--env", "tracelab/FrozenLake-v1", "--opponent-p", "0.5"])


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
    """A 2v2 policy of GridWar's earlier trainer's format (one network for both agents, always "up"), evaluated
    on war.toml at agents_per_team = 2: every game counted, by the spec's outcomes; --run traces each."""
    from dataclasses import replace

    import torch

    from tracelab.game.scenario import builtin_scenario
    team = replace(builtin_scenario("base"), agents_per_team=2, red_starts=None, blue_starts=None, max_steps=12)
    net = NetSpec(8, (8,), team.n_actions)  # the team's view: 4 numbers an agent
    weights = constant_weights(net, 0)
    path = save_policy(tmp_path / "pol", team, {"shared": {k: torch.from_numpy(v) for k, v in weights.items()}},
                       {"shared": [0, 1]}, net.to_json(), False, False, {"run": None, "step": 0})
    assert main(["eval", str(path), "--games", "3", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["env"]["kwargs"]["agents_per_team"] == 2 and figures["games"] == 3
    # walking up from (7, 0) never reaches blue's base: lost to the opponent, or cut at 12 steps
    assert figures["wins"] == 0 and figures["losses"] + figures["truncated"] == 3
    run = tmp_path / "teamrun"
    assert main(["eval", str(path), "--games", "2", "--json", "--run", str(run)]) == 0
    capsys.readouterr()
    con = open_run(run)
    try:
        agents = con.execute("SELECT DISTINCT agent FROM decisions ORDER BY agent").fetchall()
        actions = con.execute("SELECT DISTINCT action_name FROM decisions").fetchall()
    finally:
        con.close()
    assert agents == [("red-agent-1",), ("red-agent-2",)] and actions == [("up",)]
