"""Checkpoints and policies from strangers (issue 24): a checkpoint loads without running code (torch's
weights_only) and is checked against the shapes its config implies; a checkpoint of the old format, a path
that is not a run, a FIFO, a malformed policy.json or policy.pt, and a network too big for the machine are
each refused with one line and exit status 1, before anything is built. Commands that could hang on a FIFO
run in a subprocess with a timeout, so a regression fails instead of hanging."""
from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import torch

from tracelab.cli import main
from tracelab.train.env_checkpoint import checkpoint_path
from rulesim_policies import RULESIM_POLICY
from train_helpers import tiny_training_run, walk_argv

TIMEOUT = 120  # seconds; the command itself takes a few (importing torch), a hang takes forever


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One finished tiny training run (checkpoint, policy); tests work on copies of it."""
    return tiny_training_run(tmp_path_factory.mktemp("trained") / "run")


@pytest.fixture
def run(trained: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(trained, copy)
    return copy


def error_line(capsys: pytest.CaptureFixture[str], status: int) -> str:
    """The command failed with status 1 and said why on exactly one line of stderr; returns it."""
    err = capsys.readouterr().err
    assert status == 1, err
    assert err.startswith("tracelab: error: ") and err.count("\n") == 1, err
    return err


def run_cli(*argv: str) -> subprocess.CompletedProcess[str]:
    """The CLI in a subprocess that a hang cannot outlive (TimeoutExpired fails the test)."""
    return subprocess.run([sys.executable, "-m", "tracelab.cli", *argv], capture_output=True, text=True,
                          timeout=TIMEOUT)


def assert_one_line_refusal(proc: subprocess.CompletedProcess[str], fragment: str) -> None:
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.startswith("tracelab: error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert fragment in proc.stderr, proc.stderr


class RunsCode:
    """Pickled, it tells the unpickler to call os.system: a full unpickler creates the marker file."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return os.system, (f"touch {shlex.quote(str(self.marker))}",)


def code_that_would_run(path: Path, marker: Path, content: dict[str, Any]) -> None:
    """Save `content` with a payload at `path`, and check that the payload is live: loading the file
    the old way (weights_only=False) does create the marker."""
    torch.save({**content, "payload": RunsCode(marker)}, path)
    torch.load(path, weights_only=False)
    assert marker.exists()
    marker.unlink()


# ---------------------------------------------------------------------------------------------------------
# Checkpoints
# ---------------------------------------------------------------------------------------------------------
def test_a_checkpoint_that_would_run_code_is_refused_and_the_code_does_not_run(run, tmp_path, capsys):
    marker = tmp_path / "payload-ran"
    code_that_would_run(checkpoint_path(run), marker, {"format": "tracelab-dqn-env-checkpoint/2"})
    err = error_line(capsys, main(["train", "--resume", str(run), *walk_argv(), "--run", str(tmp_path / "new")]))
    assert "posix.system" in err and "which loading would call" in err
    assert f"tracelab eval {run}/policy --env ENV" in err and f"tracelab show {run}" in err
    assert not marker.exists()
    assert not (tmp_path / "new").exists()


def test_a_checkpoint_of_the_old_format_is_refused_with_how_to_continue(run, tmp_path, capsys):
    """The first env format (each world's generator state) cannot be rebuilt: refused, saying how to go on."""
    state = torch.load(checkpoint_path(run), weights_only=True)
    state["format"] = "tracelab-dqn-env-checkpoint/1"
    torch.save(state, checkpoint_path(run))
    err = error_line(capsys, main(["train", "--resume", str(run), *walk_argv(), "--run", str(tmp_path / "new")]))
    assert "written by an earlier tracelab (tracelab-dqn-env-checkpoint/1)" in err and "policy.json" in err, err
    assert not (tmp_path / "new").exists()
    # what it says to do works: the run's policy still plays
    assert main(["eval", f"{run}/policy", *walk_argv(), "--games", "2"]) == 0


