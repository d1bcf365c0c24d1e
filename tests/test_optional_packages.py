"""The main job needs no optional package: `pip install -e .` (no torch, no rerun-sdk) plays, records and
answers questions; a command that needs an optional package says in one line which extra installs it.
The packages are made unimportable in a subprocess (a sitecustomize that puts None in sys.modules, which
is how Python reports a module that is not installed: ModuleNotFoundError naming it)."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
OPTIONAL = ("torch", "rerun", "stable_baselines3", "ray", "tensorboard", "matplotlib", "pandas")


@pytest.fixture(scope="module")
def without_optional(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    blocker = tmp_path_factory.mktemp("blocker")
    (blocker / "sitecustomize.py").write_text(
        "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in OPTIONAL))
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(blocker), os.environ.get("PYTHONPATH", "")])}


def tracelab(env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tracelab", *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)


def test_the_main_job_runs_without_optional_packages(without_optional: dict[str, str], tmp_path: Path) -> None:
    run = tmp_path / "run"
    played = tracelab(without_optional, "play", "--scenario", "advanced", "--episodes", "1", "--run", str(run))
    assert played.returncode == 0, played.stderr
    asked = tracelab(without_optional, "sql", str(run), "SELECT count(*) FROM episodes")
    assert asked.returncode == 0 and "1" in asked.stdout, asked.stderr


@pytest.mark.parametrize(("command", "extra"), [
    (("train", "--scenario", "base", "--total-timesteps", "64"), "train"),
    (("replay", "sample_runs/advanced", "--episode", "0", "--save", "{tmp}/r.rrd"), "replay"),
])
def test_a_command_needing_an_extra_names_it_in_one_line(without_optional: dict[str, str], tmp_path: Path,
                                                        command: tuple[str, ...], extra: str) -> None:
    done = tracelab(without_optional, *(a.format(tmp=tmp_path) for a in command))
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stderr.startswith("tracelab: error: ") and f"pip install 'tracelab[{extra}]'" in done.stderr


def test_the_core_install_leaves_the_heavy_packages_to_extras() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = " ".join(project["dependencies"])
    assert "torch" not in core and "rerun" not in core
    extras = project["optional-dependencies"]
    for needed in ("torch==2.13.0", "rerun-sdk"):  # the README's test command installs `test`
        assert any(d.startswith(needed) for d in extras["test"])
