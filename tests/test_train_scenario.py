"""`tracelab train --scenario NAME` trains GridWar through its spec (issue 38 item 2, one trainer): the
scenario and GridWar's flags become rules/gridworld/war.toml params of a GridWar id, EnvTrainer trains it
and writes env_checkpoint's format, the run still names the scenario and its settings; what the spec path
cannot train is refused in one line; an old RuleSim run, resumed with or without --env, is refused in one
line saying how to start again."""
from __future__ import annotations

from pathlib import Path

import json

import numpy as np
import pytest
import torch

from tracelab.cli import main
from tracelab.envs.declared.gridwar import scenario_env
from tracelab.game.scenario import Rewards, builtin_scenario
from tracelab.store.meta import current_meta
from tracelab.train.config import TrainConfig
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar_runs import RULESIM_FORMATS
from tracelab.envs.declared.gridwar_scenarios import resumed_scenario
from tracelab.train.env_checkpoint import ENV_FORMAT, checkpoint_path
from tracelab.train.torch_files import load_tensors

from train_helpers import run_rows

TINY = ["--total-timesteps", "200", "--num-envs", "4", "--learning-starts", "50", "--eval-every", "200",
        "--eval-games", "4", "--eval-envs", "3", "--trace-eval-games", "1", "--log-every", "100",
        "--buffer-size", "500", "--batch-size", "16"]


def error_line(capsys: pytest.CaptureFixture[str], status: int) -> str:
    err = capsys.readouterr().err
    assert status == 1, err
    assert err.startswith("tracelab: error: ") and err.count("\n") == 1, err
    return err


def test_a_scenario_and_its_flags_are_war_toml_params() -> None:
    """The one mapping: the advanced scenario is its id; the opponent's p, --non-markov and the scenario's
    rewards are params; params at war.toml's defaults are left out."""
    assert scenario_env(builtin_scenario("base"), 0.7, False) == ("tracelab/GridWar-base-v0", {})
    shaped = builtin_scenario("advanced")
    shaped = type(shaped)(**{**shaped.__dict__, "rewards": Rewards(got_shot=-400.0), "max_steps": 50})
    assert scenario_env(shaped, 0.3, True) == ("tracelab/GridWar-advanced-v0", {
        "p_toward": 0.3, "stack_previous": True, "max_steps": 50, "got_shot": -400.0})


