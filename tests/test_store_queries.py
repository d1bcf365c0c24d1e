"""The saved queries (tracelab/queries/*.sql): every one runs with its defaults, and the game ones count
what a hand-made grid-world trace says they should."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from store_helpers import write_walk_run

from tracelab.store.diff import first_divergence
from tracelab.store.queries import list_queries
from tracelab.store.reader import open_run, query_readonly
from tracelab.store.writer import TraceWriter


def run_query(con, name: str, **params: object) -> list[tuple]:  # noqa: ANN001
    q = next(q for q in list_queries() if q.name == name)
    return query_readonly(con, q.sql, q.bind({k: str(v) for k, v in params.items()})).fetchall()


def test_every_saved_query_runs_with_its_defaults(tmp_path: Path) -> None:
    con = open_run(write_walk_run(tmp_path / "walk"))
    names = [q.name for q in list_queries()]
    assert {"firings_per_episode", "rule_coverage", "episode_summary", "actions_per_win",
            "steps_before_loss", "learner_events", "hid_behind_mountain"} <= set(names)
    for q in list_queries():
        assert q.description, q.name
        query_readonly(con, q.sql, q.bind({})).fetchall()


def test_generic_queries_on_the_walk_run(tmp_path: Path) -> None:
    con = open_run(write_walk_run(tmp_path / "walk"))
    firings = run_query(con, "firings_per_episode")
    direct = con.execute("SELECT episode, rule, count(*) FROM changes WHERE cause_kind = 2 "
                         "GROUP BY ALL").fetchall()
    assert sorted((e, r, n) for e, r, n, *_ in firings) == sorted(direct)
    coverage = {r[0]: r[3] for r in run_query(con, "rule_coverage")}
    assert coverage == {"near": 7, "go": 5, "leave": 5, "alarm": 2}
    assert run_query(con, "actions_per_win") == [(1, 6.0, 1, 6.0)]
    before = run_query(con, "steps_before_loss", n=2)
    assert [(r[0], r[1], r[4]) for r in before] == [(12, 4, 1), (12, 5, 1)]
    summary = {r[0]: r[2:8] for r in run_query(con, "episode_summary")}
    assert summary[11] == ("truncated", 6, -12.0, 7, 1, 0)


def test_actions_per_win_counts_only_the_won_games_whose_steps_were_recorded() -> None:
    """A training run traces a few evaluation games among thousands: an untraced win has no step rows,
    and counting it as 0 actions made base-train's figure 0.2 actions a win (it is about 30)."""
    con = open_run(Path(__file__).resolve().parents[1] / "sample_runs" / "base-train")
    (wins, _, traced, per_win), = run_query(con, "actions_per_win", learner="red-agent-%")
    counts = [n for _, n in con.execute(
        "SELECT e.episode, count(*) FROM episodes e JOIN steps s ON s.episode = e.episode "
        "WHERE e.outcome = 'win' AND s.agent LIKE 'red-agent-%' GROUP BY e.episode").fetchall()]
    assert 0 < traced == len(counts) < wins
    assert per_win == pytest.approx(sum(counts) / len(counts))


# ---- a hand-made grid-world trace: 8 wide, a mountain at cell 19 (x=3, y=2) ---------------------------

class Vocab:
    def __init__(self) -> None:
        self.nodes: list[str] = []
        self.labels = ["atLoc", "mountain", "gotShot", "unsafe", "invalid"]
        self.arity = [2, 1, 1, 1, 1]
        self.atoms: list[tuple[int, int, int]] = []

    def node(self, name: str) -> int:
        if name not in self.nodes:
            self.nodes.append(name)
        return self.nodes.index(name)

    def atom(self, label: str, *args: str) -> int:
        key = (self.labels.index(label), self.node(args[0]), self.node(args[1]) if len(args) > 1 else -1)
        if key not in self.atoms:
            self.atoms.append(key)
        return self.atoms.index(key)

    def arrays(self) -> dict[str, object]:
        a = np.array(self.atoms, np.int32).reshape(-1, 3)
        return {"nodes": self.nodes, "labels": self.labels, "label_arity": np.array(self.arity, np.int8),
                "atom_label": a[:, 0], "atom_arg0": a[:, 1], "atom_arg1": a[:, 2]}


