"""TraceWriter -> Parquet parts -> open_run, and seal: what goes in comes out, through the readable views,
for a run of the real engine and for synthetic volume."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from store_helpers import (
    WALK_EPISODES,
    WALK_RULES,
    WALK_STEPS,
    synthetic_trace,
    synthetic_vocabulary,
    write_walk_run,
)
from tracelab.engine import Engine, load_program

from tracelab.store.parts import read_manifest
from tracelab.store.reader import open_run, run_info
from tracelab.store.seal import seal_run
from tracelab.store.writer import TraceWriter


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_walk_run(tmp_path_factory.mktemp("store") / "walk")


def reference_trace() -> tuple[Engine, dict[str, np.ndarray]]:
    """The same walk, run again straight from the engine, for comparison with what the store holds."""
    from store_helpers import walk_action
    eng = Engine(load_program(str(WALK_RULES)), worlds=len(WALK_EPISODES))
    move = eng.atom("move", "r1")
    prev = [0] * len(WALK_EPISODES)
    parts = []
    for t in range(WALK_STEPS):
        for w in range(len(WALK_EPISODES)):
            if walk_action(w, t) != prev[w]:
                prev[w] = walk_action(w, t)
                eng.add_fact(move, float(prev[w]), float(prev[w]), world=w)
        eng.step()
        parts.append(eng.take_trace())
    return eng, {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def test_every_engine_row_is_stored_with_its_episode_names_and_cause(walk: Path) -> None:
    eng, tr = reference_trace()
    con = open_run(walk)
    rows = con.execute("SELECT episode, world, t, pass_no, atom, old_lower, old_upper, new_lower, new_upper, "
                       "rule, grounding FROM changes ORDER BY seq").fetchall()
    assert len(rows) == len(tr["t"])
    for i, r in enumerate(rows):
        w = int(tr["world"][i])
        assert r[0] == WALK_EPISODES[w] and r[1] == w
        assert r[2:4] == (int(tr["t"][i]), int(tr["pass_no"][i]))
        assert r[4] == eng.atom_text(int(tr["atom"][i]))
        assert r[5:9] == tuple(float(tr[c][i]) for c in ("old_lower", "old_upper", "new_lower", "new_upper"))
        expected = eng.cause_name(int(tr["cause_kind"][i]), int(tr["cause_id"][i]))
        assert r[9] == ("action" if expected == "external" else expected)
        assert r[10] == int(tr["grounding"][i])


def test_firings_carry_the_grounding_bindings(walk: Path) -> None:
    eng, tr = reference_trace()
    con = open_run(walk)
    got = con.execute("SELECT rule, bindings, head, grounding FROM firings ORDER BY seq").fetchall()
    rule_rows = np.flatnonzero(tr["cause_kind"] == 2)
    assert len(got) == len(rule_rows)
    for (rule, bindings, head, g), i in zip(got, rule_rows):
        assert rule == eng.rules[int(tr["cause_id"][i])].name
        assert bindings == eng.grounding_text(int(tr["grounding"][i]))
        assert head == eng.atom_text(int(tr["atom"][i])) and g == int(tr["grounding"][i])


def test_program_episodes_steps_metrics_and_run_metadata(walk: Path) -> None:
    con = open_run(walk)
    rules = con.execute("SELECT name, delay, immediate, body, line FROM rules ORDER BY rule").fetchall()
    assert [r[0] for r in rules] == ["go", "leave", "near", "alarm"]
    assert rules[0][1:4] == (1, False, "at(A,X):[1,1], edge(X,Y):[1,1], move(A):[1,1]")
    assert rules[3][2] is True and rules[3][4] == 16
    assert con.execute("SELECT count(*) FROM facts").fetchone()[0] == 6
    eps = con.execute("SELECT episode, world, outcome, steps, reward, ended, rewards FROM episodes "
                      "ORDER BY episode").fetchall()
    assert [e[:6] for e in eps] == [(10, 0, "win", 6, 250.0, True), (11, 1, "truncated", 6, -12.0, True),
                                    (12, 2, "loss", 6, -12.0, True)]
    assert json.loads(eps[0][6]) == {"r1": 1.0}
    steps = con.execute("SELECT step, action, obs, truncated FROM steps WHERE episode = 12 ORDER BY step").fetchall()
    assert [s[1] for s in steps] == [0, 1, 1, 1, 1, 1] and steps[3][2] == [3.0, 2.0]
    assert con.execute("SELECT bool_or(truncated) FROM steps WHERE episode = 11").fetchone()[0] is True
    assert con.execute("SELECT count(*), count(DISTINCT name) FROM metrics").fetchone() == (12, 2)
    run = con.execute("SELECT command, scenario, seed, status, rule_files, config FROM run").fetchone()
    assert run[:4] == ("pytest walk", "walk", 7, "finished")
    assert json.loads(run[4])[0]["sha256"] and json.loads(run[5]) == {"worlds": 3}
    assert run_info(walk).meta["versions"]["duckdb"]


def test_sealed_run_answers_every_view_like_the_live_one(tmp_path: Path) -> None:
    run = write_walk_run(tmp_path / "walk")
    views = ["changes", "firings", "episodes", "steps", "metrics", "rules", "facts", "atoms", "groundings"]
    live = open_run(run)
    before = {v: live.execute(f"SELECT * FROM {v} ORDER BY ALL").fetchall() for v in views}
    live.close()
    sealed = seal_run(run)
    assert sealed == run / "run.duckdb" and not (run / "parts").exists()
    for con in (open_run(run), open_run(sealed)):  # the directory or the lone file
        for v in views:
            assert con.execute(f"SELECT * FROM {v} ORDER BY ALL").fetchall() == before[v], v
        assert con.execute("SELECT status FROM run").fetchone()[0] == "finished"
    assert seal_run(run) == sealed  # idempotent


def test_vocabulary_grows_incrementally_and_ids_are_checked(tmp_path: Path) -> None:
    vocab = synthetic_vocabulary(n_nodes=8, n_atoms=100)
    with TraceWriter(tmp_path / "grow") as w:
        w.write_vocabulary(vocab)
        w.begin_episode(0)
        w.write_changes(0, synthetic_trace(50, n_atoms=100))
        with pytest.raises(ValueError, match="atom id 150.*100 atoms"):
            bad = synthetic_trace(5, n_atoms=100)
            bad["atom"][2] = 150
            w.write_changes(0, bad)
        bigger = synthetic_vocabulary(n_nodes=8, n_atoms=200)
        bigger["nodes"] = [*vocab["nodes"], "extra"]
        w.write_vocabulary(bigger)
        w.write_vocabulary(bigger)  # nothing new: nothing written
        w.write_changes(0, synthetic_trace(50, n_atoms=200, t0=10))
        with pytest.raises(ValueError, match="shrank"):
            w.write_vocabulary(vocab)
        w.end_episode(0, steps=1, outcome="draw")
    con = open_run(tmp_path / "grow")
    assert con.execute("SELECT count(*) FROM raw.atoms").fetchone()[0] == 200
    assert con.execute("SELECT count(*), count(DISTINCT atom) FROM raw.atoms").fetchone() == (200, 200)
    assert con.execute("SELECT name FROM raw.nodes WHERE node = 8").fetchone()[0] == "extra"
    assert con.execute("SELECT count(*) FROM changes WHERE atom IS NULL").fetchone()[0] == 0


def test_trace_input_is_checked_and_errors_name_the_value(tmp_path: Path) -> None:
    with TraceWriter(tmp_path / "bad") as w:
        w.write_vocabulary(synthetic_vocabulary())
        rows = synthetic_trace(10)
        with pytest.raises(KeyError, match="'cause_kind'"):
            w.write_changes(0, {k: v for k, v in rows.items() if k != "cause_kind"})
        with pytest.raises(ValueError, match="differ in length.*'t': 9"):
            w.write_changes(0, {**rows, "t": rows["t"][:9]})
        with pytest.raises(ValueError, match="cause_kind 7"):
            w.write_changes(0, {**rows, "cause_kind": np.full(10, 7, np.int8)})
        with pytest.raises(ValueError, match="grounding id 3"):
            w.write_changes(0, {**rows, "grounding": np.full(10, 3, np.int32)})
        with pytest.raises(ValueError, match="world 5.*2 entries"):
            w.write_changes([0, 1], {**rows, "world": np.full(10, 5, np.int32)})
        with pytest.raises(ValueError, match="episode 4 is not open"):
            w.end_episode(4, steps=1, outcome="win")
        w.begin_episode(4)
        with pytest.raises(ValueError, match="episode 4 was already begun"):
            w.begin_episode(4)
        with pytest.raises(TypeError, match="metric 'loss'"):
            w.write_metrics(1, {"loss": "high"})
        assert w.write_changes(None, {**rows, "episode": np.arange(10)}) == 10
    con = open_run(tmp_path / "bad")
    assert con.execute("SELECT count(DISTINCT episode) FROM changes").fetchone()[0] == 10


def test_episode_ids_by_world_and_part_compaction(tmp_path: Path) -> None:
    vocab = synthetic_vocabulary()
    with TraceWriter(tmp_path / "many", part_rows=500, compact_files=3) as w:
        w.write_vocabulary(vocab)
        for step in range(20):
            rows = synthetic_trace(120, t0=step * 12, seed=step)
            rows["world"] = (np.arange(120) % 3).astype(np.int32)
            w.write_changes(np.array([100, 200, 300]) + step // 10, rows)
            w.flush()  # one part per step, so compaction has work
        stats = w.stats()
    assert stats["compactions"] > 0
    con = open_run(tmp_path / "many")
    n, distinct = con.execute("SELECT count(*), count(DISTINCT seq) FROM raw.changes").fetchone()
    assert n == distinct == 2400
    per_ep = dict(con.execute("SELECT episode, count(*) FROM changes GROUP BY 1").fetchall())
    assert per_ep == {100: 400, 200: 400, 300: 400, 101: 400, 201: 400, 301: 400}
    assert con.execute("SELECT count(*) FROM changes WHERE episode // 100 - 1 <> world").fetchone()[0] == 0
    assert len(read_manifest(tmp_path / "many")["changes"]) < 20


def test_writer_refuses_an_existing_run_and_records_failure(tmp_path: Path) -> None:
    run = tmp_path / "r"
    with pytest.raises(ZeroDivisionError):
        with TraceWriter(run) as w:
            w.write_vocabulary(synthetic_vocabulary())
            w.begin_episode(0)
            w.write_changes(0, synthetic_trace(10))
            raise ZeroDivisionError  # the program writing the run fails
    assert run_info(run).status == "failed"
    assert open_run(run).execute("SELECT count(*) FROM changes").fetchone()[0] == 10
    with pytest.raises(FileExistsError, match="already holds a run"):
        TraceWriter(run)
    with pytest.raises(RuntimeError, match="closed"):
        w.write_changes(0, synthetic_trace(1))
    with pytest.raises(FileNotFoundError, match="rule file"):
        TraceWriter(tmp_path / "r2", {"rule_files": ["nope.rules"]})
    with pytest.raises(ValueError, match="unknown run metadata"):
        TraceWriter(tmp_path / "r3", {"colour": "red"})


def test_open_run_errors_name_the_path(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no run 'nowhere'"):
        open_run("nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="not a tracelab run"):
        open_run(tmp_path / "empty")
