"""`tracelab rewards RUN --set TERM=VALUE` re-scores every recorded episode from the run's reward terms
without re-simulating (issue 39 item 5): on a spec world's run, the re-scored returns are the returns of
the same games played again with the edited spec (the same seed, the same random actions), for a table
term, a term that also ends the game and the scaled atom (whose --set is the scale), and so for terms worth 0
in the run (their occurrences are recorded as rows of value 0 with their quantity). A run written before
terms were recorded, or before their quantities were, says so in one line; an unknown term is one line
with a did-you-mean; a term that never occurred is re-scored to no change, and a note says so."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from test_reading_imports import ALLOWED, CHILD, HEAVY
from older_runs import older_run
from test_spec_world_game import RULES, SPEC

import duckdb

from tracelab.cli import main
from tracelab.store import open_run

ROOT = Path(__file__).resolve().parents[1]
# the trap world with a table term that ends nothing (standing on c0_3) and a scaled atom (was(c0_2))
TABLE = '[reward.table]\n"home(me)" = "door_reward"\n"dead(me)" = -1\n'
assert TABLE in SPEC
BASE = SPEC.replace(TABLE, '[reward]\natom = "was(c0_2)"\nscale = 0.5\n\n' + TABLE + '"at(c0_3)" = 0.25\n')
SETS = {"at(c0_3)": 2.0, "home(me)": 5.0, "was(c0_2)": 3.0}
EDITED = BASE.replace('"at(c0_3)" = 0.25', '"at(c0_3)" = 2.0').replace("door_reward = 1.0", "door_reward = 5.0") \
    .replace("scale = 0.5", "scale = 3.0")
# the same world with the table term and the scaled atom worth 0: their occurrences pay nothing
ZERO = BASE.replace('"at(c0_3)" = 0.25', '"at(c0_3)" = 0').replace("scale = 0.5", "scale = 0")


def play(folder: Path, name: str, text: str) -> Path:
    (folder / f"{name}.toml").write_text(text)
    run = folder / "runs" / name
    assert main(["play", "--env", str(folder / f"{name}.toml"), "--episodes", "12", "--seed", "3",
                 "--run", str(run)]) == 0
    return run


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    folder = tmp_path_factory.mktemp("rescore")
    (folder / "trap.rules").write_text(RULES)
    return play(folder, "base", BASE), play(folder, "edited", EDITED), play(folder, "zero", ZERO)


def returns(run: Path) -> dict[int, float]:
    con = open_run(run)
    try:
        return {int(e): float(r) for e, r in con.execute("SELECT episode, reward FROM episodes").fetchall()}
    finally:
        con.close()


def test_rescored_returns_match_the_games_played_with_the_edited_spec(runs: tuple[Path, Path, Path],
                                                                     capsys: pytest.CaptureFixture) -> None:
    base, edited, _ = runs
    old, new = returns(base), returns(edited)
    assert old.keys() == new.keys() and old != new  # the edit changes some return
    capsys.readouterr()
    argv = ["rewards", str(base), "--json", *(a for t, v in SETS.items() for a in ("--set", f"{t}={v}"))]
    assert main(argv) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["set"] == {"at(c0_3)": {"old": 0.25, "new": 2.0}, "home(me)": {"old": 1.0, "new": 5.0},
                          "was(c0_2)": {"old": 0.5, "new": 3.0}}
    assert {r["episode"]: r["return"] for r in got["episodes"]} == pytest.approx(old)
    assert {r["episode"]: r["rescored"] for r in got["episodes"]} == pytest.approx(new)
    assert got["total"]["rescored"] == pytest.approx(sum(new.values()))
    # every term occurred, so each --set mattered
    assert {t for r in got["episodes"] for t in r["by_term"]} == {"home(me)", "dead(me)", "at(c0_3)", "was(c0_2)"}
    notes = "\n".join(got["notes"])
    assert "home(me) also ends an episode ([end] terminated, win)" in notes
    assert "--set was(c0_2)=S sets the scale" in notes
    assert "at(c0_3) also ends" not in notes


def test_terms_worth_0_are_rescored_as_the_games_played_with_their_new_values(
        runs: tuple[Path, Path, Path], capsys: pytest.CaptureFixture) -> None:
    """at(c0_3) and the scaled atom's scale are 0 in the `zero` run: their occurrences (and the atom's
    bounds) are recorded all the same, so --set gives the returns of the edited spec's games."""
    _, edited, zero = runs
    con = open_run(zero)
    try:
        paid = dict(con.execute("SELECT term, sum(value) FROM rewards WHERE quantity <> 0 GROUP BY term").fetchall())
    finally:
        con.close()
    assert paid["at(c0_3)"] == 0 and paid["was(c0_2)"] == 0  # they occurred, and paid nothing
    capsys.readouterr()
    argv = ["rewards", str(zero), "--json", *(a for t, v in SETS.items() for a in ("--set", f"{t}={v}"))]
    assert main(argv) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["set"]["at(c0_3)"] == {"old": 0.0, "new": 2.0} and got["set"]["was(c0_2)"] == {"old": 0.0, "new": 3.0}
    assert {r["episode"]: r["rescored"] for r in got["episodes"]} == pytest.approx(returns(edited))


