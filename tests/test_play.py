"""`tracelab play`: traced games through the vector env and StoreSink into a real trace-store run."""
from __future__ import annotations

from tracelab.cli import main
from tracelab.store import open_run
from tracelab.store.why import explain, render_why


def test_play_records_episodes_changes_steps_and_explains_a_position(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["play", "--scenario", "advanced", "--episodes", "3", "--worlds", "2", "--seed", "4",
                 "--run", str(run)]) == 0
    out = capsys.readouterr().out
    assert "played 3 episodes" in out and f"tracelab why {run}" in out
    assert f"tracelab tui {run}" in out and f"tracelab replay {run} --episode 0" in out
    con = open_run(run)
    ended = con.execute("SELECT count(*) FROM episodes WHERE outcome IN ('win','loss','draw','truncated')"
                        ).fetchone()[0]
    assert ended == 3 == con.execute("SELECT count(*) FROM episodes").fetchone()[0]
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
