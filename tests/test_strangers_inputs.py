"""Untrusted inputs, round two (issues 37.6, 37.8, 43.3, 43.4): big rule files and graphs measured before
they are built, path arguments that are not files, sweep files checked like specs, and training sizes
(flags, a stranger's checkpoint config) estimated before anything is allocated. Every refusal is one line
`tracelab: error: ...` and exit status 1; commands run in a subprocess with a timeout ceiling and a cap
on their address space and CPU time, so a regression fails (MemoryError, SIGXCPU) instead of taking the
machine. The sweep refusals come before Ray starts: they are run against an address where no Ray answers
(`--ray 127.0.0.1:1`), whose own refusal would be the line otherwise."""
from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from test_cli_errors import COMPILE_NOTICE

from tracelab import RULES_DIR

ADDRESS_SPACE = 4 << 30  # a command's imports (torch, numba) fit; the refused inputs need far more
CPU_SECONDS = 90         # a ceiling: the refusals take a few seconds; main's readings took minutes
TIMEOUT = 240
NO_RAY = ["--ray", "127.0.0.1:1"]  # nothing answers there: a sweep that reaches Ray fails with that line


def tracelab(*args: str, cwd: Path | None = None, env: dict[str, str] | None = None,
             cpu: int = CPU_SECONDS) -> subprocess.CompletedProcess:
    def capped() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))

    return subprocess.run([sys.executable, "-m", "tracelab", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=TIMEOUT, check=False, preexec_fn=capped, env={**os.environ, **(env or {})})


def refusal(p: subprocess.CompletedProcess, *fragments: str) -> str:
    """The one line of a user error (exit 1, no traceback; a cold numba cache may add its notice) holding
    every fragment; returns it."""
    assert "Traceback" not in p.stderr, p.stderr[-3000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.strip() and not ln.startswith(COMPILE_NOTICE)]
    assert p.returncode == 1 and len(lines) == 1 and lines[0].startswith("tracelab: error: "), p.stderr[-3000:]
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


# ---- 37.6: big rule files and graphs ---------------------------------------------------------------------

def _facts(path: Path, n: int) -> Path:
    with path.open("w") as f:
        f.writelines(f"e(n{i},n{i + 1})\n" for i in range(n))
    return path


def test_a_rule_file_too_big_to_parse_is_refused_before_parsing(tmp_path: Path) -> None:
    # 14 MB of 700,000 facts (far under the 64 MiB file cap): parsed, about 1.7 GB and minutes of CPU
    rules = _facts(tmp_path / "big.rules", 700_000)
    line = refusal(tracelab("reason", str(rules), "--steps", "1"), "big.rules", "700,000 lines",
                   "TRACELAB_PARSE_MEMORY")
    assert "to parse" in line


def test_the_parse_limit_is_set_by_its_variable_and_a_program_under_it_runs(tmp_path: Path) -> None:
    rules = _facts(tmp_path / "r.rules", 2_000)
    refusal(tracelab("reason", str(rules), "--steps", "1", env={"TRACELAB_PARSE_MEMORY": "1M"}),
            "set by $TRACELAB_PARSE_MEMORY")
    p = tracelab("reason", str(rules), "--steps", "1", "--no-trace")
    assert p.returncode == 0, p.stderr
    assert "e(n1999,n2000)" in p.stdout


def _keyed_graph(path: Path, keys: int, nodes: int = 2, default: bool = False, names: int = 30_000) -> Path:
    """A graph with `keys` attribute keys (each with a <default> if `default`) naming at most `names`
    attributes (the engine takes 32,768 predicates), the first node holding every attribute."""
    out = ['<?xml version="1.0" encoding="UTF-8"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n']
    for i in range(keys):
        d = "<default>1</default>" if default else ""
        out.append(f'<key id="k{i}" for="node" attr.name="a{i % names}" attr.type="double">{d}</key>\n')
    out.append('<graph edgedefault="directed">\n<node id="n0">\n')
    out += [f'<data key="k{i}">1</data>\n' for i in range(keys)]
    out.append("</node>\n")
    out += [f'<node id="n{i}"/>\n' for i in range(1, nodes)]
    out.append('<edge source="n0" target="n1"/>\n</graph>\n</graphml>\n')
    path.write_text("".join(out))
    return path


@pytest.mark.parametrize("dialect", ["tracelab", "pyreason"])
def test_graphml_keys_are_read_in_linear_time(tmp_path: Path, dialect: str) -> None:
    # 60,000 keys: on ce39376 the pyreason reading's list.index took minutes of CPU (25,000 keys: 39 s);
    # both readings now take a few seconds (the ceiling is the CPU time of the whole command)
    graph = _keyed_graph(tmp_path / "keys.graphml", 60_000)
    (tmp_path / "r.rules").write_text("b(X) <-1 a1(X)\n" if dialect == "tracelab" else "b(x) <-1 a1(x)\n")
    p = tracelab("reason", "--dialect", dialect, str(tmp_path / "r.rules"), "--graph", str(graph), "--steps", "1",
                 "--query", "b(X)", cpu=45)
    assert p.returncode == 0, p.stderr[-3000:]


def test_a_graph_whose_key_defaults_make_too_many_facts_is_refused_before_they_are_built(tmp_path: Path) -> None:
    # 300 keys with a default over 100,000 nodes: 30 million facts from a 2 MB file
    graph = _keyed_graph(tmp_path / "defaults.graphml", 300, nodes=100_000, default=True)
    (tmp_path / "r.rules").write_text("b(X) <-1 a1(X)\n")
    refusal(tracelab("reason", str(tmp_path / "r.rules"), "--graph", str(graph), "--steps", "1",
                     "--max-groundings", "1000000"), "defaults.graphml", "30,0", "--max-groundings")


# ---- 37.8: path arguments that are not files ---------------------------------------------------------------

def test_a_nul_byte_in_a_spec_s_rule_path_is_one_line(tmp_path: Path) -> None:
    for f in ("frozen_lake.toml", "frozen_lake.rules"):
        shutil.copy(RULES_DIR / "toytext" / f, tmp_path / f)
    spec = tmp_path / "frozen_lake.toml"
    spec.write_text(spec.read_text().replace('rules = ["frozen_lake.rules"]', 'rules = ["frozen\\u0000lake.rules"]'))
    refusal(tracelab("play", "--env", str(spec), "--episodes", "1"), "NUL byte")


@pytest.fixture
def strange_paths(tmp_path: Path) -> dict[str, str]:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "dir").mkdir()
    return {"fifo": str(fifo), "/dev/zero": "/dev/zero", "dir": str(tmp_path / "dir"),
            "long": str(tmp_path / ("x" * 5000))}


