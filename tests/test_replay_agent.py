"""The replay's plots of the agent's half (viewers/replay/agent_plots.py), read back from rerun's own
recording of a real traced evaluation game (sample_runs/base-train): a series per action named by it,
whose values are the run's `decisions` at each step, and each agent's return by reward term stacked, its
top line the running sum of `steps.reward`."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from test_replay import read_rrd

from tracelab.cli import main
from tracelab.store.reader import open_run

ROOT = Path(__file__).resolve().parent.parent
TRAINED = ROOT / "sample_runs" / "base-train"
SCALARS = "Scalars:scalars"


def series(rows: list[dict]) -> tuple[str, dict[int, float]]:
    """A series' name (its static row) and its value at each step."""
    name = next(r["SeriesLines:names"][0] for r in rows if r.get("SeriesLines:names"))
    return name, {r["step"]: r[SCALARS][0] for r in rows if r.get(SCALARS) is not None}


def test_action_values_and_the_return_by_term_of_a_traced_evaluation(tmp_path: Path) -> None:
    con = open_run(TRAINED)
    try:
        episode = con.execute("SELECT min(episode) FROM decisions").fetchall()[0][0]
        decided = con.execute("SELECT s.t, d.agent, d.actions, d.\"values\" FROM decisions d "
                              "JOIN steps s USING (episode, step, agent) WHERE d.episode = ?", [episode]).fetchall()
        steps = con.execute("SELECT agent, t, reward FROM steps WHERE episode = ? ORDER BY agent, t",
                            [episode]).fetchall()
        terms = con.execute("SELECT r.agent, r.term, s.t, r.value FROM rewards r JOIN steps s "
                            "USING (episode, step, agent) WHERE r.episode = ?", [episode]).fetchall()
    finally:
        con.close()
    assert decided and terms
    out = tmp_path / "eval.rrd"
    assert main(["replay", str(TRAINED), "--episode", str(episode), "--save", str(out)]) == 0
    (entities,) = read_rrd(out).values()

    # a series per action of each deciding agent, named by the action, its values the decisions'
    want: dict[str, dict[int, float]] = {}
    for t, agent, actions, values in decided:
        for action, value in zip(actions, values):
            want.setdefault(f"/values/{agent}/{action}", {})[t] = value
    got = {path: series(rows) for path, rows in entities.items() if path.startswith("/values/")}
    assert set(got) == set(want)
    for path, (name, values) in got.items():
        assert name == path.rsplit("/", 1)[1]
        assert values == want[path]

    # per deciding agent (red: blue is the scripted opponent, its terms not stacked): the stacked lines
    # step up by each term's running return; the top one is the return
    deciders = {agent for _, agent, _, _ in decided}
    assert {path.split("/")[2] for path in entities if path.startswith("/terms/")} == deciders
    for agent in deciders:
        ts = [t for a, t, _ in steps if a == agent]
        ret = np.cumsum([r for a, _, r in steps if a == agent])
        # an entity path's part escapes rerun's special characters (a term `won(blue)` is `won\(blue\)`)
        mine = {re.sub(r"\\(.)", r"\1", path.rsplit("/", 1)[1]): series(rows)[1] for path, rows in entities.items()
                if path.startswith(f"/terms/{agent}/")}
        assert np.allclose([mine["return"][t] for t in ts], ret)
        own = {term: np.cumsum([sum(v for a, k, tt, v in terms if a == agent and k == term and tt == t)
                                for t in ts]) for term in {k for a, k, _, _ in terms if a == agent}}
        assert set(mine) == {*own, "return"}
        below = np.zeros(len(ts))
        for term in sorted(own, key=lambda k: (-abs(own[k][-1]), k)):   # the largest term at the bottom
            line = np.asarray([mine[term][t] for t in ts])
            assert np.allclose(line - below, own[term]), term
            below = line