def rows(v: Vocab, changes: list[tuple[int, str, tuple[str, ...], float]]) -> dict[str, np.ndarray]:
    """(t, label, args, value) -> trace arrays; value 1 sets [1,1], 0 sets [0,0]; all caused by actions."""
    n = len(changes)
    new = np.array([c[3] for c in changes], float)
    return {"world": np.zeros(n, np.int32), "t": np.array([c[0] for c in changes], np.int32),
            "pass_no": np.zeros(n, np.int32),
            "atom": np.array([v.atom(c[1], *c[2]) for c in changes], np.int32),
            "old_lower": 1 - new, "old_upper": 1 - new, "new_lower": new, "new_upper": new,
            "cause_kind": np.ones(n, np.int8), "cause_id": np.arange(n, dtype=np.int32),
            "grounding": np.full(n, -1, np.int32), "n_sources": np.ones(n, np.int16)}


@pytest.fixture(scope="module")
def game(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201 - a duckdb connection
    red, blue = "red-agent-1", "blue-agent-1"
    v = Vocab()
    ep1 = rows(v, [
        (0, "mountain", ("19",), 1), (0, "atLoc", (red, "18"), 1), (0, "atLoc", (blue, "21"), 1),  # hidden
        (1, "atLoc", (blue, "21"), 0), (1, "atLoc", (blue, "29"), 1),          # blue leaves the row
        (1, "gotShot", (red,), 1), (1, "invalid", (blue,), 1),
        (2, "atLoc", (red, "18"), 0), (2, "atLoc", (red, "10"), 1),            # red steps down
        (2, "atLoc", (blue, "29"), 0), (2, "atLoc", (blue, "21"), 1),
        (2, "gotShot", (red,), 0), (2, "unsafe", (red,), 1),
        (3, "atLoc", (red, "10"), 0), (3, "atLoc", (red, "18"), 1),            # hidden again
        (3, "gotShot", (red,), 1), (3, "unsafe", (red,), 0),
        (4, "atLoc", (blue, "21"), 0), (4, "atLoc", (blue, "26"), 1),          # blue above red: seen
    ])
    ep2 = rows(v, [(0, "mountain", ("19",), 1), (0, "atLoc", (red, "2"), 1), (0, "atLoc", (blue, "21"), 1),
                   (1, "atLoc", (red, "2"), 0), (1, "atLoc", (red, "3"), 1)])
    run = tmp_path_factory.mktemp("game") / "game"
    with TraceWriter(run) as w:
        w.write_vocabulary(v.arrays())
        for e, tr, outcome in ((1, ep1, "loss"), (2, ep2, "win"), (3, ep2, "win")):
            w.begin_episode(e, t_start=0)
            w.write_changes(e, tr)
            w.end_episode(e, steps=5, outcome=outcome)
    return open_run(run)


def test_learner_events_count_shots_unsafe_and_invalid_of_the_learner_only(game) -> None:  # noqa: ANN001
    got = run_query(game, "learner_events")
    assert got == [(1, "loss", 5, 2, 1, 0), (2, "win", 5, 0, 0, 0), (3, "win", 5, 0, 0, 0)]
    # parametrised by label names: count blue's invalid actions instead
    assert run_query(game, "learner_events", learner="blue-agent-%")[0][3:] == (0, 0, 1)


def test_hid_behind_mountain_counts_timesteps_with_a_mountain_between(game) -> None:  # noqa: ANN001
    assert run_query(game, "hid_behind_mountain") == [(1, "loss", 5, 2), (2, "win", 5, 0), (3, "win", 5, 0)]
    # with a wider grid the cell numbers mean other places: no longer on one row
    assert run_query(game, "hid_behind_mountain", width=10)[0][3] == 0


def test_diff_of_identical_episodes(game) -> None:  # noqa: ANN001
    d = first_divergence(game, 2, 3)
    assert d.identical and d.rel_t is None
    d = first_divergence(game, 1, 2)
    assert d.rel_t == 0 and {r["atom"] for r in d.only_in_a} == {"atLoc(red-agent-1,18)"}


def test_hid_behind_mountain_reads_a_spec_runs_cell_names() -> None:
    """A spec run names its cells c{row}_{col} and states its mountains as static facts of the board:
    sample_runs/base, episode 0, t=49 and 50, red on c5_3 below the mountain c4_3 with blue further up
    column 3 (it read 0 everywhere while it took cells for y * 8 + x). RuleSim's numbered cells read as
    before."""
    root = Path(__file__).resolve().parents[1]
    spec_run = open_run(root / "sample_runs" / "base")
    assert run_query(spec_run, "hid_behind_mountain") == [(0, "loss", 74, 2), (1, "loss", 34, 0), (2, "loss", 17, 0)]
    rulesim = open_run(root / "tests" / "data" / "rulesim" / "base")
    assert run_query(rulesim, "hid_behind_mountain") == [(0, "win", 21, 0), (1, "win", 24, 0), (2, "win", 17, 0)]