def _checkpoint_is(kind: str, run: Path) -> None:
    f = checkpoint_path(run)
    f.unlink()
    if kind == "a link to /etc/passwd":
        f.symlink_to("/etc/passwd")
    else:
        shutil.copyfile("/etc/passwd", f)


@pytest.mark.parametrize("target, fragment", [
    ("/etc/passwd", "/etc/passwd: not a training run's directory"),
    ("a link to /etc/passwd", "checkpoint.pt: is a symbolic link; refused"),
    ("a copy of /etc/passwd", "checkpoint.pt: not a file torch.save writes"),
])
def test_resume_from_what_is_not_a_run_s_checkpoint_never_reaches_the_unpickler(target, fragment, run, capsys,
                                                                              monkeypatch):
    if target != "/etc/passwd":
        _checkpoint_is(target, run)
        target = str(run)

    def no_unpickling(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("torch.load was called")

    monkeypatch.setattr(torch, "load", no_unpickling)
    assert fragment in error_line(capsys, main(["train", "--resume", target]))


def test_a_fifo_as_checkpoint_is_refused_without_waiting(run):
    f = checkpoint_path(run)
    f.unlink()
    os.mkfifo(f)
    assert_one_line_refusal(run_cli("train", "--resume", str(run), *walk_argv()),
                            "checkpoint.pt: is a named pipe (FIFO)")


def _edit(key: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(state: dict[str, Any]) -> None:
        *path, last = key.split(".")
        target = state
        for k in path:
            target = target[k]
        target[last] = value(target[last]) if callable(value) else value
    return edit


@pytest.mark.parametrize("edit, fragment", [
    (_edit("config.hidden", [64]), "key 'config.hidden': expected layer widths as a string (64,64) or one width"),
    (_edit("config.hidden", "6x4"), "config: hidden must be up to 32 layer widths >= 1 separated by commas"),
    (_edit("config.steps", -5), "config: steps must be at least 1, got -5"),
    (_edit("learner", "readable"), "key 'learners.shared.online': expected an object with exactly the keys "
                                   "0.weight, 0.bias, 2.weight, 2.bias, got nothing"),
    (_edit("learner", "torch.load"), "key 'learner': expected one of 'fused', 'readable'"),
    (_edit("env_actions", lambda h: h.fill_(100)), "key 'env_actions': expected values from 0 to 4"),
    (_edit("games.obs", torch.zeros(1)), "key 'games.obs': expected a float32 tensor of shape 4 x 4"),
    (_edit("learners.shared.buffer.size", 3), "key 'learners.shared.buffer.obs': expected 3 rows (its size)"),
    (_edit("rng.bit_generator", "MT19937"), "key 'rng.bit_generator': expected 'PCG64'"),
    (_edit("env", "tracelab/GridWar-base-v0"), "key 'env': expected an object"),
    (_edit("learners", []), "key 'learners': expected an object, got an empty list"),
])
def test_a_checkpoint_that_does_not_match_its_config_is_refused_naming_the_key(edit, fragment, run, tmp_path,
                                                                             capsys):
    state = torch.load(checkpoint_path(run), weights_only=True)
    edit(state)
    torch.save(state, checkpoint_path(run))
    err = error_line(capsys, main(["train", "--resume", str(run), *walk_argv(), "--run", str(tmp_path / "new")]))
    assert err.startswith(f"tracelab: error: {checkpoint_path(run)}: ") and fragment in err, err
    assert not (tmp_path / "new").exists()


# ---------------------------------------------------------------------------------------------------------
# Policies
# ---------------------------------------------------------------------------------------------------------
def _spec_edit(key: str, value: Any) -> Callable[[Path], None]:
    def edit(policy: Path) -> None:
        spec = json.loads((policy / "policy.json").read_text())
        *path, last = key.split(".")
        target = spec
        for k in path:
            target = target[k]
        target[last] = value
        (policy / "policy.json").write_text(json.dumps(spec))
    return edit


def _json_is(text: str) -> Callable[[Path], None]:
    return lambda policy: (policy / "policy.json").write_text(text)


def _json_links_to_dev_zero(policy: Path) -> None:
    (policy / "policy.json").unlink()
    (policy / "policy.json").symlink_to("/dev/zero")


@pytest.mark.parametrize("command", ["eval", "play"])
@pytest.mark.parametrize("edit, fragment", [
    (_json_is("[]"), "policy.json: expected an object, got an empty list"),
    (_spec_edit("network", None), "policy.json: key 'network': expected an object, got null"),
    (_spec_edit("env", "base"), "policy.json: key 'env': expected an object, got the string 'base'"),
    (_spec_edit("network.hidden", "64"), "policy.json: key 'network.hidden': expected an integer >= 1"),
    (_spec_edit("network.hidden", [1] * 33), "policy.json: key 'network.hidden': expected an integer >= 1 (or a "
                                             "list of up to 32 of them)"),
    (_spec_edit("network.dueling", True), "policy.pt: key 'shared.trunk.0.weight': expected a floating tensor of "
                                          "shape 64 x 4, got nothing (the key is missing)"),
    (_spec_edit("networks", {"shared": "0"}), "policy.json: key 'networks.shared': expected a list"),
    (_json_links_to_dev_zero, "policy.json: is a symbolic link; refused"),
    (_spec_edit("network.hidden", 10 ** 9), "policy.json: network: 1 network of 4 inputs x 1,000,000,000 "
                                            "hidden units x 5 outputs would take an estimated"),
])
def test_a_malformed_policy_json_is_one_line_naming_the_key(command, edit, fragment, run, capsys):
    edit(run / "policy")
    # the walk's policy plays on the env it was trained on, named again
    argv = ["eval", str(run / "policy"), *walk_argv(), "--games", "2"] if command == "eval" else \
        ["play", "--policy", str(run / "policy"), *walk_argv(), "--episodes", "1", "--no-trace"]
    assert fragment in error_line(capsys, main(argv))


def _pt_is(content: Any) -> Callable[[Path, Path], None]:
    return lambda pt, marker: torch.save(content, pt)


@pytest.mark.parametrize("write, fragment", [
    (lambda pt, marker: pt.write_bytes(b""), "policy.pt: is empty; refused"),
    (_pt_is([1, 2]), "policy.pt: expected an object, got a list of 2 items"),
    (_pt_is({"fast": {}}), "policy.pt: key 'shared': expected an object, got nothing (the key is missing)"),
    (_pt_is({"shared": {"0.weight": torch.zeros(3)}}), "policy.pt: key 'shared.0.weight': expected a floating tensor "
                                                       "of shape 64 x 4, got a float32 tensor of shape (3,)"),
    (lambda pt, marker: code_that_would_run(pt, marker, {}), "policy.pt: refers to posix.system"),
])
def test_a_malformed_policy_pt_is_one_line_and_runs_nothing(write, fragment, run, tmp_path, capsys):
    marker = tmp_path / "payload-ran"
    write(run / "policy" / "policy.pt", marker)
    assert fragment in error_line(capsys, main(["eval", str(run / "policy"), *walk_argv(), "--games", "2"]))
    assert not marker.exists()


@pytest.mark.parametrize("name", ["policy.pt", "policy.json"])
def test_a_fifo_in_a_policy_is_refused_without_waiting(name, run):
    (run / "policy" / name).unlink()
    os.mkfifo(run / "policy" / name)
    assert_one_line_refusal(run_cli("eval", str(run / "policy"), *walk_argv(), "--games", "2"),
                            f"{name}: is a named pipe (FIFO)")


def test_an_old_rulesim_policy_still_loads(capsys):
    assert main(["eval", str(RULESIM_POLICY), "--games", "2"]) == 0


@pytest.fixture
def old_policy(tmp_path: Path) -> Path:
    """A copy of a policy of GridWar's earlier trainer (RuleSim's format, tests/data/rulesim/base-policy)."""
    return Path(shutil.copytree(RULESIM_POLICY, tmp_path / "old-policy"))


def _old_pt_with_code(policy: Path, marker: Path) -> None:
    code_that_would_run(policy / "policy.pt", marker, torch.load(policy / "policy.pt", weights_only=True))


@pytest.mark.parametrize("command", ["eval", "play"])
@pytest.mark.parametrize("edit, fragment", [
    (_spec_edit("format", "tracelab-dqn-policy/9"), "policy.json: key 'format': expected 'tracelab-dqn-policy/1'"),
    (_spec_edit("scenario.toml", "name = "), "policy.json: key 'scenario.toml': not TOML: Invalid value"),
    (_spec_edit("scenario.toml", "name = 'x'\nwidth = -3"), "policy.json: key 'scenario.toml'"),
    (_spec_edit("scenario", {"name": "base"}), "policy.json: key 'scenario.toml': expected a string"),
    (_spec_edit("observation.stack_previous", "no"), "policy.json: key 'observation.stack_previous': expected"),
    (_spec_edit("networks", {"shared": [0], "other": [0]}), "policy.json: key 'networks': expected one network"),
    (_spec_edit("network.hidden", 10 ** 9), "policy.json: network: 1 network of 4 inputs x 1,000,000,000 "
                                            "hidden units x 5 outputs would take an estimated"),
    (_spec_edit("network.inputs", 7), "policy.pt: key 'shared.0.weight': expected a floating tensor of shape "
                                      "64 x 7, got a float32 tensor of shape (64, 4)"),
    (_json_links_to_dev_zero, "policy.json: is a symbolic link; refused"),
    (lambda policy: torch.save({"shared": {}}, policy / "policy.pt"),
     "policy.pt: key 'shared.0.weight': expected a floating tensor of shape 64 x 4, got nothing"),
    (lambda policy: _old_pt_with_code(policy, policy.parent / "payload-ran"), "policy.pt: refers to posix.system"),
])
def test_a_malformed_old_policy_is_refused_in_one_line_and_runs_nothing(command, edit, fragment, old_policy,
                                                                         capsys):
    """A policy of RuleSim's format from a stranger: checked as the trainer's own are, before its networks are
    built (sizes, shapes, no code run), each failure one line naming the key."""
    edit(old_policy)
    argv = ["eval", str(old_policy), "--games", "2"] if command == "eval" else \
        ["play", "--policy", str(old_policy), "--episodes", "1", "--no-trace"]
    assert fragment in error_line(capsys, main(argv))
    assert not (old_policy.parent / "payload-ran").exists()


def test_the_sample_run_s_policy_still_loads(capsys):
    sample = Path(__file__).resolve().parents[1] / "sample_runs" / "base-train" / "policy"
    assert main(["eval", str(sample), "--games", "2"]) == 0


# ---------------------------------------------------------------------------------------------------------
# Sizes
# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("flag, value, named", [
    ("--hidden", "100000000", "--hidden 100000000"),
    ("--buffer", "10000000000", "--buffer-size 10000000000"),  # the documented flag of the alias typed
    ("--envs", "100000000", "--num-envs 100000000"),
])
def test_a_run_too_big_for_the_machine_is_refused_before_anything_is_built(flag, value, named, tmp_path, capsys):
    err = error_line(capsys, main(["train", flag, value, "--run", str(tmp_path / "run")]))
    assert named in err and "would take an estimated" in err and "bytes" in err and "--max-memory" in err, err
    assert not (tmp_path / "run").exists()


def test_max_memory_sets_the_limit(tmp_path, capsys):
    err = error_line(capsys, main(["train", "--max-memory", "1M", "--run", str(tmp_path / "run")]))
    assert "over the limit of 1,048,576 bytes (1.0 MiB, set by --max-memory)" in err, err
    assert not (tmp_path / "run").exists()
