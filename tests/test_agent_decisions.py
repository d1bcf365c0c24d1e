"""The agent explained in the store (issue 39): traced games record each agent-step's decision (the action
by name, the policy's value of every action, greedy or explored, the mask) and each step's reward by term,
on GridWar's spec (a freshly initialised 1v1 policy: train's traced evaluations, external_eval.DeclaredEvaluator;
`play --policy`) and on a declared world (Taxi: `play --env --policy`'s path). Runs written before read as
having none."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from older_runs import older_run
from rulesim_policies import write_rulesim_policy

from tracelab.cli import main
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.play import load_declared, make_declared_env, play_episodes
from tracelab.game.observe import obs_size
from tracelab.game.scenario import builtin_scenario
from tracelab.store import TraceWriter, open_run
from tracelab.train.env_policy import EnvPolicy, one_env_actor
from tracelab.train.env_source import ObservationEncoder, probe_env
from tracelab.train.external_eval import DeclaredEvaluator, EvalSettings
from tracelab.train.qnet import NetSpec, NumpyQ

ROOT = Path(__file__).resolve().parent.parent
ADVANCED = builtin_scenario("advanced")  # one agent a team, shots
ADVANCED_ID = EnvSource("tracelab/GridWar-advanced-v0", {"p_toward": 0.3})


def random_weights(net: NetSpec, seed: int) -> dict[str, np.ndarray]:
    """A freshly initialised network: its actions' values differ from state to state."""
    rng = np.random.default_rng(seed)
    return {k: rng.normal(0.0, 1.0, shape).astype(np.float32) for k, shape in net.state_dict_shapes().items()}


def gridwar_net() -> NetSpec:
    return NetSpec(obs_size(ADVANCED, False), (16,), ADVANCED.n_actions)


@pytest.fixture(scope="module")
def gridwar_run(tmp_path_factory) -> Path:
    """Four traced evaluation games of a fresh 1v1 policy on GridWar's advanced spec, as train's evaluations
    trace them (external_eval.DeclaredEvaluator)."""
    run = tmp_path_factory.mktemp("agent") / "gridwar"
    encoder, n_actions, _ = probe_env(ADVANCED_ID)
    net = NetSpec(encoder.size, (16,), n_actions)
    policy = EnvPolicy(NumpyQ(net, random_weights(net, 0)), encoder)
    writer = TraceWriter.open(run, {})
    ids = iter(range(1 << 62))
    evaluator = DeclaredEvaluator(ADVANCED_ID, writer, lambda: next(ids), EvalSettings(games=4, traced=4))
    evaluator.play(policy, 0, 0)
    evaluator.close()
    writer.close()
    return run


@pytest.fixture(scope="module")
def taxi_run(tmp_path_factory) -> Path:
    """Three traced Taxi games of a fresh masked policy, as `play --env --policy` records them."""
    run = tmp_path_factory.mktemp("agent") / "taxi"
    source = EnvSource.given("tracelab/Taxi-v4", {})
    spec = load_declared(source)
    env = make_declared_env(source, spec, trace_writer=TraceWriter.open(run, {}))
    encoder = ObservationEncoder(env.observation_space, "taxi")
    net = NetSpec(encoder.size, (16,), len(spec.action_names))
    policy = EnvPolicy(NumpyQ(net, random_weights(net, 1)), encoder, mask=True)
    play_episodes(env, 3, 0, one_env_actor(policy, env), step_cap=40)
    env.close()
    return run


def check_decisions(run: Path, agents: str, n_actions: int, masked: bool) -> int:
    """A decision per agent-step with every action's value; the greedy action is the argmax of the
    stored values (among the allowed ones, for a masked policy) on every greedy row. Returns the rows."""
    con = open_run(run)
    try:
        steps = con.execute(f"SELECT episode, step, agent, action, action_name FROM steps WHERE agent LIKE '{agents}' "
                            "ORDER BY ALL").fetchall()
        rows = con.execute("SELECT episode, step, agent, action, action_name, explored, actions, \"values\", mask "
                           "FROM decisions ORDER BY episode, step, agent").fetchall()
    finally:
        con.close()
    assert steps and [r[:5] for r in rows] == steps  # one decision per agent-step, the step's action and name
    for *_, name, explored, actions, values, mask in rows:
        assert len(values) == len(actions) == n_actions and not np.isnan(values).any()
        assert explored is False
        v = np.array(values)
        if masked:
            assert mask[actions.index(name)]
            v = np.where(mask, v, -np.inf)
        assert actions[int(np.argmax(v))] == name
    return len(rows)


