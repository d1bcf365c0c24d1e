"""The spec's computed step facts and earlier observations (docs/worlds.md: `[[clock]]`, `[[nearest]]`,
`[observation] previous`) on a world of their own: what each sets on which step, in the single and the
vector env, and each mistake a located error. GridWar's specs use them against RuleSim in
tests/test_gridwar_spec.py."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracelab.envs.declared.computed import nearest_things
from tracelab.envs.declared.gym_env import DeclaredEnv
from tracelab.envs.declared.spec import NearestFacts, SpecError, load_spec
from tracelab.envs.declared.vector_env import DeclaredVectorEnv

RULES = """%mode override
rang: rang(me) <-0 tick(me)
"""
SPEC = """[env]
rules = ["w.rules"]
[params]
period = 3
[agents]
names = ["me"]
[actions]
wait = []
[observation]
space = "Box"
previous = 1
[[observation.parts]]
name = "tick"
read = "onehot"
atoms = ["tick(me)"]
[end]
max_steps = 7
[[clock]]
atom = "tick(me)"
every = "period"
at = 1
"""


def world(tmp_path: Path, spec: str = SPEC) -> Path:
    (tmp_path / "w.rules").write_text(RULES)
    path = tmp_path / "w.toml"
    path.write_text(spec)
    return path


def test_a_clock_sets_its_facts_on_every_kth_step_with_the_last_observation_after(tmp_path: Path) -> None:
    """tick(me) on the episode's steps 1, 4 (every = the param period, at = 1): [now, previous]."""
    env = DeclaredEnv(world(tmp_path))
    obs, _ = env.reset(seed=0)
    got = [obs.tolist()]
    for _ in range(7):
        obs, _, _, truncated, _ = env.step(0)
        got.append(obs.tolist())
    assert truncated
    assert got == [[0, 0], [0, 0], [1, 0], [0, 1], [0, 0], [1, 0], [0, 1], [0, 0]]
    env.reset()  # a new episode counts from 0 again
    assert [env.step(0)[0].tolist() for _ in range(3)] == [[0, 0], [1, 0], [0, 1]]
    env2 = DeclaredEnv(world(tmp_path), period=2)
    env2.reset(seed=0)
    assert [env2.step(0)[0][0] for _ in range(5)] == [0, 1, 0, 1, 0]


def test_a_dict_observation_gains_previous_entries(tmp_path: Path) -> None:
    """previous = 2 in a Dict space: `previous_tick` and `previous2_tick`, the start's at a reset."""
    env = DeclaredEnv(world(tmp_path, SPEC.replace('space = "Box"\nprevious = 1', 'space = "Dict"\nprevious = 2')))
    assert sorted(env.observation_space.spaces) == ["previous2_tick", "previous_tick", "tick"]
    obs, _ = env.reset(seed=0)
    seen = [obs]
    for _ in range(3):
        seen.append(env.step(0)[0])
    assert [[float(o[k][0]) for k in ("tick", "previous_tick", "previous2_tick")] for o in seen] == \
        [[0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0]]
    assert all(env.observation_space.contains(o) for o in seen)


def test_the_vector_env_counts_each_worlds_steps(tmp_path: Path) -> None:
    """Every world ticks on its own episode's steps; a world restarted by autoreset starts from its start
    observation twice, the ended episode's last one in final_obs."""
    vec = DeclaredVectorEnv(world(tmp_path), 2, max_episode_steps=5)
    obs, _ = vec.reset(seed=0)
    seq, ends = [obs.tolist()], []
    for _ in range(6):
        obs, _, _, truncated, info = vec.step(np.zeros(2, np.int64))
        seq.append(obs.tolist())
        ends.append(truncated.tolist())
        if truncated.any():
            assert info["final_obs"].tolist() == [[1, 0], [1, 0]]  # step 4 of the ended episode ticked
    assert ends == [[False, False]] * 4 + [[True, True], [False, False]]
    assert [row[0] for row in seq] == [[0, 0], [0, 0], [1, 0], [0, 1], [0, 0], [0, 0], [0, 0]]
    assert [row[0] for row in seq] == [row[1] for row in seq]


def test_nearest_in_line_breaks_ties_by_the_lines_order() -> None:
    """Of things at equal distances the first line listed wins (up before left), the same cell first, a thing
    out of line or on no cell never; without lines, the first thing listed."""
    width, cells = 5, 25
    n = NearestFacts(("nearest", 0), (), (), 1, 3, width, ((-1, 0), (1, 0), (0, -1), (0, 1)))

    def where(who: int, *things: int) -> np.ndarray:
        truth = np.zeros((1, 4, cells), bool)
        for k, c in enumerate((who, *things)):
            if c >= 0:
                truth[0, k, c] = True
        return truth.reshape(1, -1)

    centre = 12  # row 2, col 2
    assert nearest_things(n, where(centre, 10, 14, 2)).tolist() == [[2]]  # left, right, up, all at 2: up
    assert nearest_things(n, where(centre, 10, 2, 12)).tolist() == [[2]]  # the same cell first
    assert nearest_things(n, where(centre, 0, 24, -1)).tolist() == [[-1]]  # none in line
    assert nearest_things(n, where(-1, 10, 2, 11)).tolist() == [[-1]]  # no cell for who
    anywhere = NearestFacts(("nearest", 0), (), (), 1, 3, width, None)
    assert nearest_things(anywhere, where(centre, 0, 18, 6)).tolist() == [[1]]  # 18 is 2 away, 6 is 2: first


@pytest.mark.parametrize("change, message", [
    (("at = 1", "at = 3"), "w.toml:21: clock[0].at: expected a step in 0..2 (of every 3), got 3"),
    (("every = \"period\"", "every = 0"), "w.toml:20: clock[0].every: expected an integer >= 1, got the number 0"),
    (("atom = \"tick(me)\"\nevery", "atom = \"tock(me)\"\nevery"),
     "clock[0].atom: 'tock(me)': the program has no predicate 'tock'"),
    (("space = \"Box\"", "space = \"Discrete\"", "read = \"onehot\"\natoms = [\"tick(me)\"]",
      "read = \"index\"\natoms = [\"tick(me)\"]"),
     "w.toml:11: observation.previous: a Discrete observation is one number"),
    (("previous = 1", "previous = 65"), "observation.previous: at most 64 earlier observations, got 65"),
    (("[[clock]]", "[[nearest]]\natom = \"rang(Who)\"\nwho = [\"me\"]\nthings = [\"me\"]\n"
                   "where = \"tick(Thing)\"\n[[clock]]"),
     "nearest[0]: [[nearest]] measures distances on the [board]; the spec has none"),
])
def test_mistakes_are_located(tmp_path: Path, change: tuple[str, ...], message: str) -> None:
    spec = SPEC
    for old, new in zip(change[::2], change[1::2]):
        assert old in spec
        spec = spec.replace(old, new, 1)
    with pytest.raises(SpecError) as e:
        load_spec(world(tmp_path, spec))
    assert message in str(e.value)