REACH = str(RULES_DIR / "examples" / "reach.rules")
PATH_ARGUMENTS = {
    "rules": ["reason", "{}", "--steps", "1"],
    "--graph": ["reason", REACH, "--graph", "{}", "--steps", "1"],
    "--facts-table": ["reason", REACH, "--facts-table", "{}", "--steps", "1"],
    "policy": ["eval", "{}"],
    "--resume": ["train", "--resume", "{}"],
}


@pytest.mark.parametrize("what", ["fifo", "/dev/zero", "long"])
@pytest.mark.parametrize("argument", list(PATH_ARGUMENTS))
def test_a_path_argument_that_is_no_file_is_one_line_and_no_hang(strange_paths: dict[str, str], argument: str,
                                                                    what: str) -> None:
    args = [a.format(strange_paths[what]) if a == "{}" else a for a in PATH_ARGUMENTS[argument]]
    refusal(tracelab(*args))


# ---- 43.3: sweep files -------------------------------------------------------------------------------------

def _sweep(tmp_path: Path, text: str) -> subprocess.CompletedProcess:
    (tmp_path / "s.toml").write_text(text)
    return tracelab("sweep", "s.toml", *NO_RAY, cwd=tmp_path)


GRID = "[grid]\nlr = [1e-4, 3e-4]\n"


