"""`tracelab replay` of GridWar's games, headless, on the one path every run takes (the sample runs, played
through rules/gridworld/war*.toml and drawn on its `[board]`): .rrd files checked with rerun's own
CLI and read back through rerun's chunk reader (entity paths, steps, fired-rule lines, agent positions
against the run's steps rows, lanes, why documents), a training run per the training-run contract, --live
on a run being written, and a golden file.

The golden file: regenerate it (after an intended change) with
    tracelab replay sample_runs/base --episode 2 --why-depth 2 --save tests/data/replay_golden.rrd
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader
from tracelab.viewers.replay.outputs import rerun_cli

from tracelab.cli import main
from tracelab.store.reader import open_run
from tracelab.store.coordinates import run_grid
from tracelab.store.why import explain, render_why

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "sample_runs"
GOLDEN = ROOT / "tests" / "data" / "replay_golden.rrd"


def read_rrd(path: Path) -> dict[str, dict[str, list[dict]]]:
    """recording id -> entity path -> rows (column name -> value), timed rows in time order."""
    reader = RrdReader(path)
    out: dict[str, dict[str, list[dict]]] = {}
    for store in reader.recordings():
        entities: dict[str, list[dict]] = {}
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            cols = {name: batch.column(name).to_pylist() for name in batch.schema.names}
            rows = entities.setdefault(chunk.entity_path, [])
            rows += [{k: v[i] for k, v in cols.items()} for i in range(batch.num_rows)]
        for rows in entities.values():
            rows.sort(key=lambda r: r.get("step", -1))
        out[store.recording_id] = entities
    return out


def latest_at(rows: list[dict], step: int, column: str) -> object:
    """The value of `column` in force at `step` on the step timeline (the last row at or before it)."""
    value = None
    for r in rows:
        if r.get("step") is not None and r["step"] <= step and r.get(column) is not None:
            value = r[column]
    return value


def replay(*args: str) -> int:
    return main(["replay", *map(str, args)])


@pytest.fixture(scope="module")
def advanced(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "advanced.rrd"
    assert replay(SAMPLES / "advanced", "--save", path) == 0
    return path


@pytest.fixture(scope="module")
def advanced_data(advanced: Path) -> dict[str, dict[str, list[dict]]]:
    return read_rrd(advanced)


def test_one_recording_per_played_episode_that_rerun_verifies(advanced, advanced_data) -> None:
    assert sorted(advanced_data) == [f"advanced/episode-{e}" for e in range(3)]   # 3 played, 1 aborted
    verify = subprocess.run([rerun_cli(), "rrd", "verify", str(advanced)], capture_output=True, text=True, check=False)
    assert verify.returncode == 0, verify.stderr
    stats = subprocess.run([rerun_cli(), "rrd", "stats", str(advanced)], capture_output=True, text=True, check=False)
    assert stats.returncode == 0 and "/board/agents/red-agent-1" in stats.stdout


def test_entity_paths_and_steps(advanced_data) -> None:
    ep2 = advanced_data["advanced/episode-2"]
    for path in ("/board/terrain", "/board/agents/red-agent-1",       # war.toml's [board] pieces
                 "/board/agents/blue-agent-1", "/board/bullets/red-bullet-1-1", "/board/bullets/blue-bullet-1-1",
                 "/board/fired", "/rules/log", "/why", "/plots/changed/atLoc",
                 "/lanes/alive/red-agent-1", "/lanes/atLoc/red-agent-1", "/plots/return/red-agent-1",
                 "/plots/reward/red-agent-1"):
        assert path in ep2, path
    assert [r["step"] for r in ep2["/why"]] == list(range(15))                   # steps 0..14
    assert max(r["step"] for r in ep2["/rules/log"]) == 14
    assert not any(p.startswith(("/train", "/graph")) for p in ep2)             # no training, no graph drawn


def test_the_return_plots_are_the_steps_rows_in_the_pieces_colours(advanced_data) -> None:
    ep0 = advanced_data["advanced/episode-0"]
    con = open_run(SAMPLES / "advanced")
    for agent, colour in (("red-agent-1", (0xe6, 0x39, 0x46)),):   # the learner's steps (blue is the spec's script)
        rows = con.execute("SELECT t, reward FROM steps WHERE episode = 0 AND agent = ? ORDER BY t", [agent]).fetchall()
        returns = [(r["step"], r["Scalars:scalars"][0]) for r in ep0[f"/plots/return/{agent}"] if "step" in r]
        assert returns[-1] == (rows[-1][0], pytest.approx(sum(w for _, w in rows)))
        style = next(r for r in ep0[f"/plots/return/{agent}"] if r.get("SeriesLines:colors"))
        assert style["SeriesLines:colors"][0] == int.from_bytes(bytes([*colour, 255]), "big")   # war.toml's


def test_the_fired_rule_log_of_a_known_step(advanced_data) -> None:
    """Advanced episode 2, step 14: blue's bullet hits red on c6_3 and red dies."""
    log = [r for r in advanced_data["advanced/episode-2"]["/rules/log"] if r["step"] == 14]
    con = open_run(SAMPLES / "advanced")
    n = con.execute("SELECT count(*) FROM firings WHERE episode = 2 AND t = 14").fetchall()[0][0]
    assert len(log) == n
    lines = [(r["TextLog:level"][0], r["TextLog:text"][0]) for r in log]
    hit = ("b_hit", "b_hit(B=blue-bullet-1-2, A=red-agent-1, Y=c6_3): "
                    "struck(blue-bullet-1-2,red-agent-1) [0,1] -> [1,1]")
    death = ("d_killed", "d_killed(A=red-agent-1): alive(red-agent-1) [1,1] -> [0,0]")
    end = ("g_eliminated", "g_eliminated(T=red, A=red-agent-1): eliminated(red) [0,1] -> [1,1]")
    assert lines.index(hit) < lines.index(death) < lines.index(end)   # in the engine's order