def test_the_table_has_a_column_per_term_and_a_total(runs: tuple[Path, Path, Path],
                                                     capsys: pytest.CaptureFixture) -> None:
    base = runs[0]
    capsys.readouterr()
    assert main(["rewards", str(base)]) == 0
    lines = capsys.readouterr().out.splitlines()
    # the spec's terms in its order (the table's keys, then the scaled atom)
    assert lines[0].split() == ["episode", "agent", "home(me)", "dead(me)", "at(c0_3)", "was(c0_2)", "return"]
    rows = {int(line.split()[0]): [float(x) for x in line.split()[2:]] for line in lines[1:-1]}
    assert {e: r[-1] for e, r in rows.items()} == pytest.approx(returns(base))
    assert all(sum(r[:-1]) == pytest.approx(r[-1]) for r in rows.values())
    total = [float(x) for x in lines[-1].split()[1:]]
    assert lines[-1].startswith("total") and total == pytest.approx([sum(c) for c in zip(*rows.values())])
    capsys.readouterr()
    assert main(["rewards", str(base), "--episode", "0"]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[:2] == ["0", "me"]


def one_error_line(capsys: pytest.CaptureFixture, argv: list[str]) -> str:
    capsys.readouterr()
    assert main(argv) == 1
    out = capsys.readouterr()
    assert out.out == "" and len(out.err.splitlines()) == 1, out
    return out.err


def test_an_unknown_term_is_one_line_with_a_did_you_mean(runs: tuple[Path, Path, Path],
                                                         capsys: pytest.CaptureFixture) -> None:
    err = one_error_line(capsys, ["rewards", str(runs[0]), "--set", "home(m)=2"])
    assert err.startswith("tracelab: error: --set: no reward term 'home(m)' in this run; did you mean home(me)")


def test_a_run_written_before_reward_terms_says_it_has_none(capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    older = older_run(ROOT / "sample_runs" / "base", tmp_path / "older")
    err = one_error_line(capsys, ["rewards", str(older), "--set", "win=1"])
    assert err.startswith("tracelab: error: the run records no reward terms")


def test_rewards_loads_only_duckdb_pyarrow_and_numpy(runs: tuple[Path, Path, Path]) -> None:
    """A reading command (tests/test_reading_imports.py): the spec's values are read from the run's config
    with tomllib and tracelab.expressions, not through the env package (which loads gymnasium)."""
    argv = [["rewards", str(runs[0]), "--set", "was(c0_2)=2", "--set", "at(c0_3)=1"]]
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(HEAVY), json.dumps(argv)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    (report,) = [json.loads(line) for line in out.stdout.splitlines()]
    assert report["status"] == 0 and report["printed"], (report, out.stderr)
    # the runs play wrote are not sealed: their reader reads meta.json (tracelab.store.meta), as every
    # reading command does on such a run
    assert {"duckdb", "pyarrow"} <= set(report["loaded"]) <= ALLOWED | {"tracelab.store.meta"}, report["loaded"]


def without_quantities(run: Path, into: Path) -> Path:
    """`run` as tracelab wrote it before it kept the reward terms' quantities (nor rows of terms worth 0)."""
    shutil.copytree(run, into)
    assert main(["seal", str(into)]) == 0
    con = duckdb.connect(str(into / "run.duckdb"))
    try:
        for (view,) in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal").fetchall():
            con.execute(f'DROP VIEW IF EXISTS "{view}"')  # made again when the run is opened
        con.execute("DELETE FROM raw.reward_terms WHERE value = 0")
        con.execute("ALTER TABLE raw.reward_terms DROP COLUMN quantity")
    finally:
        con.close()
    return into


def test_a_lake_run_rescores_its_zero_terms_and_says_which_never_occurred(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """FrozenLake pays 0 for ice and holes: the random games' --set of both equals the games played with
    those values in its `reward_schedule`; the goal, never reached, re-scores to no change and a note says
    so; a run written before quantities were kept says in one line why it cannot re-score a term worth 0."""
    lake, paid = tmp_path / "lake", tmp_path / "paid"
    assert main(["play", "--env", "tracelab/FrozenLake-v1", "--episodes", "4", "--seed", "0", "--run", str(lake)]) == 0
    assert main(["play", "--env", "tracelab/FrozenLake-v1", "--env-arg", "reward_schedule=[1, -1, -0.01]",
                 "--episodes", "4", "--seed", "0", "--run", str(paid)]) == 0
    capsys.readouterr()
    assert main(["rewards", str(lake), "--json", "--set", "landed(ice)=-0.01", "--set", "landed(hole)=-1",
                 "--set", "landed(goal)=2"]) == 0
    out = capsys.readouterr()
    got = json.loads(out.out)
    assert [r["return"] for r in got["episodes"]] == [0.0] * 4
    assert {r["episode"]: r["rescored"] for r in got["episodes"]} == pytest.approx(returns(paid))
    assert returns(paid) != returns(lake)
    assert "landed(goal) never occurred in the recorded episodes: re-scoring it changes nothing" in got["notes"]
    assert "note: landed(goal) never occurred" not in out.err  # --json carries its notes inside
    older = without_quantities(lake, tmp_path / "older")
    err = one_error_line(capsys, ["rewards", str(older), "--set", "landed(hole)=-1"])
    assert err == ("tracelab: error: --set: landed(hole) is 0 in this run, which was written before tracelab "
                   "recorded the occurrences of terms worth 0: it cannot be re-scored from the record\n")
    capsys.readouterr()
    assert main(["rewards", str(older)]) == 0  # an all-zero run without term rows reads as zero returns
    assert capsys.readouterr().out.splitlines()[-1].split() == ["total", "0"]


def test_gridwar_terms_are_rescored_with_the_specs_values(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A play --scenario run (GridWar through war.toml) names its terms by the spec's reward atoms: re-scoring
    `canAct(Agent)` (each valid action's cost) to -1 and `won(red)` to 100 moves each game's return by the
    occurrences counted in its `rewards` rows; the notes say the win's value is a params expression."""
    run = tmp_path / "g"
    assert main(["play", "--scenario", "base", "--episodes", "3", "--seed", "0", "--run", str(run)]) == 0
    con = open_run(run)
    try:
        acted = {(int(e), str(a)): int(n) for e, a, n in con.execute(
            "SELECT episode, agent, count(*) FILTER (WHERE term = 'canAct(Agent)') FROM rewards GROUP BY ALL"
        ).fetchall()}
    finally:
        con.close()
    capsys.readouterr()
    assert main(["rewards", str(run), "--json", "--set", "canAct(Agent)=-1", "--set", "won(red)=100"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["set"] == {"canAct(Agent)": {"old": -2.0, "new": -1.0}, "won(red)": {"old": 250.0, "new": 100.0}}
    for r in got["episodes"]:
        won = r["by_term"].get("won(red)", 0.0)
        assert won in (0.0, 250.0)
        assert r["rescored"] == pytest.approx(r["return"] + acted[r["episode"], r["agent"]] - 150 * (won > 0))
    assert all(acted.values()) and any("win * reward_scale" in n for n in got["notes"])


def test_a_term_not_counted_where_it_is_worth_0_cannot_be_rescored() -> None:
    """An older GridWar run's `step` term worth 0 kept no count of its occurrences (RuleSim's tracer wrote
    none), so `rewards --set step=V` there says in one line why it cannot re-score it; a term counted at 0
    (a hit worth 0) can be."""
    from tracelab.errors import UserError
    from tracelab.store.reward_rescore import Term, parse_sets

    with pytest.raises(UserError, match="does not count its occurrences where it is worth 0"):
        parse_sets(["step=-1"], [Term("step", 0.0, counted_at_zero=False)])
    assert parse_sets(["hit=5"], [Term("hit", 0.0)]) == {"hit": (0.0, 5.0)}


def test_a_rulesim_run_is_rescored_with_its_scenarios_rewards(capsys: pytest.CaptureFixture) -> None:
    """A run RuleSim's tracer wrote (tests/data/rulesim/base: no spec in it) re-scores its terms from its
    scenario's [rewards], as the war game's registration reads them (world_extras.old_run_terms)."""
    run = Path(__file__).parent / "data" / "rulesim" / "base"
    assert main(["rewards", str(run), "--json", "--set", "step=-1", "--set", "win=100"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["set"] == {"step": {"old": -2.0, "new": -1.0}, "win": {"old": 250.0, "new": 100.0}}
    assert any(n.startswith("step: the step term is not paid") for n in got["notes"])
    for r in got["episodes"]:
        by = r["by_term"]
        assert r["rescored"] == pytest.approx(r["return"] - by.get("step", 0) / 2 - 150 * (by.get("win", 0) > 0))