@pytest.mark.parametrize("text, fragments", [
    ('[set]\nhidden = "100000000"\n' + GRID, ["s.toml:2:1: set.hidden", "--hidden 100000000", "--max-memory"]),
    ("[set]\nbuffer = 100000000\n" + GRID, ["s.toml:2:1: set.buffer", "a replay buffer of", "--max-memory"]),
    ("[grid]\nbuffer = [100, 100000000]\n", ["s.toml:2:1: grid.buffer", "100,000,000 transitions"]),
    ('[set]\nenv = "tracelab/FrozenLake-v1"\nbuffer = 100000000\n' + GRID,
     ["s.toml:3:1: set.buffer", "a replay buffer of", "--max-memory"]),
    ('[random]\nenvs = "randint:1,1000000000"\n', ["s.toml:2:1: random.envs", "1,000,000,000 training worlds"]),
    ("[set]\nthreads = 100000\n" + GRID, ["s.toml:2:1: set.threads", "at most 256"]),
    ("[set]\nsteps = 100\n" + "x = " + "[" * 5000 + "]" * 5000 + "\n" + GRID, ["s.toml", "nested too deeply"]),
    ('[set]\nscenario = "/etc/passwd"\n' + GRID, ["s.toml:2:1: set.scenario", "inside it"]),
    ('[set]\nscenario = "a\\u0000b"\n' + GRID, ["s.toml:2:1: set.scenario", "NUL byte"]),
])
def test_a_sweep_file_is_checked_and_estimated_before_ray_starts(tmp_path: Path, text: str,
                                                                 fragments: list[str]) -> None:
    refusal(_sweep(tmp_path, text), *fragments)


def test_a_sweep_file_s_scenario_may_not_leave_its_folder_through_a_link(tmp_path: Path) -> None:
    (tmp_path / "sc.toml").symlink_to("/etc/passwd")
    refusal(_sweep(tmp_path, '[set]\nscenario = "sc.toml"\n' + GRID), "set.scenario", "outside")


def test_a_sweep_s_max_memory_sets_the_limit_of_its_trials(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_text("[set]\nbuffer = 50000\n" + GRID)
    refusal(tracelab("sweep", "s.toml", "--max-memory", "1M", *NO_RAY, cwd=tmp_path), "set by --max-memory")
    refusal(tracelab("sweep", "s.toml", *NO_RAY, cwd=tmp_path), "no Ray cluster answers")  # fits: Ray's turn


def test_a_sweep_file_s_scenario_inside_its_folder_is_read_from_there(tmp_path: Path) -> None:
    from tracelab.game.scenario import builtin_scenario
    (tmp_path / "mine.toml").write_text(builtin_scenario("base").to_toml())
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "s.toml").write_text('[set]\nscenario = "mine.toml"\n' + GRID)
    refusal(tracelab("sweep", str(tmp_path / "s.toml"), *NO_RAY, cwd=elsewhere), "no Ray cluster answers")


# ---- 43.4: training sizes from flags and a stranger's checkpoint -------------------------------------------

LAKE = "tracelab/FrozenLake-v1"


def test_train_env_with_ten_million_worlds_is_refused_naming_the_flag(tmp_path: Path) -> None:
    refusal(tracelab("train", "--env", LAKE, "--num-envs", "1e7", "--run", str(tmp_path / "run")),
            "--num-envs 10000000", "training worlds", "--max-memory")
    assert not (tmp_path / "run").exists()


def test_a_stranger_s_env_checkpoint_asking_for_a_billion_worlds_is_refused_on_resume(tmp_path: Path) -> None:
    import torch

    from tracelab.commands.train import train_env_into
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.env_checkpoint import checkpoint_path
    from tracelab.train.config import TrainConfig

    run = tmp_path / "run"
    cfg = TrainConfig(steps=200, envs=2, warmup=50, eval_every=0, buffer=500, batch=16, checkpoint_every=100,
                      reward_scale=1.0)
    assert train_env_into(cfg, EnvSource(LAKE), run, "Discrete(16) one-hot") == 0
    f = checkpoint_path(run)
    state = torch.load(f, weights_only=True)
    state["config"]["envs"] = 10 ** 9
    torch.save(state, f)
    refusal(tracelab("train", "--resume", str(run), "--env", LAKE, "--total-timesteps", "400"),
            "checkpoint.pt: config: --num-envs 1000000000")


def test_a_stranger_s_checkpoint_asking_for_a_billion_worlds_is_refused_on_resume(tmp_path: Path) -> None:
    import torch

    from tracelab.train.env_checkpoint import checkpoint_path
    from train_helpers import tiny_training_run, walk_argv

    run = tiny_training_run(tmp_path / "run")  # GridWar's walk, through its spec
    f = checkpoint_path(run)
    state = torch.load(f, weights_only=True)
    state["config"]["envs"] = 10 ** 9
    torch.save(state, f)
    refusal(tracelab("train", "--resume", str(run), *walk_argv(), "--total-timesteps", "400"),
            "checkpoint.pt: config: --num-envs 1000000000")
