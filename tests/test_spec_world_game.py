"""A world that is not in the repository, written here as a spec beside its rules (a corridor with a trap
that kills one step later, a delayed rule, a door that wins, and a `[board]`), is a first-class game in
every view with no Python beyond the commands: play, train, eval, replay (its board, its returns, every
step to the last), the TUI (returns, outcomes), `sql --query actions_per_win`, show and compare (its own
params). Issue 38, item 3."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from store_helpers import run_rows as rows
from test_replay import read_rrd
from tui_helpers import episodes_ready, run_app, wait_for

from tracelab.cli import main
from tracelab.envs import make_env

RULES = """%mode override
%closed dest
snap:     was(C) <-1 at(C)
snap_off: was(C):[0,0] <-1 was(C), at(C):[0,0]
clr_dest: dest(C):[0,0] <-1 dest(C)
# the trap kills a step after it is stepped on: the delayed rule sets dead(me) at the next step's pass 0
hurt:     dead(me) <-1 at(C), trap(C)
step_w:   dest(E) <-! was(C), go(west), west(C, E)
step_e:   dest(E) <-! was(C), go(east), east(C, E)
arrive:   at(E) <-! dest(E)
leave:    at(C):[0,0] <-! was(C), dest(E), ~dest(C)
home:     home(me) <-! at(C), door(C)
"""

SPEC = """[env]
rules = ["trap.rules"]

[params]
door_reward = 1.0

[board]
rows = ["T...D"]
legend = { D = ["door"], T = ["trap"] }
neighbours = { west = [0, -1], east = [0, 1] }
marks = { at = "@" }
colors = { T = "#8b0000", D = "#006400" }

[agents]
names = ["me"]

[actions]
west = ["go(west)"]
east = ["go(east)"]

[observation]
space = "Discrete"
[[observation.parts]]
name = "cell"
read = "index"
atom = "at(C)"
over = "cells"

[reward.table]
"home(me)" = "door_reward"
"dead(me)" = -1

[end]
terminated = ["home(me)", "dead(me)"]
win = ["home(me)"]
loss = ["dead(me)"]
max_steps = 30