def check_reward_terms(run: Path) -> None:
    """The rewards view sums to steps.reward on every step (a step without terms has reward 0)."""
    con = open_run(run)
    try:
        off = con.execute("""
            SELECT count(*) AS steps, count(*) FILTER (WHERE abs(s.reward - coalesce(r.total, 0)) > 1e-9) AS off
            FROM steps s LEFT JOIN (SELECT episode, step, agent, sum(value) AS total FROM rewards GROUP BY ALL) r
                 USING (episode, step, agent)""").fetchone()
        ended = con.execute("SELECT episode, rewards FROM episodes WHERE ended").fetchall()
        by_term = {(e, a): v for e, a, v in con.execute("SELECT episode, agent, sum(value) FROM returns "
                                                         "GROUP BY ALL").fetchall()}
    finally:
        con.close()
    assert off[0] > 0 and off[1] == 0
    # each episode's return by term adds up to the agent's return the episode recorded
    for episode, rewards in ended:
        for agent, total in json.loads(rewards).items():
            if agent not in ("red", "blue"):
                assert by_term.get((episode, agent), 0.0) == pytest.approx(total)


def test_gridwar_decisions_have_every_actions_value_and_greedy_is_their_argmax(gridwar_run):
    assert check_decisions(gridwar_run, "red%", ADVANCED.n_actions, masked=False) > 4


def test_gridwar_rewards_sum_to_the_step_reward_by_the_games_terms(gridwar_run):
    check_reward_terms(gridwar_run)
    con = open_run(gridwar_run)
    try:
        terms = dict(con.execute("SELECT term, list(DISTINCT value) FROM rewards GROUP BY term").fetchall())
        by_episode = con.execute("SELECT e.episode, e.outcome, r.term FROM episodes e JOIN returns r "
                                 "ON r.episode = e.episode AND r.agent = 'red-agent-1' "
                                 "WHERE r.term IN ('won(red)', 'won(blue)')").fetchall()
    finally:
        con.close()
    r = ADVANCED.rewards
    assert set(terms) <= set(load_declared(ADVANCED_ID).reward_terms)  # the spec's [reward] entries
    assert terms["canAct(Agent)"] == [r.valid_action]  # every step an agent acts pays a valid action's
    # an unsafe step pays the valid action's and the rest of RuleSim's unsafe reward
    assert set(terms.get("unsafe(Agent)", [r.unsafe - r.valid_action])) == {r.unsafe - r.valid_action}
    assert by_episode and all((outcome, term) in (("win", "won(red)"), ("loss", "won(blue)"))
                              for _, outcome, term in by_episode)


def test_taxi_decisions_and_reward_terms(taxi_run):
    assert check_decisions(taxi_run, "%", 6, masked=True) > 3
    check_reward_terms(taxi_run)
    con = open_run(taxi_run)
    try:
        terms = {t for (t,) in con.execute("SELECT DISTINCT term FROM rewards").fetchall()}
    finally:
        con.close()
    assert "plain(taxi)" in terms and terms <= {"plain(taxi)", "illegal(taxi)", "delivered(taxi)"}


def test_play_policy_records_decisions(tmp_path):
    net = gridwar_net()  # a policy of GridWar's earlier trainer (RuleSim's format), converted at load
    path = write_rulesim_policy(tmp_path / "policy", ADVANCED, net, {"shared": random_weights(net, 2)}, {"shared": [0]})
    run = tmp_path / "played"
    assert main(["play", "--policy", str(path), "--episodes", "2", "--run", str(run)]) == 0
    check_decisions(run, "red%", ADVANCED.n_actions, masked=False)
    check_reward_terms(run)


def test_runs_written_before_read_as_having_no_decisions(tmp_path):
    con = open_run(older_run(ROOT / "sample_runs" / "base", tmp_path / "older"))
    try:
        counts = [con.execute(f"SELECT count(*) FROM {v}").fetchone()[0]
                  for v in ("decisions", "action_values", "rewards", "returns")]
        names = con.execute("SELECT count(*) FILTER (WHERE action_name IS NOT NULL) FROM steps").fetchone()[0]
    finally:
        con.close()
    assert counts == [0, 0, 0, 0] and names == 0


