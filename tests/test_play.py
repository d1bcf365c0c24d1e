"""`tracelab play --scenario`: GridWar's games through its spec (rules/gridworld/war*.toml) into a real
trace-store run; old policies of GridWar's trainer play there as on RuleSim."""
from __future__ import annotations

from pathlib import Path

from tracelab.cli import main
from tracelab.store import open_run
from tracelab.store.why import explain, render_why

ROOT = Path(__file__).resolve().parent.parent


def test_play_records_episodes_changes_steps_and_explains_a_position(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["play", "--scenario", "advanced", "--episodes", "3", "--seed", "4",
                 "--run", str(run)]) == 0
    out = capsys.readouterr().out
    assert "played 3 episodes" in out and f"tracelab why {run}" in out
    assert f"tracelab tui {run}" in out and f"tracelab replay {run} --episode 0" in out
    con = open_run(run)
    ended = con.execute("SELECT count(*) FROM episodes WHERE outcome IN ('win','loss','terminated','truncated')"
                        ).fetchone()[0]
    assert con.execute("SELECT scenario FROM run").fetchone()[0] == "advanced"
    assert con.execute("SELECT count(DISTINCT term) FROM raw.reward_terms").fetchone()[0] >= 5
    assert ended == 3 == con.execute("SELECT count(*) FROM episodes").fetchone()[0]
    # what play says of the games is what the run records of them
    won, lost, truncated, mean = con.execute(
        "SELECT count(*) FILTER (outcome = 'win'), count(*) FILTER (outcome = 'loss'), "
        "count(*) FILTER (outcome = 'truncated'), avg(reward) FROM episodes").fetchone()
    assert f"{won} won, {lost} lost, {truncated} truncated; mean return {mean:.2f}" in out
    # every episode starts from its own set-up rows, then the rules move the agents
    per_ep = con.execute("SELECT episode, min(t), count(*) FILTER (rule = 'm_go') FROM changes "
                         "GROUP BY episode ORDER BY episode").fetchall()
    assert all(first == 0 for _, first, _ in per_ep)
    assert sum(moves for *_, moves in per_ep) > 0
    # the learner's per-step actions and rewards are recorded
    assert con.execute("SELECT count(*) FROM steps WHERE agent = 'red-agent-1'").fetchone()[0] > 0
    atom, t = con.execute("SELECT atom, t FROM changes WHERE rule = 'm_go' AND episode = 0 "
                          "ORDER BY t LIMIT 1").fetchone()
    text = render_why(explain(con, episode=0, atom=atom, at=t, depth=2))
    con.close()
    assert "m_go" in text and "dest(" in text


def test_play_without_trace_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["play", "--scenario", "base", "--episodes", "2", "--no-trace"]) == 0
    assert "played 2 episodes" in capsys.readouterr().out
    assert not (tmp_path / "runs").exists()


def test_play_names_a_bad_scenario_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nwidth = 8\nheight = 8\nred_base = [7, 0]\nblue_base = [0, 7]\n'
                   'mountains = [[9, 3]]\n')
    assert main(["play", "--scenario", str(bad), "--episodes", "1", "--no-trace"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error: ") and "mountains[0]" in err and err.count("\n") == 1


def test_play_refuses_a_scenario_no_spec_plays_in_one_line(tmp_path, capsys):
    odd = tmp_path / "odd.toml"
    odd.write_text('name = "odd"\nwidth = 8\nheight = 8\nred_base = [7, 0]\nblue_base = [0, 7]\n'
                   'mountains = [[1, 1]]\n')
    assert main(["play", "--scenario", str(odd), "--episodes", "1", "--no-trace"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error: scenario 'odd': its board is not war.toml's 8x8 map") \
        and err.count("\n") == 1
    assert main(["play", "--policy", "scripted", "--no-trace"]) == 1
    err = capsys.readouterr().err
    assert "--policy scripted" in err and err.count("\n") == 1


def test_play_a_team_records_each_agent(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["play", "--scenario", "base", "--agents", "2", "--episodes", "2", "--opponent-p", "0.2",
                 "--run", str(run)]) == 0
    assert "played 2 episodes of base" in capsys.readouterr().out
    con = open_run(run)
    agents = con.execute("SELECT DISTINCT agent FROM steps ORDER BY agent").fetchall()
    params = con.execute("SELECT config FROM run").fetchone()[0]
    con.close()
    assert agents == [("red-agent-1",), ("red-agent-2",)]
    assert '"agents_per_team": 2' in params and '"p_toward": 0.2' in params


def test_an_old_gridwar_policy_plays_as_it_did_on_rulesim(tmp_path):
    """tests/data/rulesim/base-policy (GridWar's trainer on RuleSim) converted at load and played greedily on RefSim
    (the hand-written oracle) and through the spec path, the same seed: the same games, step for step (its
    observation is the spec's)."""
    import numpy as np

    from gridwar_refsim import RefGridWar
    from rulesim_policies import RULESIM_POLICY
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.envs.declared.gridwar import scenario_spec
    from tracelab.envs.declared.gridwar_scenarios import load_trained, read_rulesim_spec, rulesim_scenario
    from tracelab.envs.declared.play import load_declared, make_declared_env, play_episodes
    from tracelab.train.env_policy import greedy_actor

    scenario = rulesim_scenario(read_rulesim_spec(RULESIM_POLICY))
    source = EnvSource(*scenario_spec(scenario))
    policy = load_trained(RULESIM_POLICY, source)
    ref, dec = RefGridWar(scenario), make_declared_env(source, load_declared(source))
    games = [play_episodes(env, 6, 3, greedy_actor(policy))["episodes"] for env in (ref, dec)]
    outcomes = {"win": "win", "loss": "loss"}
    assert [(g["steps"], g["return"]) for g in games[0]] == [(g["steps"], g["return"]) for g in games[1]]
    assert [outcomes.get(g["outcome"], "other") for g in games[1]].count("win") >= 1
    assert np.std([g["steps"] for g in games[1]]) > 0  # not one game six times


def test_a_policy_refused_on_a_world_of_another_shape_in_one_line(capsys):
    from rulesim_policies import RULESIM_POLICY
    assert main(["play", "--env", "tracelab/GridWar-advanced-v0", "--policy", str(RULESIM_POLICY), "--no-trace"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "trained on GridWar's 'base' (1 agents, 5 actions, 4 observations)" in err
    assert "9 actions, 7 observations" in err