def test_the_struck_cell_is_marked_with_the_rule(advanced_data) -> None:
    """war.toml's `annotate`: at step 14 the hit, the kill and the death on red's cell c6_3 (row 6, column
    3: the box at (3.5, 6.5)), the cell the bullet left (c5_3) beside it; nothing is drawn past the
    episode's last step."""
    ep2 = advanced_data["advanced/episode-2"]
    fired = {r["step"]: r for r in ep2["/board/fired"]}
    assert fired[14]["Boxes2D:centers"] == [[3.5, 6.5], [3.5, 5.5]]
    assert fired[14]["Boxes2D:labels"][0].split("\n")[:3] == ["b_hit", "h_killed", "d_killed"]
    assert max(fired) == 14
    # the bullet that hit flew down from c5_3 at step 13 and is off the board at 14
    bullet = ep2["/board/bullets/blue-bullet-1-2"]
    np.testing.assert_allclose(latest_at(bullet, 13, "Arrows2D:origins"), [[3.5, 5.2]], atol=1e-5)
    np.testing.assert_allclose(latest_at(bullet, 13, "Arrows2D:vectors"), [[0.0, 0.6]], atol=1e-5)
    assert [r.get("Arrows2D:origins") for r in bullet if r.get("step") == 14] == [[]]


@pytest.mark.parametrize("run", ["advanced", "nonmarkov"])
def test_agent_positions_agree_with_the_runs_steps_rows(run: str, tmp_path: Path) -> None:
    path = tmp_path / f"{run}.rrd"
    assert replay(SAMPLES / run, "--save", path) == 0
    data = read_rrd(path)
    con = open_run(SAMPLES / run)
    config = json.loads(con.execute("SELECT config FROM run").fetchall()[0][0])
    height = int(next(line for line in config["scenario"].splitlines() if line.startswith("height")).split("=")[1])
    rows = con.execute("SELECT episode, step, obs FROM steps WHERE agent = 'red-agent-1' ORDER BY 1, 2").fetchall()
    agents = sorted({a for (a,) in con.execute("SELECT DISTINCT agent FROM steps").fetchall()},
                    key=lambda a: (not a.startswith("red"), a))
    checked = 0
    for episode, step, obs in rows:
        entities = data[f"{run}/episode-{episode}"]
        xy = np.asarray(obs[:2 * len(agents)]).reshape(-1, 2)
        for agent, (x, y) in zip(agents, xy.tolist()):
            agent_rows = entities[f"/board/agents/{agent}"]
            label = latest_at(agent_rows, step, "Points2D:labels")[0]
            if x < 0:                                   # dead: observed at (-1, -1)
                assert label.endswith("dead")
                continue
            px, py = latest_at(agent_rows, step, "Points2D:positions")[0]
            assert (px - 0.5, height - 0.5 - py) == (x, y), (episode, step, agent)
            checked += 1
    assert checked > 20


