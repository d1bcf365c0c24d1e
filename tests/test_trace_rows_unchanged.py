"""A traced run's rows stay exactly what they were when recording got faster (issue 31 part 1): the
digests of every stored row (all columns but wall-clock times) of seeded games, taken from the code
before the speed work. A change here changes what every run records: only on purpose, with the new
digests and the reason in the commit."""
from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from tracelab.cli import main
from tracelab.store import open_run

# table -> the columns compared, in the order that makes the rows' order part of the digest
COMPARED = {
    "raw.changes": ("*", "seq"),
    "raw.steps": ("*", "episode, step, agent"),
    "raw.episode_begin": ("episode, world, t_start, seed, info", "episode"),
    "raw.episode_end": ("episode, steps, t_end, outcome, reward, rewards, info", "episode"),
}


def run_digests(run: Path) -> dict[str, tuple[int, str]]:
    con = open_run(run)
    try:
        out = {}
        for table, (columns, order) in COMPARED.items():
            rows = con.execute(f"SELECT {columns} FROM {table} ORDER BY {order}").fetchall()
            out[table] = (len(rows), hashlib.sha256(repr(rows).encode()).hexdigest()[:16])
        return out
    finally:
        con.close()


# Digests of main at 37fd478 (before issue 31's recording speed work). gridwar's since issue 38: play --scenario
# plays GridWar through its spec (war.toml, the declared recorder; red random), a new baseline taken then
# (RuleSim's scripted games had 14,222 changes and 518 steps; the episode begins are unchanged). Its changes
# again on 2026-11-29: the opponent's goal cells are derived for every agent (env.rules, opponent.rules, for
# --explore-scripted's scriptMove), 3,954 more rows; the steps and episodes, the games, are the same. Again
# on 2026-11-29 (branch speed38): the opponent reads which moves get closer from one atom per agent and
# move (opponent.rules' closerUp..closerRight) instead of per cell (hasV, hasH), 2,260 fewer rows; the
# steps and episodes are the same. And the action mask's rules (game.rules section 7, env.rules) are
# immediate rules after the game's instead of Δt = 0 rules: the same 34,846 rows, in other passes (pass 1,
# not 2 or 3) and so in another order. Again on 2026-11-29 (branch speedrules38): the opponent's goal moves
# are derived per base cell, not per agent (okUp(G,X): no goalUp atoms, half the okUp atoms), and the tally's
# level 0 is a fact (noHits), not tally atoms: 2,688 fewer rows, all of an episode's start; the steps and
# episodes are the same.
EXPECTED = {
    "gridwar": {"raw.changes": (32158, "cff6ab406434238e"), "raw.steps": (316, "1c59708717304daf"),
                "raw.episode_begin": (12, "e5922dd3df8262e7"), "raw.episode_end": (12, "d515e398b502c416")},
    "frozenlake": {"raw.changes": (12492, "37ac591e13f7b5ed"), "raw.steps": (455, "a3d8f1232317cea3"),
                   "raw.episode_begin": (60, "c181fb942608bd40"), "raw.episode_end": (60, "6dc7d68960f21851")},
}
GAMES = {
    "gridwar": ["play", "--scenario", "base", "--episodes", "12", "--seed", "1"],
    "frozenlake": ["play", "--env", "tracelab/FrozenLake-v1", "--episodes", "60", "--seed", "3"],
}


@pytest.mark.parametrize("game", sorted(GAMES))
def test_a_seeded_traced_run_records_the_same_rows_as_before(game: str, tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert main([*GAMES[game], "--run", str(run)]) == 0
    assert run_digests(run) == EXPECTED[game]
