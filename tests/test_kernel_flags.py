"""`--kernel` on `tracelab play` and `tracelab train` (TrainConfig.kernel): it reaches the engines of every
env a command builds; a kernel the command cannot use is a one-line error; `--kernel compiled` on a
program not yet cached starts at once on the counting kernel while the kernel compiles in the background."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys

import pytest
from tracelab.cli import main
from tracelab.store import run_info
from tracelab.train.config import TrainConfig
from train_helpers import walk_config, walk_trainer

CLI = [sys.executable, "-m", "tracelab"]


def _tracelab(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, check=False,
                          env={**os.environ, **(env or {})})


def test_a_kernel_the_command_cannot_use_is_a_usage_error() -> None:
    for command in ("play", "train"):
        out = _tracelab(command, "--kernel", "fastest")
        assert out.returncode == 2 and "invalid choice: 'fastest'" in out.stderr.splitlines()[-1]
    with pytest.raises(ValueError, match="kernel must be one of auto, counting, lanes, compiled"):
        TrainConfig(kernel="fastest")


def test_train_kernel_reaches_the_training_and_evaluation_engines(tmp_path, capsys) -> None:
    cfg = walk_config(steps=200, seed=1, kernel="lanes")  # 4 worlds: auto is not lanes
    trainer = walk_trainer(cfg)  # writing no run: its evaluations play untraced, in an env of their own
    try:
        trainer.run_eval()
        engines = [trainer.env.worlds.engine, trainer._eval_env.worlds.engine]
        assert [e.kernel for e in engines] == ["lanes", "lanes"]
    finally:
        trainer.close()
    # through the command line: the run's config records it, and --resume may change it
    run, resumed = tmp_path / "run", tmp_path / "resumed"
    flags = ["--scenario", "base", "--steps", "64", "--envs", "4", "--warmup", "32", "--batch", "16",
             "--eval-every", "0", "--eval-games", "2", "--eval-envs", "2", "--trace-eval-games", "1",
             "--log-every", "32"]
    assert main(["train", *flags, "--kernel", "counting", "--run", str(run)]) == 0
    assert run_info(run).meta["config"]["kernel"] == "counting"
    assert "counting kernel" in capsys.readouterr().err
    # the run finished its 64 steps: a resume raises the budget (nothing to resume otherwise)
    assert main(["train", "--resume", str(run), "--kernel", "lanes", "--total-timesteps", "96",
                 "--run", str(resumed)]) == 0
    assert run_info(resumed).meta["config"]["kernel"] == "lanes"


def test_play_kernel_reaches_the_engine(tmp_path, capsys) -> None:
    run = tmp_path / "run"
    assert main(["play", "--scenario", "base", "--episodes", "2", "--kernel", "lanes", "--run", str(run)]) == 0
    assert run_info(run).meta["config"]["kernel"] == "lanes"
    assert "played 2 episodes" in capsys.readouterr().out


def test_play_kernel_compiled_does_not_wait_for_the_compile(tmp_path) -> None:
    """The game's kernel is not in an empty cache: the games start on the counting kernel at once, the
    compile goes on in the background and outlives the short run (this test then stops it)."""
    out = _tracelab("play", "--scenario", "base", "--episodes", "2", "--kernel", "compiled", "--no-trace",
                    env={"TRACELAB_CACHE_DIR": str(tmp_path)})
    assert out.returncode == 0, out.stderr
    assert "played 2 episodes" in out.stdout
    lines = out.stderr.splitlines()
    started = [ln for ln in lines if "is being built in the background" in ln]
    assert len(started) == 1 and "starts on the counting kernel" in started[0]
    pid = int(re.search(r"pid (\d+)", started[0]).group(1))
    still = [ln for ln in lines if "still being built in the background" in ln]
    try:
        assert still == [f"tracelab: the compiled kernel is still being built in the background (pid {pid}); "
                         "the next run takes it from the cache (--kernel compiled or auto)"]
    finally:
        try:
            os.kill(pid, signal.SIGTERM)  # the compile this test started (a minute of CPU otherwise)
        except ProcessLookupError:
            pass