def test_lanes_and_the_why_document_of_a_death(advanced_data) -> None:
    ep2 = advanced_data["advanced/episode-2"]
    alive = [(r["step"], r["StateChange:state"]) for r in ep2["/lanes/alive/red-agent-1"] if "step" in r]
    assert alive == [(0, ["true"]), (14, ["false"])]
    where = [r["StateChange:state"][0] for r in ep2["/lanes/atLoc/red-agent-1"] if "step" in r]
    assert where[0] == "c7_7"                                        # red's base, the spec's cell name
    doc = ep2["/why"][14]["TextDocument:text"][0]
    con = open_run(SAMPLES / "advanced")
    tree = render_why(explain(con, 2, "alive(red-agent-1)", 14), 14, run_grid(con))
    assert "### Why alive(red-agent-1)" in doc and tree in doc       # as `tracelab why` prints it
    assert "It ended: loss" in doc
    # the death's why before the step's long tallies: the panel's first screen shows it (docs/images/replay.png)
    assert doc.index("### Why alive(red-agent-1)") < doc.index("- changed: ") < doc.index("- fired: ")
    assert "### Why" not in ep2["/why"][3]["TextDocument:text"][0]   # nobody died in step 3


def test_why_names_any_atom_of_a_game(tmp_path: Path) -> None:
    out = tmp_path / "why.rrd"
    assert replay(SAMPLES / "advanced", "--episode", "2", "--why", "eliminated(red)", "--save", out) == 0
    docs = [r["TextDocument:text"][0] for r in read_rrd(out)["advanced/episode-2"]["/why"]]
    con = open_run(SAMPLES / "advanced")
    assert render_why(explain(con, 2, "eliminated(red)", 14), 14, run_grid(con)) in docs[14]
    assert "### Why eliminated(red)" in docs[3]                     # never set until step 14, shown each step


def test_episode_selection_and_user_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sel.rrd"
    assert replay(SAMPLES / "base", "--episodes", "0-1", "--save", out) == 0
    assert sorted(read_rrd(out)) == ["base/episode-0", "base/episode-1"]
    assert replay(SAMPLES / "advanced", "--outcome", "loss", "--limit", "1", "--save", out) == 0
    assert sorted(read_rrd(out)) == ["advanced/episode-0"]
    capsys.readouterr()
    assert replay(SAMPLES / "base", "--episode", "0", "--lanes", "alive,won", "--save", out) == 0
    assert sorted(p for p in read_rrd(out)["base/episode-0"] if p.startswith("/lanes/")) == [
        "/lanes/alive/blue-agent-1", "/lanes/alive/red-agent-1", "/lanes/won/blue"]   # any predicate of the run
    for bad in (["--episode", "9"], ["--episodes", "3-x"], ["--outcome", "tie"], ["--lanes", "alive,mood"]):
        assert replay(SAMPLES / "advanced", *bad, "--save", tmp_path / "bad.rrd") == 1
        err = capsys.readouterr().err
        assert err.startswith("tracelab: error: ") and err.count("\n") == 1, err
    assert replay(tmp_path / "no-such-run", "--save", out) == 1


def _write_training_run(run_dir: Path) -> None:
    """A run following the training-run contract, as the trainer writes it through the spec path
    (tracelab/train/external_eval.py): traced eval games of GridWar's advanced spec (begin info
    kind=eval, episode ids from the training's run), an untraced training episode, and metrics."""
    from tracelab import RULES_DIR
    from tracelab.envs.declared.gym_env import DeclaredEnv
    from tracelab.envs.declared.play import play_episodes, random_policy
    from tracelab.envs.declared.recording import declared_run_config
    from tracelab.envs.declared.spec import load_spec
    from tracelab.store import TraceWriter

    spec = load_spec(RULES_DIR / "gridworld" / "war.toml", advanced=True)
    writer = TraceWriter.open(run_dir, {"command": "tracelab train --test", "scenario": "war.toml", "seed": 0,
                                        "config": {"steps": 300, **declared_run_config(spec)}})
    ids = iter(range(1000))
    env = DeclaredEnv(spec, trace_writer=writer, trace_episode_ids=lambda: next(ids))
    for episode in range(2):
        env.trace_info({"kind": "eval", "train_step": 100 * (episode + 1), "eval_round": episode, "opponent_p": 0.3})
        play_episodes(env, 1, 4 + episode, random_policy(env, episode))
    env.close()  # the recorder writes what it kept; the run stays open (trace_episode_ids)
    writer.begin_episode(1000, info={"kind": "train", "train_step": 50})
    writer.end_episode(1000, steps=12, outcome="loss", reward=-260.0)
    for step in (100, 200, 300):
        writer.write_metrics(step, {"loss": 1.0 / step, "epsilon": 1 - step / 400, "eval/win_rate@p0.3": step / 300})
    writer.close()