[start]
[[start.choose]]
atom = "at(C)"
over = ["c0_1", "c0_2"]
"""


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("trap")
    (folder / "trap.rules").write_text(RULES)
    (folder / "trap.toml").write_text(SPEC)
    return folder


@pytest.fixture(scope="module")
def played(world: Path) -> Path:
    run = world / "runs" / "play"
    assert main(["play", "--env", str(world / "trap.toml"), "--episodes", "30", "--seed", "1", "--run", str(run)]) == 0
    return run


def test_a_worlds_declared_win_and_loss_are_its_games_outcomes(played: Path, capsys: pytest.CaptureFixture) -> None:
    outcomes = dict(rows(played, "SELECT outcome, count(*) FROM episodes GROUP BY 1"))
    assert set(outcomes) == {"win", "loss"} and sum(outcomes.values()) == 30
    # every win ended on the door (return door_reward), every loss in the trap (-1)
    assert rows(played, "SELECT DISTINCT outcome, reward FROM episodes ORDER BY 1") == [("loss", -1.0), ("win", 1.0)]
    capsys.readouterr()
    assert main(["sql", str(played), "--query", "actions_per_win", "--format", "json"]) == 0
    (answer,) = json.loads(capsys.readouterr().out)
    assert answer["wins"] == outcomes["win"]


def test_play_counts_the_worlds_wins_and_losses(world: Path, played: Path, capsys: pytest.CaptureFixture) -> None:
    """The summary of `play --env` names wins and losses where the world declares them (it said "with a
    positive return"), the same games as the recorded run's outcomes."""
    capsys.readouterr()
    assert main(["play", "--env", str(world / "trap.toml"), "--episodes", "30", "--seed", "1", "--no-trace"]) == 0
    outcomes = dict(rows(played, "SELECT outcome, count(*) FROM episodes GROUP BY 1"))
    assert f"{outcomes['win']} won, {outcomes['loss']} lost, 0 truncated" in capsys.readouterr().out


def test_the_replay_draws_the_board_and_the_return_to_the_last_step(played: Path, tmp_path: Path) -> None:
    (episode, t_end, reward), = rows(played, "SELECT episode, t_end, reward FROM episodes WHERE outcome = 'loss' "
                                             "ORDER BY t_end DESC, episode LIMIT 1")
    out = tmp_path / "r.rrd"
    assert main(["replay", str(played), "--episode", str(episode), "--why", "dead(me)", "--save", str(out)]) == 0
    (rec,) = read_rrd(out).values()
    docs = {r["step"]: r["TextDocument:text"][0] for r in rec["/why"]}
    # the agent died at t_end (the delayed rule fired at its pass 0): the last document says so
    assert max(docs) == t_end
    assert f"step {t_end} of {t_end}" in docs[t_end] and f"dead(me) = [1,1] at the end of t={t_end}" in docs[t_end]
    # the board, as the env's rgb_array draws it: the last frame has the agent on the trap's cell
    frames = [r for r in rec["/board/terrain"] if r.get("Image:buffer")]
    assert frames[0]["step"] == 0 and frames[-1]["step"] <= t_end
    env = make_env(played.parent.parent / "trap.toml", render_mode="rgb_array")
    painter_image = env.unwrapped._painter({"c0_0": "at"}, env.unwrapped.world_spec.board.mark_colors)
    env.close()
    assert np.array_equal(np.frombuffer(bytes(frames[-1]["Image:buffer"][0]), np.uint8), painter_image.ravel())
    # the return, step by step to the last
    returns = [(r["step"], r["Scalars:scalars"][0]) for r in rec["/plots/return/me"] if r.get("Scalars:scalars")]
    assert returns[-1] == (t_end, reward)


def test_the_tui_lists_returns_and_outcomes_of_the_worlds_games(played: Path) -> None:
    seen: dict[str, Any] = {}

    async def body(app: Any, pilot: Any) -> None:
        table = await episodes_ready(app, pilot)
        await wait_for(pilot, lambda: any(c.key == "reward" for c in app.screen.query_one("EpisodesPane").columns))
        seen["columns"] = [c.key for c in app.screen.query_one("EpisodesPane").columns]
        seen["table"] = table
    run_app([played], body, (120, 34))
    assert "reward" in seen["columns"] and "outcome" in seen["columns"]


def test_training_counts_wins_and_show_and_compare_list_the_worlds_params(
        world: Path, capsys: pytest.CaptureFixture) -> None:
    runs = []
    for reward in ("1", "2"):
        run = world / "runs" / f"train-{reward}"
        assert main(["train", "--env", str(world / "trap.toml"), "--env-arg", f"door_reward={reward}",
                     "--total-timesteps", "100", "--learning-starts", "20", "--eval-every", "100",
                     "--eval-games", "8", "--trace-eval-games", "2", "--run", str(run)]) == 0
        runs.append(run)
    # every evaluation game counted (traced and untraced): in this world a win is the one positive return
    rates = rows(runs[0], "SELECT w.step, w.value, s.value FROM metrics w JOIN metrics s ON s.step = w.step AND "
                          "s.name = 'eval/success_rate' WHERE w.name = 'eval/win_rate' ORDER BY w.step")
    assert rates and all(win == success for _, win, success in rates)
    capsys.readouterr()
    assert main(["eval", str(runs[0] / "policy"), "--env", str(world / "trap.toml"), "--env-arg", "door_reward=1",
                 "--games", "20", "--json"]) == 0
    evaluated = json.loads(capsys.readouterr().out)
    assert evaluated["games"] == 20 and evaluated["win_rate"] == evaluated["success_rate"]
    traced = dict(rows(runs[0], "SELECT outcome, count(*) FROM episodes WHERE kind = 'eval' GROUP BY 1"))
    assert set(traced) <= {"win", "loss", "truncated"} and sum(traced.values()) >= 2
    trained = dict(rows(runs[0], "SELECT outcome, count(*) FROM episodes WHERE kind = 'train' GROUP BY 1"))
    assert set(trained) <= {"win", "loss", "truncated", "aborted"} and {"win", "loss"} <= set(trained)
    capsys.readouterr()
    assert main(["show", str(runs[1])]) == 0
    shown = capsys.readouterr().out
    assert "params    door_reward = 2" in shown
    for gridwar in ("opponent_p", "scenario  ", "eval_p", "(the method's)"):
        assert gridwar not in shown
    assert main(["compare", str(runs[0]), str(runs[1])]) == 0
    compared = capsys.readouterr().out
    assert "(the method's)" not in compared and "opponent_p" not in compared
    (param,) = [line.split() for line in compared.splitlines() if line.startswith("param door_reward")]
    assert param[2:] == ["1", "2"]


def test_a_sweep_trains_the_world_with_its_trials_reading_its_evaluations(world: Path) -> None:
    """`tracelab sweep --set env=SPEC` (was: "TrainConfig has no field 'env'"): the spec names the world and
    defaults to a metric every env's evaluation writes; each trial is a `train --env` whose evaluations
    reach the sink Tune reads (train_seed, as a trial calls it). Ray itself is left out (tests/test_ray.py
    runs Tune)."""
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.experiments.runner import train_seed
    from tracelab.train.sweep_spec import SweepSpecError, build_spec

    spec = build_spec(sets=[f"env={world / 'trap.toml'}", "steps=100", "eval_every=50", "eval_games=4",
                            "learning-starts=20", "trace_eval_games=1"], grids=["lr=1e-3,3e-4"])
    assert spec.env == str(world / "trap.toml") and spec.metric == "eval/mean_return" and spec.trials == 2
    assert build_spec(sets=[f"env={world / 'trap.toml'}"], grids=["lr=1e-3"], metric="eval/win_rate").metric \
        == "eval/win_rate"
    with pytest.raises(SweepSpecError, match="opponent_p describes GridWar"):
        build_spec(sets=[f"env={world / 'trap.toml'}", "opponent_p=0.5"], grids=["lr=1e-3"])
    with pytest.raises(SweepSpecError, match="env cannot be searched"):
        build_spec(grids=["env=a.toml,b.toml"])

    class Sink:
        def __init__(self) -> None:
            self.rows: list[tuple[int, dict]] = []

        def write(self, step: int, values: dict) -> None:
            self.rows.append((step, dict(values)))

        def flush(self) -> None:
            pass

    sink, started = Sink(), []
    run = world / "runs" / "trial"
    cfg = spec.base_config()
    assert train_seed(cfg, EnvSource.given(spec.env, {}), run, "tracelab sweep (test)", (), cfg.eval_games, [sink],
                      started.append).status == "finished"
    assert len(started) == 1
    evaluations = [(step, v["eval/win_rate"]) for step, v in sink.rows if "eval/win_rate" in v]
    assert [s for s, _ in evaluations][-1] >= 100 and all(0 <= w <= 1 for _, w in evaluations)
    assert rows(run, "SELECT status FROM run") == [("finished",)]
