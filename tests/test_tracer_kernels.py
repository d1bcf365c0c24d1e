"""The envs' tracer's compiled calls (tracelab/envs/step_log.py) compile once each: a first run's second
process (tracelab/game/rulesim_warmup_child.py), a traced play at one and several worlds, an episode limit that
leaves worlds unrecorded, and an env reset that cuts episodes short all pass them the same argument types
(a second signature would be a second compile on a first run: tests/test_first_run.py)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from tracelab.envs import step_log
from tracelab.envs.sinks import MemorySink
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.rulesim_warmup_child import compile_game_kernels
from tracelab.game.scenario import builtin_scenario
from tracelab.playing import Games


def _play(worlds: int, episodes: int) -> MemorySink:
    sink = MemorySink()
    games = Games(builtin_scenario("base"), episodes, worlds=worlds, seed=2, sink=sink)
    while not games.done:
        games.step()
    games.close()
    return sink


def test_each_tracer_kernel_has_one_signature_whatever_the_play() -> None:
    compile_game_kernels(builtin_scenario("base"), 1, False, "counting", True)  # what the second process does
    one, several = _play(1, 3), _play(4, 6)  # 4 worlds, 6 episodes: worlds past the limit play unrecorded
    assert [e["episode"] for e in one.ended] == [0, 1, 2]
    assert sorted(e["episode"] for e in several.ended) == list(range(6))
    env = GridWarVectorEnv(3, replace(builtin_scenario("advanced"), max_steps=40), backend="rules",
                           trace_sink=MemorySink())
    env.reset(seed=1)
    rng = np.random.default_rng(1)
    for k in range(30):
        env.step(rng.integers(0, 9, env.action_space.shape))
        if k == 10:
            env.reset()  # the running episodes end "aborted"
    env.close()
    kernels = (step_log._log_step, step_log._begin_episodes, step_log._episode_of_rows)
    assert {k.__name__: len(k.signatures) for k in kernels} == {k.__name__: 1 for k in kernels}