def test_a_training_run_replays_its_eval_games_on_the_step_timeline_only(tmp_path: Path) -> None:
    """The eval games, everything on `step`: its metrics on a `train_step` timeline were a Training panel
    that stood empty under the time panel's `step` (rerun plots the active timeline only)."""
    _write_training_run(tmp_path / "train")
    out = tmp_path / "train.rrd"
    assert replay(tmp_path / "train", "--save", out) == 0
    data = read_rrd(out)
    assert sorted(data) == ["train/episode-0", "train/episode-1"]              # the eval games only
    entities = data["train/episode-0"]
    assert "/board/agents/red-agent-1" in entities and "/why" in entities
    timed = {k for rows in entities.values() for r in rows for k, v in r.items() if v is not None}
    assert "train_step" not in timed and not any(p.startswith("/train") for p in entities)
    for episode, train_step in (("train/episode-0", 100), ("train/episode-1", 200)):   # what it shows of them
        docs = [r["TextDocument:text"] for r in data[episode]["/why"] if r.get("step") is not None]
        assert all(f"an evaluation game of the training, at train step {train_step}, round" in d[0] for d in docs)
        assert all("opponent p=0.3 (its curves" in d[0] for d in docs)  # the level such an older run recorded


def test_live_follows_a_run_being_written(tmp_path: Path) -> None:
    run_dir, out = tmp_path / "live", tmp_path / "live.rrd"
    play = subprocess.Popen([sys.executable, "-m", "tracelab.cli", "play", "--scenario", "advanced",
                             "--episodes", "3", "--seed", "2", "--run", str(run_dir)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (run_dir / "parts" / "manifest.json").exists():
            assert play.poll() is None or (run_dir / "parts" / "manifest.json").exists(), play.stderr.read()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert replay(run_dir, "--live", "--save", out) == 0
    finally:
        play.wait(timeout=120)
    assert play.returncode == 0
    data = read_rrd(out)
    assert sorted(data) == [f"live/episode-{e}" for e in range(3)]
    # a game of the spec path (war.toml): the same board, pieces, lanes and plots as a RuleSim run's
    for path in ("/board/terrain", "/board/agents/red-agent-1", "/board/agents/blue-agent-1", "/board/fired",
                 "/lanes/alive/red-agent-1", "/plots/return/red-agent-1", "/rules/log", "/why"):
        assert all(path in episode for episode in data.values()), path


def test_the_golden_recording_is_unchanged(tmp_path: Path) -> None:
    out = tmp_path / "golden.rrd"
    assert replay(SAMPLES / "base", "--episode", "2", "--why-depth", "2", "--save", out) == 0
    compare = subprocess.run([rerun_cli(), "rrd", "compare", "--unordered", str(GOLDEN), str(out)],
                             capture_output=True, text=True, check=False)
    assert compare.returncode == 0, (compare.stdout + compare.stderr)[-2000:]


def test_the_default_lanes_follow_the_agents_and_lanes_names_show_every_thing(advanced_data, tmp_path: Path) -> None:
    ep0 = advanced_data["advanced/episode-0"]
    lanes = {p for p in ep0 if p.startswith("/lanes/")}
    assert "/lanes/atLoc/red-agent-1" in lanes and not any("bullet" in p for p in lanes)   # a game's agents only
    # blue plays scripted (no steps rows of its own): its lanes are drawn too, as the board's pieces that live
    assert {"/lanes/alive/blue-agent-1", "/lanes/atLoc/blue-agent-1"} <= lanes, sorted(lanes)
    out = tmp_path / "atloc.rrd"
    assert replay(SAMPLES / "advanced", "--episode", "0", "--lanes", "atLoc", "--save", out) == 0
    assert any("bullet" in p for p in read_rrd(out)["advanced/episode-0"] if p.startswith("/lanes/atLoc/"))
