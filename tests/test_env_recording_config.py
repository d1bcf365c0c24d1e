"""Every way of recording a declared world writes the same run config (recording.declared_run_config): a
run recorded by gym.make(id, trace_writer=...) or a TeamEnv with a trace writer has the board the viewers
draw and the `declared_facts` that `why` names a draw by, as a `tracelab play --env` run has."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import tracelab.envs  # noqa: F401  (registers the tracelab/ ids)
from tracelab.cli import main
from tracelab.envs.declared.play import TeamEnv
from tracelab.envs.declared.recording import declared_run_config
from tracelab.envs.declared.spec import load_spec
from tracelab.store.portable_paths import portable_config
from tracelab.store.reader import open_run
from tracelab.store.why import explain, render_why
from tracelab.store.writer import TraceWriter
from tracelab.viewers.board_state import board_of_run

REPO = Path(__file__).resolve().parent.parent


def run_config(run: Path) -> dict[str, Any]:
    con = open_run(run)
    try:
        return json.loads(con.execute("SELECT config FROM run").fetchall()[0][0])
    finally:
        con.close()


def first_slip_why(run: Path) -> str:
    """`why` of the first drawn slip of episode 0 (FrozenLake's slippery ice), its first line."""
    con = open_run(run)
    try:
        assert board_of_run(con) is not None
        t, atom = con.execute("SELECT t, atom FROM changes WHERE episode = 0 AND label = 'slip' AND new_lower = 1 "
                              "ORDER BY t LIMIT 1").fetchone()
        return render_why(explain(con, 0, atom, t, depth=1)).splitlines()[0]
    finally:
        con.close()


def test_a_gym_make_run_has_the_board_and_names_its_draws_as_a_play_run(tmp_path: Path) -> None:
    played, made = tmp_path / "played", tmp_path / "made"
    assert main(["play", "--env", "tracelab/FrozenLake-v1", "--episodes", "3", "--seed", "0",
                 "--run", str(played)]) == 0
    env = gym.make("tracelab/FrozenLake-v1", trace_writer=TraceWriter.open(made))
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(3):
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(int(rng.integers(4)))
            done = terminated or truncated
        env.reset()
    env.close()
    spec = env.unwrapped.world_spec
    for run in (played, made):
        config, declared = run_config(run), portable_config(declared_run_config(spec), run)  # rules/toytext/...
        assert {k: config.get(k) for k in declared} == declared and config["sources"][0]["path"].startswith("rules/")
        assert first_slip_why(run).endswith("by draw:slip"), run


def test_a_team_env_run_records_the_worlds_config(tmp_path: Path) -> None:
    spec = load_spec(REPO / "rules" / "gridworld" / "war.toml", agents_per_team=2)
    run = tmp_path / "team"
    env = TeamEnv(spec, trace_writer=TraceWriter.open(run, {"command": "test"}))
    env.reset(seed=1)
    for _ in range(3):
        env.step(np.zeros(env.n_agents, np.int64))
    env.close()
    config, declared = run_config(run), portable_config(declared_run_config(spec), run)
    assert {k: config.get(k) for k in declared} == declared
    assert config["sources"][0]["path"] == "rules/gridworld/war.toml"
    con = open_run(run)
    try:
        assert board_of_run(con) is not None
    finally:
        con.close()
