"""tracelab.playing.Games, what `tracelab play` plays: the run it records is the one the vector env records
for the same seed and worlds; the tracer hands step records over in chunks; nothing outside the CLI
imports tracelab/commands."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from tracelab.envs import tracer
from tracelab.envs.sinks import MemorySink
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.scenario import builtin_scenario
from tracelab.playing import Games

ROOT = Path(__file__).resolve().parents[1]


def play_games(sink: MemorySink, episodes: int, worlds: int, seed: int) -> Games:
    games = Games(builtin_scenario("advanced"), episodes, worlds=worlds, seed=seed, sink=sink)
    while not games.done:
        games.step()
    games.close()
    return games


def play_vector_env(sink: MemorySink, episodes: int, worlds: int, seed: int) -> None:
    """`tracelab play`'s loop before Games: the scripted red policy through GridWarVectorEnv."""
    sc = builtin_scenario("advanced")
    env = GridWarVectorEnv(worlds, sc, backend="rules", trace_sink=sink, trace_episodes=episodes)
    index_of = {a: i for i, a in enumerate(sc.action_ids)}
    to_index = np.array([index_of.get(a, 0) for a in range(9)])
    env.reset(seed=seed)
    ended, started = 0, worlds  # episodes numbered in the order they begin
    of_world = np.arange(worlds)
    while ended < episodes:
        red = to_index[env.sim.scripted_actions("red")]
        _, _, term, trunc, _ = env.step(red[:, 0])
        done = np.flatnonzero(term | trunc)
        ended += int((of_world[done] < episodes).sum())
        of_world[done] = started + np.arange(len(done))
        started += len(done)
    env.close()


def test_games_record_what_the_vector_env_records() -> None:
    games, env = MemorySink(), MemorySink()
    played = play_games(games, episodes=7, worlds=3, seed=5)
    play_vector_env(env, episodes=7, worlds=3, seed=5)
    assert sorted(played.finished) == list(range(7))
    assert [e["episode"] for e in games.begun] == [e["episode"] for e in env.begun] == list(range(7))
    assert sorted(games.ended, key=lambda e: e["episode"]) == sorted(env.ended, key=lambda e: e["episode"])
    for ep in range(7):
        for got, want in ((games.rows(ep), env.rows(ep)), (games.steps(ep), env.steps(ep))):
            assert got.keys() == want.keys() and len(want["t"]) > 0
            for col in want:
                np.testing.assert_array_equal(got[col], want[col], err_msg=f"episode {ep}, {col}")
    # the outcome play reports is the one the run records
    assert {e: played.finished[e]["outcome"] for e in range(7)} == {e["episode"]: e["outcome"] for e in games.ended}


def test_step_records_go_to_the_sink_in_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    chunked = MemorySink()
    play_games(chunked, episodes=4, worlds=2, seed=1)
    steps = chunked.steps()
    assert len(chunked.step_chunks) < len(np.unique(steps["t"])) * 2 / 4  # far fewer calls than steps
    monkeypatch.setattr(tracer, "HANDOVER_STEPS", 1)  # a log of one step: handed over after every step
    every = MemorySink()
    play_games(every, episodes=4, worlds=2, seed=1)
    assert len(every.step_chunks) > len(chunked.step_chunks)
    for ep in range(4):
        a, b = chunked.steps(ep), every.steps(ep)
        for col in b:
            np.testing.assert_array_equal(a[col], b[col], err_msg=f"episode {ep}, {col}")
    assert chunked.ended == every.ended  # the same returns, added in the same order


def _imports_of(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_nothing_but_the_cli_imports_tracelab_commands() -> None:
    commands = ROOT / "tracelab" / "commands"
    cli = {ROOT / "tracelab" / "cli.py", ROOT / "tracelab" / "__main__.py"}
    offenders = [str(p.relative_to(ROOT)) for folder in ("tracelab", "engine", "viewers")
                 for p in sorted((ROOT / folder).rglob("*.py"))
                 if commands not in p.parents and p not in cli
                 and any(n == "tracelab.commands" or n.startswith("tracelab.commands.") for n in _imports_of(p))]
    assert offenders == []
