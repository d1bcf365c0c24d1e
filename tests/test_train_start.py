"""What a training pays before its first step (issue 40): torch's deterministic mode is set without
importing torch.compile's machinery (torch._inductor, torch._dynamo: ~2 s of CPU), and set as torch's own
switch would (the eager flag that the operations read). Figures: `tracelab bench first-run` (train)."""
from __future__ import annotations

import json
import subprocess
import sys

CHILD = """
import json, sys, torch
from tracelab.train.determinism import use_deterministic_algorithms
seen = []
for mode in (True, False, True):
    use_deterministic_algorithms(mode)
    seen.append(torch.are_deterministic_algorithms_enabled())
loaded = "torch._inductor" in sys.modules or "torch._dynamo" in sys.modules
import torch._inductor.config as inductor_config  # once something has loaded it, its flag follows too
use_deterministic_algorithms(False)
print(json.dumps({"seen": seen, "loaded": loaded, "inductor": inductor_config.deterministic,
                  "eager": torch.are_deterministic_algorithms_enabled()}))
"""


def test_the_deterministic_switch_loads_no_compiler() -> None:
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300, check=True)
    got = json.loads(done.stdout.splitlines()[-1])
    assert got["seen"] == [True, False, True]
    assert got["loaded"] is False
    assert got["inductor"] is False and got["eager"] is False


def test_sizing_a_declared_world_builds_no_engine_and_reads_the_env_spaces(monkeypatch) -> None:  # noqa: ANN001
    """probe_env (what sizes a training and checks a policy before eval) reads a declared world's spaces from
    its spec: no engine is built (grounding war.toml and stepping it cost ~1 s, which the command's vector
    env then did again); the sizes are the env's own."""
    from tracelab.engine.core import Engine
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.env_source import ObservationEncoder, probe_env
    built = []
    real_init = Engine.__init__

    def counted(self, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
        built.append(1)
        real_init(self, *args, **kwargs)

    monkeypatch.setattr(Engine, "__init__", counted)
    for name in ("tracelab/GridWar-base-v0", "tracelab/FrozenLake-v1"):
        source = EnvSource(name, {})
        encoder, n_actions, spec = probe_env(source)
        assert built == [], name
        env = source.make()  # the env itself: its spaces are the ones the probe read
        try:
            assert (encoder.size, n_actions) == (ObservationEncoder(env.observation_space, name).size,
                                                 int(env.action_space.n))
            assert spec is not None and spec.path == env.unwrapped.world_spec.path
        finally:
            env.close()
        built.clear()


def test_the_runs_meta_reads_the_spec_train_loaded_already(monkeypatch) -> None:  # noqa: ANN001
    """train loads the spec once to size the training (probe_env) and hands it to the run's meta, which
    parsed it again (~0.2 s of CPU before the first step); the meta is the same either way."""
    from tracelab.envs.declared import play
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.config import TrainConfig
    from tracelab.train.env_source import probe_env
    from tracelab.train.env_trainer import env_run_meta
    source = EnvSource("tracelab/FrozenLake-v1", {})
    cfg = TrainConfig(steps=100, eval_games=4, trace_eval_games=2)
    parsed = env_run_meta(cfg, source, "tracelab train")
    _, _, spec = probe_env(source)
    loads = []
    real = play.load_declared
    monkeypatch.setattr(play, "load_declared", lambda s: loads.append(s) or real(s))
    assert env_run_meta(cfg, source, "tracelab train", spec=spec) == parsed
    assert loads == []


def test_eval_parses_the_world_spec_once(monkeypatch) -> None:  # noqa: ANN001
    """eval checks the policy against the spaces of the spec it then plays (the opponent at the method's p):
    one parse, where it parsed the spec again for its vector env (~0.1 s of CPU before the first step)."""
    from tracelab.bench.common import sample_runs_dir
    from tracelab.cli import main
    from tracelab.envs.declared import spec as spec_module
    reads = []
    real = spec_module.read_spec_file
    monkeypatch.setattr(spec_module, "read_spec_file", lambda path: reads.append(path) or real(path))
    assert main(["eval", str(sample_runs_dir() / "base-train" / "policy"), "--games", "2", "--num-envs", "2"]) == 0
    assert len(reads) == 1
