"""`tracelab eval`: every policy played on its world's spec, GridWar's earlier policies (RuleSim's format,
converted at load: tests/data/rulesim/base-policy) on their scenario's; the method's counting (wins, losses,
draws, truncations, the win rate and its Wilson interval, per opponent p), the CLI's table, JSON and traced
run, and `tracelab play --policy`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rulesim_policies import RULESIM_POLICY, constant_weights, write_rulesim_policy
from train_helpers import random_env_policy, walk_argv, walk_source

from tracelab.cli import main
from tracelab.game.scenario import Scenario
from tracelab.store import open_run
from tracelab.train.env_policy import EnvEvalResult, EnvPolicy, evaluate_env
from tracelab.train.experiments.stats import wilson
from tracelab.train.qnet import NetSpec

# red starts one step below blue's base on a 4x4 board: no spec plays it (RuleSim's scenario file)
NEAR = Scenario(name="near", width=4, height=4, red_base=(3, 0), blue_base=(0, 3), red_starts=((0, 2),))


def _saved(tmp_path, scenario: Scenario, action_id: int) -> Path:
    """A policy of GridWar's earlier trainer (RuleSim's format) always taking one action."""
    net = NetSpec(4 if not scenario.advanced else 7, (8,), scenario.n_actions)
    weights = constant_weights(net, scenario.action_ids.index(action_id))
    return write_rulesim_policy(tmp_path / "policy", scenario, net, {"shared": weights}, {"shared": [0]})


def _walk_policy(tmp_path) -> tuple[Path, EnvPolicy]:
    """A policy of train --env on the 4x4 walk (tests/train_helpers.py), seeded random weights: it wins some
    games and loses others against the opponent."""
    return random_env_policy(tmp_path / "walk-policy", walk_source(), seed=3)


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


def test_eval_command_plays_an_old_policy_as_main_did(capsys):
    """GridWar's earlier trainer's policy (tests/data/rulesim/base-policy, RuleSim's format), converted at load and
    evaluated on its scenario's spec (tracelab/GridWar-base-v0): the figures main gave on 2026-11-29 with its
    own player of that format (64 of 64 won, mean return 188.75, 30.625 steps a game)."""
    assert main(["eval", str(RULESIM_POLICY), "--games", "64", "--seed", "0", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["env"] == {"name": "tracelab/GridWar-base-v0", "kwargs": {"p_toward": 0.3}}
    assert figures["scenario"] == "base"
    assert (figures["games"], figures["wins"], figures["losses"], figures["truncated"]) == (64, 64, 0, 0)
    assert (figures["mean_return"], figures["mean_steps"]) == (188.75, 30.625)
    assert main(["eval", str(RULESIM_POLICY), "--games", "4", "--envs", "2"]) == 0
    assert "win rate" in capsys.readouterr().out


def test_eval_run_traces_every_game_and_counts_them_as_the_run_records_them(tmp_path, capsys):
    """eval --run on GridWar's earlier policy (converted): every game in the run with its decisions and reward
    terms; the figures printed are the run's episodes counted (wins, Wilson interval, mean return)."""
    run = tmp_path / "evalrun"
    assert main(["eval", str(RULESIM_POLICY), "--games", "5", "--json", "--run", str(run), "--seed", "3"]) == 0
    figures = json.loads(capsys.readouterr().out)
    con = open_run(run)
    try:
        episodes = con.execute("SELECT kind, outcome, reward FROM episodes ORDER BY episode").fetchall()
        decided = con.execute("SELECT count(DISTINCT episode), count(*) FROM decisions").fetchone()
        steps = con.execute("SELECT count(*) FROM steps").fetchone()[0]
        terms = con.execute("SELECT count(DISTINCT episode) FROM rewards").fetchone()[0]
        began = {b for (b,) in con.execute("SELECT DISTINCT begin_info FROM episodes").fetchall()}
    finally:
        con.close()
    assert [k for k, _, _ in episodes] == ["eval"] * 5 and decided == (5, steps) and terms == 5
    # each game begins with the world's own params (the id's and the opponent's p as its spec names them)
    assert [json.loads(b) for b in began] == [{"kind": "eval", "params": {"advanced": False, "p_toward": 0.3}}]
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
        assert figures["env"] == source.to_json() and figures["env"]["kwargs"]["p_toward"] == p
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
    err = error(["eval", str(RULESIM_POLICY), "--scenario", "advanced", "--games", "3"])
    assert "trained on GridWar's 'base' (1 agents, 5 actions, 4 observations)" in err
    assert "tracelab/GridWar-advanced-v0 --env-arg p_toward=0.3 has 1 agents, 9 actions, 7 observations" in err
    assert "drop --backend" in error(["eval", str(RULESIM_POLICY), "--backend", "reference", "--games", "3"])
    walk, _ = _walk_policy(tmp_path)
    on_file = json.loads((walk / "policy.json").read_text())  # the walk's world named by its spec file
    on_file["env"]["name"] = str(Path(__file__).resolve().parent.parent / "rules" / "gridworld" / "war.toml")
    (walk / "policy.json").write_text(json.dumps(on_file))
    assert "trained with train --env on a spec file: name that env with --env" in error(["eval", str(walk)])
    walk, _ = _walk_policy(tmp_path / "again")
    assert "has none" in error(["eval", str(walk), "--env", "tracelab/FrozenLake-v1", "--opponent-p", "0.5"])


def test_a_policy_of_train_on_a_gridwar_id_plays_without_env(tmp_path, capsys):
    """README's `tracelab eval runs/base-1/policy`: a policy train --scenario base wrote (its env:
    tracelab/GridWar-base-v0) is evaluated on that id without --env, against the method's opponent (p = 0.3)
    unless --opponent-p says, and played by play --policy."""
    from tracelab.envs.declared.env_source import EnvSource
    source = EnvSource("tracelab/GridWar-base-v0", {})
    path, policy = random_env_policy(tmp_path / "policy", source, seed=4)
    assert main(["eval", str(path), "--games", "8", "--num-envs", "4", "--seed", "2", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    against = EnvSource(source.name, {"p_toward": 0.3})
    expected = evaluate_env(policy, against, 8, 2, 4).to_dict()
    assert figures["env"] == against.to_json()
    for key in ("games", "wins", "losses", "truncated", "mean_return", "mean_steps"):
        assert figures[key] == pytest.approx(expected[key]), key
    assert main(["play", "--policy", str(path), "--episodes", "2", "--opponent-p", "0.2", "--no-trace"]) == 0
    assert "played 2 episodes of GridWar-base-v0" in capsys.readouterr().out


def test_play_plays_and_traces_a_saved_policy(tmp_path, capsys):
    run = tmp_path / "played"
    assert main(["play", "--policy", str(RULESIM_POLICY), "--episodes", "3", "--run", str(run)]) == 0
    assert "played 3 episodes of base" in capsys.readouterr().out
    con = open_run(run)
    steps = con.execute("SELECT count(*) FROM steps WHERE agent = 'red-agent-1'").fetchone()[0]
    # each step's decision is the policy's greedy choice among its Q-values
    greedy = con.execute("SELECT count(*) FROM raw.decisions "
                         "WHERE list_position(values, list_max(values)) - 1 = action").fetchone()[0]
    con.close()
    assert steps > 0 and greedy == steps


@pytest.mark.parametrize("command", [["eval", "{}", "--games", "3"], ["play", "--policy", "{}", "--no-trace"]])
def test_an_old_teams_policy_is_refused_with_the_command_that_trains_it_again(command, tmp_path, capsys):
    """A 2v2 policy of GridWar's earlier trainer: each agent read the team with its own blocks first, which no
    policy of today reads; eval and play refuse it in one line that gives the command to train it again."""
    from dataclasses import replace

    from tracelab.game.scenario import builtin_scenario
    team = replace(builtin_scenario("base"), agents_per_team=2, red_starts=None, blue_starts=None, max_steps=12)
    net = NetSpec(8, (8,), team.n_actions)  # the team's view: 4 numbers an agent
    path = write_rulesim_policy(tmp_path / "pol", team, net, {"shared": constant_weights(net, 0)},
                                {"shared": [0, 1]})
    assert main([a.format(path) for a in command]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error:") and err.count("\n") == 1, err
    assert "RuleSim's format" in err and "2 agents a team" in err
    assert err.rstrip().endswith("train it again on its spec: tracelab train --scenario base --agents 2"), err