def test_why_action_names_the_choice_the_ranking_the_observation_and_the_reward_terms(taxi_run, capsys):
    con = open_run(taxi_run)
    try:
        step, name, actions, values, mask = con.execute(
            "SELECT step, action_name, actions, \"values\", mask FROM decisions WHERE episode = 0 AND step > 1 "
            "ORDER BY step LIMIT 1").fetchone()
        terms = con.execute("SELECT term, value FROM rewards WHERE episode = 0 AND step = ?", [step]).fetchall()
    finally:
        con.close()
    assert main(["why", str(taxi_run), "--action", "taxi", "--episode", "0", "--at", str(step), "--json"]) == 0
    e = json.loads(capsys.readouterr().out)
    assert e["action"] == name and not e["explored"]
    assert [a["name"] for a in e["ranked"]] == [actions[i] for i in np.argsort(-np.array(values), kind="stable")]
    best_other = max(v for a, v, m in zip(actions, values, mask) if m and a != name)
    assert e["margin"] == pytest.approx(values[actions.index(name)] - best_other)
    features = {f["name"]: f["value"] for f in e["features"]}
    assert set(features) == {"taxi", "passenger", "destination"} and features["taxi"].startswith("at(c")
    assert {(t["term"], t["value"]) for t in e["terms"]} == set(terms)

    assert main(["why", str(taxi_run), "--action", "taxi", "--episode", "0", "--at", str(step)]) == 0
    text = capsys.readouterr().out
    assert f"-> {name}" in text and "taxi = at(c" in text and "reward" in text

    refused = next(a for a, m in zip(actions, mask) if not m)
    assert main(["why-not", str(taxi_run), "--action", refused, "--episode", "0", "--at", str(step)]) == 0
    assert "action mask did not allow" in capsys.readouterr().out
    allowed = [a for a, m in zip(actions, mask) if m and a != name]
    if allowed:
        assert main(["why-not", str(taxi_run), "--action", allowed[0], "--episode", "0", "--at", str(step),
                     "--json"]) == 0
        w = json.loads(capsys.readouterr().out)
        gap = values[actions.index(name)] - values[actions.index(allowed[0])]
        assert not w["masked"] and w["gap"] == pytest.approx(gap)


def test_why_action_on_gridwar_names_the_observation_layout(gridwar_run, capsys):
    assert main(["why", str(gridwar_run), "--action", "red-agent-1", "--episode", "0", "--at", "2", "--json"]) == 0
    e = json.loads(capsys.readouterr().out)
    assert [f["name"] for f in e["features"]][:4] == ["red_1_x", "red_1_y", "blue_1_x", "blue_1_y"]  # the spec's parts
    assert len(e["ranked"]) == ADVANCED.n_actions


@pytest.mark.parametrize("argv, message", [
    (["--action", "red-agent-1", "--episode", "0"], "--action needs --at"),
    (["--action", "nobody", "--episode", "0", "--at", "1"], "no decisions of agent nobody"),
    (["--action", "red-agent-1", "--episode", "0", "--at", "9999"], "no decision of red-agent-1 at step 9999"),
    (["alive(red-agent-1)", "--action", "red-agent-1", "--episode", "0", "--at", "1"], "give one of them"),
])
def test_why_action_errors_are_one_line(gridwar_run, capsys, argv, message):
    assert main(["why", str(gridwar_run), *argv]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error:") and message in err and "Traceback" not in err


def test_why_not_action_errors_are_one_line(gridwar_run, capsys):
    assert main(["why-not", str(gridwar_run), "--action", "fly", "--episode", "0", "--at", "1"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error:") and "no action fly" in err and "shoot_left" in err


def test_a_sealed_run_keeps_the_agents_half(taxi_run, tmp_path, capsys):
    import shutil
    run = tmp_path / "sealed"
    shutil.copytree(taxi_run, run)
    assert main(["seal", str(run)]) == 0
    assert (run / "run.duckdb").exists()
    capsys.readouterr()
    check_decisions(run, "%", 6, masked=True)
    check_reward_terms(run)


def test_why_action_reads_the_run_without_torch(taxi_run):
    import subprocess
    import sys
    code = ("import sys; from tracelab.cli import main; "
            f"status = main(['why', {str(taxi_run)!r}, '--action', 'taxi', '--episode', '0', '--at', '2']); "
            "assert status == 0; assert 'torch' not in sys.modules, 'torch was imported'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "actions by Q-value" in r.stdout


def test_a_recorder_without_the_agents_rows_records_the_same_games_without_them(gridwar_run, tmp_path):
    """bench eval's baseline (DeclaredEvaluator agent_rows=False): the world's trace of the same games, no
    decisions and no reward terms."""
    encoder, n_actions, _ = probe_env(ADVANCED_ID)
    net = NetSpec(encoder.size, (16,), n_actions)
    policy = EnvPolicy(NumpyQ(net, random_weights(net, 0)), encoder)
    run = tmp_path / "world-only"
    writer = TraceWriter.open(run, {})
    ids = iter(range(1 << 62))
    evaluator = DeclaredEvaluator(ADVANCED_ID, writer, lambda: next(ids), EvalSettings(games=4, traced=4),
                                  agent_rows=False)
    evaluator.play(policy, 0, 0)
    evaluator.close()
    writer.close()
    counts = []
    for r in (gridwar_run, run):
        con = open_run(r)
        try:
            counts.append([con.execute(f"SELECT count(*) FROM {v}").fetchone()[0]
                           for v in ("steps", "changes", "decisions", "rewards")])
        finally:
            con.close()
    (steps, changes, decisions, rewards), world_only = counts
    assert decisions == steps > 0 and rewards > 0
    assert world_only == [steps, changes, 0, 0]
