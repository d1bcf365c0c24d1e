"""A declared world's games recorded into the trace store (tracelab/envs/declared/recording.py) and
`tracelab play --env` (tracelab/commands/play.py): real runs, read back through DuckDB."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import tracelab.envs  # noqa: F401 - registers the toy-text ids
from tracelab.cli import main
from tracelab.envs.declared.toytext import spec_path
from tracelab.store import TraceWriter, open_run
from tracelab.store.why import explain, render_why


def _play(env: gym.Env, episodes: int, seed: int) -> list[tuple[int, float, list[int], list[float]]]:
    """(steps, return, observations, rewards) of each episode under random actions."""
    rng = np.random.default_rng(seed)
    out = []
    env.reset(seed=seed)
    for e in range(episodes):
        if e:
            env.reset()
        done, obs_seen, rewards = False, [], []
        while not done:
            obs, r, term, trunc, _ = env.step(int(rng.integers(env.action_space.n)))
            obs_seen.append(int(obs))
            rewards.append(float(r))
            done = term or trunc
        out.append((len(rewards), sum(rewards), obs_seen, rewards))
    return out


def test_a_traced_frozen_lake_records_every_game_its_steps_and_explains_a_win(tmp_path: Path) -> None:
    run = tmp_path / "run"
    env = gym.make("tracelab/FrozenLake-v1", trace_writer=TraceWriter.open(run))
    played = _play(env, 150, seed=4)
    env.close()
    # the same games untraced: tracing changes nothing the env returns
    assert _play(gym.make("tracelab/FrozenLake-v1"), 150, seed=4) == played
    con = open_run(run)
    eps = con.execute("SELECT episode, steps, reward, outcome, seed FROM episodes ORDER BY episode").fetchall()
    assert [(s, r) for _, s, r, _, _ in eps] == [(s, r) for s, r, _, _ in played]
    assert {o for *_, o, _ in eps} <= {"terminated", "truncated"} and eps[0][4] == 4
    steps = con.execute("SELECT episode, step, obs[1], reward FROM steps ORDER BY episode, step").fetchall()
    assert [(o, r) for _, _, o, r in steps] == [(o, r) for *_, obs, rew in played for o, r in zip(obs, rew)]
    # each episode's rows start at t = 0 with the board's facts, so its rows alone rebuild its world
    firsts = con.execute("SELECT episode, min(t), count(*) FILTER (rule LIKE 'fact:board%') FROM changes "
                         "GROUP BY episode ORDER BY episode").fetchall()
    # legend (S: start, ice) + 4 neighbours
    assert [f[0] for f in firsts] == list(range(150)) and {(f[1], f[2]) for f in firsts} == {(0, 17 + 64)}
    # a won game's goal is explained back through the rules to the keys pressed and the ice's slips
    won = [e for e, s, r, *_ in eps if r > 0]
    assert won, "no won game among 150 random ones (seeded: should not happen)"
    t = con.execute("SELECT max(t) FROM changes WHERE episode = ? AND atom = 'landed(goal)'", [won[0]]).fetchone()[0]
    text = render_why(explain(con, episode=won[0], atom="landed(goal)", at=t, depth=6))
    con.close()
    assert "land_goal" in text and "goal(c3_3)" in text
    assert "pressed(" in text and "slip(" in text and "by action" in text


def test_a_time_limit_truncation_is_recorded_as_truncated(tmp_path: Path) -> None:
    run = tmp_path / "run"
    # never slippery, always pressing left: the agent stays on the start cell until the limit (100)
    env = gym.make("tracelab/FrozenLake-v1", is_slippery=False, trace_writer=TraceWriter.open(run))
    env.reset(seed=0)
    trunc = False
    while not trunc:
        *_, trunc, _ = env.step(0)
    env.close()
    con = open_run(run)
    assert con.execute("SELECT steps, outcome FROM episodes").fetchall() == [(100, "truncated")]
    con.close()


def test_play_env_records_a_run_with_its_spec_and_says_what_to_open(tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    assert main(["play", "--env", "tracelab/FrozenLake-v1", "--env-arg", "map_name=8x8", "--env-arg",
                 "is_slippery=false", "--episodes", "12", "--seed", "2", "--run", str(run)]) == 0
    out = capsys.readouterr().out
    assert "played 12 episodes of FrozenLake-v1" in out and f"tracelab tui {run}" in out
    meta = json.loads((run / "meta.json").read_text())
    config = meta["config"]
    assert config["env_id"] == "tracelab/FrozenLake-v1" and config["env_args"] == {"map_name": "8x8",
                                                                                    "is_slippery": False}
    # the program's files by path, size and hash; their texts in the run's `sources` table
    assert [s["role"] for s in config["sources"]] == ["spec", "rules"] and "spec" not in config
    assert config["sources"][1]["path"].endswith("frozen_lake.rules") and config["sources"][1]["bytes"] > 0
    assert config["declared_facts"] == {"actions": ["pressed"], "draws": {"start": ["at"], "slip": ["slip"]}}
    assert config["declared_board"]["rows"][0] == "SFFFFFFF"
    assert meta["rule_files"][0].endswith("frozen_lake.rules") if isinstance(meta["rule_files"][0], str) \
        else meta["rule_files"][0]["path"].endswith("frozen_lake.rules")
    assert main(["show", str(run)]) == 0
    shown = capsys.readouterr().out
    assert "board     the spec's [board] (drawn by the TUI and the replay)" in shown and "\nspec      " in shown
    assert '  legend = { S = ["start", "ice"]' in shown and '"spec":' not in shown  # the spec in its section
    con = open_run(run)
    texts = dict(con.execute("SELECT role, text FROM raw.sources").fetchall())
    assert "[board]" in texts["spec"] and "land_goal" in texts["rules"]
    assert con.execute("SELECT count(*) FROM episodes WHERE ended").fetchone()[0] == 12
    # not slippery: every slip drawn is `straight`
    assert con.execute("SELECT DISTINCT atom FROM changes WHERE atom LIKE 'slip(%' AND new_lower = 1"
                       ).fetchall() == [("slip(straight)",)]
    con.close()


def test_play_env_from_a_spec_file_without_trace(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    spec = spec_path("taxi.toml")
    assert main(["play", "--env", str(spec), "--episodes", "2", "--no-trace"]) == 0
    assert "played 2 episodes of taxi" in capsys.readouterr().out
    assert not (tmp_path / "runs").exists()


def test_play_env_plays_gridwar_ids_through_its_spec(tmp_path: Path, capsys, monkeypatch) -> None:
    """GridWar's ids name rules/gridworld/war.toml for --env, its params set by --env-arg."""
    monkeypatch.chdir(tmp_path)
    assert main(["play", "--env", "tracelab/GridWar-base-v0", "--env-arg", "map=open", "--env-arg", "max_steps=5",
                 "--episodes", "2", "--no-trace"]) == 0
    assert "played 2 episodes of GridWar-base-v0 (10 steps" in capsys.readouterr().out