def test_train_scenario_runs_through_the_spec_and_resumes(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    assert main(["train", "--scenario", "base", "--opponent-p", "0.5", *TINY, "--run", str(run)]) == 0
    meta = current_meta(run)
    config = meta["config"]
    # the run names the scenario (its TOML kept); its settings are no TrainConfig fields but the params of
    # the env it trained on (the spec's id with the opponent's p) and of its evaluations' (at --eval-p)
    assert meta["scenario"] == "base" and 'name = "base"' in config["scenario_toml"]
    assert not {"scenario", "agents", "non_markov", "opponent_p", "eval_p"} & set(config)
    assert config["env"] == {"name": "tracelab/GridWar-base-v0", "kwargs": {"p_toward": 0.5}}
    assert config["eval_env"] == {"name": "tracelab/GridWar-base-v0", "kwargs": {"p_toward": 0.3}}
    state = load_tensors(checkpoint_path(run), 10**9)
    assert state["format"] == ENV_FORMAT and state["step"] == 200
    # the traced evaluation games are the spec's, counted as wins or losses
    outcomes = {o for (o,) in run_rows(run, "SELECT outcome FROM episodes WHERE kind = 'eval'")}
    assert outcomes and outcomes <= {"win", "loss", "truncated"}, outcomes
    capsys.readouterr()
    # --resume needs no --env: the scenario's env is rebuilt from the config and checked equal
    assert main(["train", "--resume", str(run), "--total-timesteps", "300"]) == 0
    assert load_tensors(checkpoint_path(run), 10**9)["step"] == 300
    _as_an_earlier_tracelab_wrote_it(run, eval_p=0.2)
    recorded = EnvSource("tracelab/GridWar-base-v0", {"p_toward": 0.5})
    # the scenario's settings read from the earlier fields: the evaluations' p from eval_p
    assert resumed_scenario(str(run), recorded, None).eval_source == recorded.with_args(p_toward=0.2)
    assert main(["train", "--resume", str(run), "--total-timesteps", "400"]) == 0
    assert load_tensors(checkpoint_path(run), 10**9)["step"] == 400
    capsys.readouterr()
    assert "--scenario advanced: " in error_line(capsys, main(["train", "--resume", str(run), "--scenario",
                                                               "advanced", "--total-timesteps", "500"]))


def _as_an_earlier_tracelab_wrote_it(run: Path, eval_p: float) -> None:
    """`run`'s meta and checkpoint as tracelab wrote them while the scenario's settings were TrainConfig
    fields: in the config, with no eval_env."""
    old = {"scenario": "base", "agents": None, "non_markov": False, "opponent_p": 0.5, "eval_p": eval_p}
    meta = json.loads((run / "meta.json").read_text())
    meta["config"] = {**{k: v for k, v in meta["config"].items() if k != "eval_env"}, **old}
    (run / "meta.json").write_text(json.dumps(meta))
    state = load_tensors(checkpoint_path(run), 10**9)
    torch.save({**state, "config": {**state["config"], **old}}, checkpoint_path(run))


@pytest.mark.parametrize("argv, fragment", [
    (["--split-networks"], "--split-networks is gone: training runs through the world's spec with one network"),
    (["--backend", "reference"], "--backend is gone: training plays the world's spec on the rule engine"),
    (["--backend=rules", "--env", "tracelab/FrozenLake-v1"], "--backend is gone"),
])
def test_what_the_spec_path_cannot_train_is_refused_in_one_line(argv: list[str], fragment: str, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    err = error_line(capsys, main(["train", *argv, *TINY, "--run", str(tmp_path / "run")]))
    assert fragment in err
    assert not (tmp_path / "run").exists()  # refused before a run is made


def test_a_scenario_file_with_another_map_is_refused_in_one_line(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "small.toml"
    f.write_text('name = "small"\nwidth = 4\nheight = 4\nred_base = [3, 0]\nblue_base = [0, 3]\n')
    err = error_line(capsys, main(["train", "--scenario", str(f), *TINY, "--run", str(tmp_path / "run")]))
    assert "scenario 'small': its board is not war.toml's 8x8 map, default or open" in err


def test_an_old_rulesim_checkpoint_on_the_spec_path_is_refused_saying_how_to_start_again(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A RuleSim run (RuleSim's observations, its replay of the worlds) does not convert to the spec's
    trainer: resumed on a GridWar id it is refused with the command that starts it again."""
    # its checkpoint as RuleSim's trainer wrote it, as far as the refusal reads it: its format and config
    run = tmp_path / "old"
    (run / "checkpoint").mkdir(parents=True)
    config = {**TrainConfig(steps=200, seed=4, envs=4).to_dict(), "scenario": "walk4"}  # its field then
    torch.save({"format": RULESIM_FORMATS[0], "config": config}, checkpoint_path(run))
    err = error_line(capsys, main(["train", "--resume", str(run), "--env", "tracelab/GridWar-base-v0"]))
    assert "trained by tracelab's RuleSim trainer" in err
    assert "start a new run with its settings: tracelab train --scenario walk4 --total-timesteps 200 --seed 4 " \
        "--num-envs 4" in err


def _rulesim_run(run: Path, checkpoint: dict) -> Path:
    """A run as RuleSim's trainer left it, as far as a resume reads it: its meta (a scenario, no env) and
    its checkpoint."""
    (run / "checkpoint").mkdir(parents=True)
    config = {**TrainConfig(steps=5000, seed=4, envs=4).to_dict(), "scenario": "advanced"}
    meta = {"command": "tracelab train", "scenario": "advanced", "status": "finished",
            "config": {**config, "scenario_toml": 'name = "advanced"'}}
    (run / "meta.json").write_text(json.dumps(meta))
    torch.save({**checkpoint, "config": config}, checkpoint_path(run))
    return run


def test_resuming_a_rulesim_run_is_refused_with_the_command_that_starts_it_again(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`train --resume OLD` (no --env: how a GridWar run was resumed) of a RuleSim run, in its format 2 or
    in its first format (numpy objects, which only a loader that runs code reads): one line each, nothing
    written into the run."""
    run = _rulesim_run(tmp_path / "old", {"format": RULESIM_FORMATS[0], "step": 100})
    before = sorted(p.name for p in run.rglob("*"))
    err = error_line(capsys, main(["train", "--resume", str(run)]))
    assert "trained by tracelab's RuleSim trainer" in err
    assert "start a new run with its settings: tracelab train --scenario advanced --total-timesteps 5000 " \
        "--seed 4 --num-envs 4" in err
    assert sorted(p.name for p in run.rglob("*")) == before
    first = _rulesim_run(tmp_path / "first", {"format": "tracelab-dqn-checkpoint/1", "games": np.zeros(3)})
    err = error_line(capsys, main(["train", "--resume", str(first), "--total-timesteps", "9000"]))
    assert "a checkpoint of RuleSim's trainer in its first format" in err
    assert "start a new run with tracelab train (its settings: tracelab show" in err
