"""The CLI's conventions (issue 27 §9): training flags named as CleanRL names them (today's names still
accepted), integers written 1e5, one name and one default for one thing across commands, an unknown flag
a one-line usage error of its subcommand with a did-you-mean, and a hint after a training too short to
learn anything."""
from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from tracelab.cli import build_parser, main
from tracelab.store.reader import run_info
from tracelab.train.budget import too_short_hint
from tracelab.train.config import TrainConfig

CLEANRL = {"--total-timesteps": ("steps", "1e5", 100_000), "--learning-rate": ("lr", "2.5e-4", 2.5e-4),
           "--buffer-size": ("buffer", "1e4", 10_000), "--batch-size": ("batch", "64", 64),
           "--learning-starts": ("warmup", "1.5e3", 1_500),
           "--target-network-frequency": ("target_every", "500", 500), "--num-envs": ("envs", "8", 8),
           "--seed": ("seed", "3", 3)}
OLD = {"--steps": "--total-timesteps", "--lr": "--learning-rate", "--buffer": "--buffer-size",
       "--batch": "--batch-size", "--warmup": "--learning-starts", "--target-every": "--target-network-frequency",
       "--envs": "--num-envs"}


def parse(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(list(argv))


def usage_error(capsys: pytest.CaptureFixture, *argv: str) -> str:
    """The one stderr line of a usage error (exit 2), nothing on stdout."""
    try:
        code = main(list(argv))
    except SystemExit as e:  # argparse's own errors exit from inside parse
        code = e.code
    out = capsys.readouterr()
    assert code == 2 and out.out == "", (code, out)
    lines = [ln for ln in out.err.splitlines() if not ln.startswith(("usage:", " "))]
    assert len(lines) == 1, out.err
    return lines[0]


def test_cleanrl_flag_names_and_numbers_like_1e5() -> None:
    for flag, (field, text, value) in CLEANRL.items():
        assert getattr(parse("train", flag, text), field) == value
    assert parse("train", "--exp-name", "sweep").exp_name == "sweep"
    assert parse("train").__dict__.get("torch_deterministic") is None      # the config's default: on
    assert TrainConfig().torch_deterministic is True
    assert parse("train", "--torch-deterministic", "false").torch_deterministic is False
    assert parse("train", "--torch-deterministic").torch_deterministic is True
    assert parse("train", "--no-torch-deterministic").torch_deterministic is False


def test_todays_names_stay_as_hidden_aliases(capsys: pytest.CaptureFixture) -> None:
    for old, new in OLD.items():
        field, text, value = CLEANRL[new]
        assert getattr(parse("train", old, text), field) == value
    with pytest.raises(SystemExit):
        parse("train", "--help")
    shown = capsys.readouterr().out
    assert all(new in shown for new in CLEANRL) and "--exp-name" in shown and "--torch-deterministic" in shown
    assert not any(f"{old} " in shown for old in OLD)


@pytest.mark.parametrize("argv, expected", [
    (["train", "--total-timesteps", "1.5"], "argument --total-timesteps: expected an integer, got '1.5'"),
    (["play", "--episodes", "2.5"], "argument --episodes: expected an integer, got '2.5'"),
    (["train", "--exp-name", "../elsewhere"], "argument --exp-name: expected a name without '/'"),
])
def test_a_bad_value_names_it(argv: list[str], expected: str, capsys: pytest.CaptureFixture) -> None:
    assert expected in usage_error(capsys, *argv)


def test_integers_in_exponent_form_everywhere() -> None:
    assert parse("play", "--episodes", "1e2").episodes == 100
    assert parse("eval", "pol", "--games", "5e2").games == 500


@pytest.mark.parametrize("argv, expected", [
    (["train", "--total-timestepz", "1000"],
     "tracelab train: error: unknown flag --total-timestepz; did you mean --total-timesteps? "
     "(tracelab train --help lists them)"),
    (["train", "--learnin-rate=1e-3"],
     "unknown flag --learnin-rate; did you mean --learning-rate, --learning-starts, --learner?"),
    (["eval", "pol", "--num-env", "4", "--gams", "3"], "unknown flag --gams; did you mean --games?"),
])
def test_an_unknown_flag_is_one_line_of_its_subcommand(argv: list[str], expected: str,
                                                        capsys: pytest.CaptureFixture) -> None:
    line = usage_error(capsys, *argv)
    assert expected in line and line.startswith(f"tracelab {argv[0]}: error: ")


def test_one_name_and_one_default_for_one_thing() -> None:
    assert parse("eval", "pol", "--num-envs", "4").envs == parse("eval", "pol", "--envs", "4").envs == 4
    assert parse("eval", "pol").envs == TrainConfig().eval_envs == 64
    from tracelab.envs.declared.gridwar_scenarios import DEFAULT_SCENARIO, ScenarioTraining
    assert DEFAULT_SCENARIO == ScenarioTraining.given({}).name == "base"


def test_a_training_too_short_to_learn_says_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "short"
    flags = ["--scenario", "base", "--total-timesteps", "64", "--num-envs", "4", "--learning-starts", "32",
             "--batch-size", "16", "--eval-every", "0", "--eval-games", "2", "--eval-envs", "2",
             "--trace-eval-games", "1", "--log-every", "32", "--kernel", "counting"]
    assert main(["train", *flags, "--run", str(run)]) == 0
    err = capsys.readouterr().err
    hints = [ln for ln in err.splitlines() if ln.startswith("hint:")]
    assert hints == ["hint: 0 wins after 64 steps is expected: the documented 1v1 runs first won after about "
                     "150,000 steps (docs/experiments/1v1-base.md); try --total-timesteps 2e5"]
    config = run_info(run).meta["config"]
    assert config["steps"] == 64 and config["torch_deterministic"] is True   # stored by field name
    assert TrainConfig.from_dict({k: v for k, v in config.items() if k in TrainConfig().to_dict()}).steps == 64
    # a budget that should have learned, or a win, is no question of budget
    assert too_short_hint(200_000, 0, 1) is None and too_short_hint(30_000, 1, 1) is None
    assert "3e5" in (too_short_hint(100_000, 0, 5) or "")


def test_the_default_reward_scale_is_the_one_that_learns_and_every_report_names_the_scale(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """0.01 learned the 1v1 base scenario where the method's 1 did not (docs/experiments/1v1-base.md): it is
    train's default, `--reward-scale 1` is the method's, and train's lines, `compare` and an experiment's
    learner row say which scale was used."""
    from tracelab.train.experiments.definitions import EXPERIMENTS
    from tracelab.train.experiments.report import learner_text
    from tracelab.train.experiments.run import ArmResult, ExperimentResult
    assert TrainConfig().reward_scale == 0.01
    assert TrainConfig.from_dict({"steps": 10}).reward_scale == 1   # a config from before the flag: resumed as it was
    flags = ["--scenario", "base", "--total-timesteps", "32", "--num-envs", "2", "--learning-starts", "16",
             "--batch-size", "8", "--eval-every", "0", "--eval-games", "2", "--eval-envs", "2",
             "--trace-eval-games", "0", "--log-every", "16", "--kernel", "counting"]
    for run, extra, said in (("default", [], "reward scale 0.01 (the method's: 1)"),
                             ("method", ["--reward-scale", "1"], "reward scale 1 (the method's)")):
        assert main(["train", *flags, *extra, "--run", str(tmp_path / run)]) == 0
        out = capsys.readouterr()
        assert said in out.err.splitlines()[0] and said in out.out.splitlines()[0], out
        assert run_info(tmp_path / run).meta["config"]["reward_scale"] == (0.01 if run == "default" else 1)
    assert main(["compare", str(tmp_path / "default"), str(tmp_path / "method")]) == 0
    rows = [ln.split("  ") for ln in capsys.readouterr().out.splitlines()]
    scale = next(r for r in rows if r[0] == "reward scale")
    assert [c.strip() for c in scale if c.strip()][1:] == ["0.01", "1 (the method's)"]
    assert main(["compare", str(tmp_path / "default")]) == 0   # one run: no differences, the scale still
    assert "reward scale" in capsys.readouterr().out
    exp = EXPERIMENTS["1v1-base"]
    text = learner_text(ExperimentResult(exp, exp.quick, True, tmp_path, [ArmResult(a) for a in exp.arms]))
    assert text == ("the method's DQN (docs/training.md), except: 1v1 base: reward scale 0.01; "
                    "1v1 base, the method's reward scale: as the method, reward scale 1")


def test_an_atom_given_after_the_flags_is_the_same_question(capsys: pytest.CaptureFixture) -> None:
    """`why`'s atom is optional (--action asks about a decision instead): argparse alone would match it,
    empty, before the first flag and call a late atom an unexpected argument."""
    run = str(Path(__file__).resolve().parent.parent / "sample_runs" / "advanced")
    assert main(["why", run, "captured(blue)", "--episode", "0", "--at", "21", "--depth", "2"]) == 0
    first = capsys.readouterr().out
    assert main(["why", run, "--episode", "0", "--at", "21", "--depth", "2", "captured(blue)"]) == 0
    assert capsys.readouterr().out == first and "captured(blue)" in first
    assert main(["why", run, "--episode", "0", "captured(blue)", "extra"]) == 2
    assert "unexpected argument: extra" in capsys.readouterr().err


def test_the_parser_is_the_command_table_and_each_command_runs_from_the_module_named_after_it() -> None:
    """`tracelab CMD ...` builds CMD's parser alone from the command table (tracelab/commands/_table.py),
    importing no command module; the command runs `run(args)` of the module named after it."""
    import importlib
    import subprocess
    import sys

    from tracelab.cli import command_module
    from tracelab.commands._table import COMMANDS
    full = build_parser()
    names = next(a for a in full._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert list(names) == [c.name for c in COMMANDS]
    for name in names:
        alone = build_parser(name)
        assert list(next(a for a in alone._actions if isinstance(a, argparse._SubParsersAction)).choices) == [name]
        assert callable(importlib.import_module(command_module(name)).run)
    assert command_module("no-such-command") is None
    assert build_parser("no-such-command").format_help() == full.format_help()  # the typo's message names all
    code = ("import sys; from tracelab.cli import build_parser; build_parser(); "
            "print([m for m in sys.modules if m.startswith('tracelab.commands.') and "
            "not m.rpartition('.')[2].startswith('_')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"


def test_experiments_choices_in_the_table_are_the_experiments() -> None:
    """The command table names without importing them: experiment's choices are the experiments."""
    from tracelab.commands._table import EXPERIMENT_NAMES
    from tracelab.train.experiments.definitions import EXPERIMENTS
    assert sorted(EXPERIMENT_NAMES) == sorted(EXPERIMENTS)