@pytest.mark.parametrize("args, fragment", [
    (["--env", "tracelab/NoSuchLake-v9"], "--env tracelab/NoSuchLake-v9: neither a spec file nor a registered id"),
    (["--env", "tracelab/GridWar-base-v0", "--env-arg", "map=moon"], "war.toml:26: env.require.map in maps"),
    (["--env", "tracelab/GridWar-advanced-v0", "--env-arg", "agents_per_team=2"], "plays one agent a team for now"),
    (["--env", "tracelab/FrozenLake-v1", "--env-arg", "slippery=false"], "unknown keyword argument 'slippery'"),
    (["--env", "tracelab/FrozenLake-v1", "--env-arg", "is_slippery"], "write KEY=VALUE"),
    (["--env", "tracelab/FrozenLake-v1", "--env-arg", "map_name=9x9"], "map_name"),
    (["--env", "tracelab/FrozenLake-v1", "--scenario", "base"], "--scenario describes GridWar"),
    (["--env", "tracelab/FrozenLake-v1", "--policy", "scripted"], "--policy scripted"),
])
def test_play_env_mistakes_are_one_line(tmp_path: Path, args: list[str], fragment: str) -> None:
    proc = subprocess.run([sys.executable, "-m", "tracelab", "play", *args, "--episodes", "1",
                           "--run", str(tmp_path / "run")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.startswith("tracelab: error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert fragment in proc.stderr
    assert not (tmp_path / "run").exists()  # nothing written for a command that could not start


def test_the_why_tutorial_of_the_docs_runs_as_shown(tmp_path: Path) -> None:
    """docs/worlds.md, "Recording games, and why a game was won": each command, run in an empty folder
    in the page's order, prints what the page shows (the play's steps/s aside: they vary)."""
    import re
    import shlex
    text = (Path(__file__).resolve().parents[1] / "docs" / "worlds.md").read_text()
    section = text.split("## Recording games, and why a game was won", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```console\n\$ (.*?)\n(.*?)```", section, re.S)
    assert [shlex.split(c)[1] for c, _ in blocks] == ["play", "sql", "trace", "why", "why-not"]
    for command, shown in blocks:
        out = subprocess.run([sys.executable, "-m", "tracelab", *shlex.split(command)[1:]], cwd=tmp_path,
                             capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr
        rate = re.compile(r"[\d,]+ steps/s")
        assert rate.sub("N steps/s", out.stdout) == rate.sub("N steps/s", shown), command
    # the tree shown reaches the draws of the ice and the keys pressed
    why = blocks[3][1]
    assert "slip(ccw):[1,1]" in why and "slip(straight):[1,1]" in why and "pressed(down):[1,1]" in why


def test_ctrl_c_keeps_the_games_played_and_says_so(tmp_path: Path) -> None:
    import signal
    import time
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "tracelab", "play", "--env", "tracelab/FrozenLake-v1",
                             "--episodes", "10000000", "--run", str(run)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:  # some games written (the writer publishes every ~0.25 s)
            if (run / "meta.json").exists():
                con = open_run(run)
                n = con.execute("SELECT count(*) FROM episodes WHERE ended").fetchone()[0]
                con.close()
                if n >= 5:
                    break
            time.sleep(0.3)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    kept = int(err.split(" keeps ")[1].split()[0])
    lines = err.strip().splitlines()
    assert lines[0] == "stopping after this step (Ctrl-C again to stop at once)", err  # between two steps
    assert lines[-1].startswith(f"tracelab: interrupted: {run} keeps ") and kept >= 5, err
    assert json.loads((run / "meta.json").read_text())["status"] == "interrupted"
    con = open_run(run)
    outcomes = dict(con.execute("SELECT outcome, count(*) FROM episodes GROUP BY 1").fetchall())
    # every game begun has ended: the one Ctrl-C cut short (if any) as aborted
    assert set(outcomes) <= {"terminated", "aborted"} and outcomes.get("aborted", 0) <= 1
    assert sum(outcomes.values()) == kept
    con.close()


def test_play_env_plays_a_spec_of_several_agents_recording_each(tmp_path: Path, capsys) -> None:
    from test_env_spec_agents import RULES, SPEC
    (tmp_path / "pair.rules").write_text(RULES)
    (tmp_path / "pair.toml").write_text(SPEC)
    assert main(["play", "--env", str(tmp_path / "pair.toml"), "--episodes", "3", "--run", str(tmp_path / "run")]) == 0
    assert "played 3 episodes of pair" in capsys.readouterr().out
    con = open_run(tmp_path / "run")
    per_agent = con.execute("SELECT agent, count(*) FROM steps GROUP BY agent ORDER BY agent").fetchall()
    assert con.execute("SELECT count(*) FROM episodes").fetchone()[0] == 3
    con.close()
    assert len(per_agent) == 2 and per_agent[0][1] == per_agent[1][1] > 0
