"""Environment specs (docs/worlds.md): what a spec declares becomes a gymnasium Env, and every mistake in
a spec is one located line (file:line: key: what was expected), before any engine is built."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

from tracelab.engine.safe_files import FileRefused
from tracelab.envs import make_env
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.spec_file import SpecError

# A corridor of four cells: the bot pushes west or east or stays; the mask says which pushes move it;
# reaching the east end ends the episode. Energy is a fuzzy atom set by a start fact.
RULES = """\
%mode override
%closed dest
snap:      was(C) <-1 at(C)
snap_off:  was(C):[0,0] <-1 was(C), at(C):[0,0]
clr_dest:  dest(C):[0,0] <-1 dest(C)
clr_moved: moved(w):[0,0] <-1 moved(w)
clr_ok:    allowed(A,D):[0,0] <-1 allowed(A,D)
mv_w:      dest(E) <-! was(C), push(A,west), west(C,E)
mv_e:      dest(E) <-! was(C), push(A,east), east(C,E)
arrive:    at(E) <-! dest(E)
moved:     moved(w) <-! dest(E)
leave:     at(C):[0,0] <-! was(C), moved(w), ~dest(C)
ok_w:      allowed(A,west) <-! bot(A), at(C), west(C,E)
ok_e:      allowed(A,east) <-! bot(A), at(C), east(C,E)
ok_stay:   allowed(A,stay) <-! bot(A), at(C), floor(C)
end:       over(w) <-! at(C), goal(C)
push(robo, stay):[0,0]
energy(robo):[0,1]
"""

SPEC = """\
[env]
rules = ["corridor.rules"]

[params]
goal_reward = 10

[board]
rows = ["S..G"]
legend = { S = ["floor"], "." = ["floor"], G = ["floor", "goal"] }
neighbours = { west = [0, -1], east = [0, 1] }
edge = "none"

[agents]
names = ["robo"]
mask = "allowed(Agent, Action)"

[actions]
west = ["push(Agent, west)"]
east = ["push(Agent, east)"]
stay = ["push(Agent, stay)"]

[observation]
space = "Box"
[[observation.parts]]
name = "where"
read = "onehot"
atom = "at(C)"
over = "cells"
[[observation.parts]]
name = "energy"
read = "bounds"
atoms = ["energy(robo)"]

[reward]
table = { "at(c0_3)" = "goal_reward" }
atom = "energy(Agent)"
scale = 2

[end]
terminated = ["over(w)"]
max_steps = 5

[start]
facts = ["at(c0_0)", "energy(robo):[0.5,0.75]", "bot(robo)"]
"""


def write_world(folder: Path, spec: str = SPEC, rules: str = RULES) -> Path:
    (folder / "corridor.rules").write_text(rules)
    path = folder / "corridor.toml"
    path.write_text(spec)
    return path


def test_a_declared_world_steps_reads_and_ends(tmp_path: Path) -> None:
    env = make_env(write_world(tmp_path))
    assert env.observation_space == spaces.Box(0.0, 1.0, (6,), np.float32)
    obs, info = env.reset(seed=1)
    assert obs.tolist() == [1, 0, 0, 0, 0.5, 0.75]
    assert info["action_mask"].tolist() == [0, 1, 1]  # no west of the first cell
    obs, reward, terminated, truncated, info = env.step(1)
    assert obs.tolist()[:4] == [0, 1, 0, 0] and info["action_mask"].tolist() == [1, 1, 1]
    assert (reward, terminated, truncated) == (1.0, False, False)  # energy's lower bound 0.5, times 2
    env.step(1)
    obs, reward, terminated, truncated, info = env.step(1)
    assert obs.tolist()[:4] == [0, 0, 0, 1] and (reward, terminated, truncated) == (11.0, True, False)
    assert info["action_mask"].tolist() == [1, 0, 1]
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(0)


def test_the_step_limit_truncates_and_params_change_values(tmp_path: Path) -> None:
    env = make_env(write_world(tmp_path), goal_reward=-3)
    env.reset(seed=0)
    flags = [env.step(2)[2:4] for _ in range(5)]
    assert flags == [(False, False)] * 4 + [(False, True)]
    env.reset()
    rewards = [env.step(1)[1] for _ in range(3)]
    assert rewards == [1.0, 1.0, -2.0]


@pytest.mark.parametrize("space, parts, want", [
    ("Discrete", [("index", "atom = \"at(C)\"\nover = \"cells\"")], spaces.Discrete(4)),
    ("MultiDiscrete", [("index", "atom = \"at(C)\"\nover = \"cells\""),
                       ("index", "atoms = [\"bot(robo)\", \"over(w)\"]")], spaces.MultiDiscrete([4, 2])),
    ("Dict", [("index", "atom = \"at(C)\"\nover = \"cells\""), ("lower", "atoms = [\"energy(robo)\"]")],
     spaces.Dict({"p0": spaces.Discrete(4), "p1": spaces.Box(0.0, 1.0, (1,), np.float32)})),
])
def test_observation_spaces_pass_gymnasiums_checker(tmp_path: Path, space: str, parts: list, want) -> None:
    text = "".join(f"[[observation.parts]]\nname = \"p{i}\"\nread = \"{read}\"\n{body}\n"
                   for i, (read, body) in enumerate(parts))
    head, rest = SPEC.split("[observation]")
    spec = head + f"[observation]\nspace = \"{space}\"\n" + text + rest[rest.index("[reward]"):]
    env = make_env(write_world(tmp_path, spec))
    assert env.observation_space == want
    check_env(env)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


def _located(tmp_path: Path, old: str, new: str, spec: str = SPEC, **params) -> str:
    """The one-line SpecError of `spec` with `old` replaced by `new`, after its 'file:'."""
    assert old in spec, old
    path = write_world(tmp_path, spec.replace(old, new, 1))
    with pytest.raises(SpecError) as e:
        load_spec(path, **params)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{path}:"), msg
    return msg[len(str(path)) + 1:]


@pytest.mark.parametrize("old, new, where, fragment", [
    ('atom = "at(C)"', 'atom = "pos(C)"', "27: observation.parts[0].atom", "the program has no predicate 'pos'"),
    ('west = ["push(Agent, west)"]', 'west = ["push(Agent, wset)"]', "18: actions.west[0]", "no constant 'wset'"),
    ('west = ["push(Agent, west)"]', 'west = ["push(west)"]', "18: actions.west[0]", "push takes 2 argument(s)"),
    ('west = ["push(Agent, west)"]', 'west = ["push(Agent, D)"]', "18: actions.west[0]", "variable D is not allowed"),
    ('terminated = ["over(w)"]', 'terminated = ["over(W)"]', "40: end.terminated[0]", "variable W is not allowed"),
    ('mask = "allowed(Agent, Action)"', 'mask = "allowed(Agent)"', "15: agents.mask", "takes 2 argument(s)"),
    ('space = "Box"', 'space = "Boxes"', "23: observation.space", "expected one of Discrete"),
    ('space = "Box"', 'space = "Discrete"', "26: observation.parts[0].read", 'expected "index"'),
    ('scale = 2', 'scale = "2 +"', "37: reward.scale", "not an expression"),
    ('scale = 2', 'scale = "__import__(\'os\').system(\'x\')"', "37: reward.scale", "Call is not allowed"),
    ('scale = 2', 'scale = "goal_reward.real"', "37: reward.scale", "Attribute is not allowed"),
    ('scale = 2', 'scale = "[0] * 10000000"', "37: reward.scale", "10,000,001 items"),
    ('scale = 2', 'scale = "nope"', "37: reward.scale", "unknown name 'nope'"),
    ('max_steps = 5', 'max_steps = 0', "41: end.max_steps", "expected an integer >= 1"),
    ('edge = "none"', 'edge = "wrap"', "11: board.edge", "expected one of stay, none"),
    ('G = ["floor", "goal"]', 'G = ["floor", "west"]', "7: board", "the board's facts do not fit the program"),
    ('rows = ["S..G"]', 'rows = ["S..G", "S."]', "8: board.rows", "rows of one length"),
    ('edge = "none"', 'edge = "none"\ncell = "{row:>999999999}{col}"', "12: board.cell", "expected a name"),
    ('edge = "none"', 'edge = "none"\ncell = "{row.__class__}{col}"', "12: board.cell", "expected a name"),
    ('[start]', '[starts]', "43: starts", "unknown section"),
    ('max_steps = 5', 'max_step = 5', "41: end.max_step", "unknown key"),
    ('rules = ["corridor.rules"]', 'rules = ["../corridor.rules"]', "2: env.rules[0]", "inside it"),
    ('rules = ["corridor.rules"]', 'rules = ["/etc/passwd"]', "2: env.rules[0]", "inside it"),
    ('rules = ["corridor.rules"]', 'rules = ["missing.rules"]', "2: env.rules", "no such file"),
    ('stay = ["push(Agent, stay)"]', 'wait = ["push(Agent, stay)"]', "20: actions.wait", "no constant 'wait'"),
    ('names = ["robo"]', 'names = ["Robo"]', "14: agents.names[0]", "not a plain constant"),
    ('facts = ["at(c0_0)"', 'facts = ["at(c0_9)"', "44: start.facts[0]", "no constant 'c0_9'"),
    ('goal_reward = 10', 'goal_reward = 10\n[data]\ngoal_reward = 1', "7: data.goal_reward", "both [data] and"),
])
def test_spec_mistakes_are_located(tmp_path: Path, old: str, new: str, where: str, fragment: str) -> None:
    msg = _located(tmp_path, old, new)
    assert msg.startswith(where + ":") and fragment in msg, msg


def test_toml_syntax_errors_name_line_and_column(tmp_path: Path) -> None:
    msg = _located(tmp_path, 'edge = "none"', 'edge = "none')
    assert msg.startswith("11:") and "not valid TOML" in msg, msg


def test_unknown_keyword_arguments_name_the_params(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match=r"unknown keyword argument 'goal' \(the spec's \[params\]: goal_reward\)"):
        load_spec(write_world(tmp_path), goal=1)


def test_a_program_error_in_the_rules_is_located_in_the_rule_file(tmp_path: Path) -> None:
    from tracelab.engine import ProgramError
    path = write_world(tmp_path, rules=RULES.replace("arrive:    at(E) <-! dest(E)", "arrive:    at(E) <-! dest(E"))
    with pytest.raises(ProgramError) as e:
        load_spec(path)
    assert e.value.file.endswith("corridor.rules") and e.value.line == 10


def test_a_spec_that_is_a_fifo_or_too_big_is_refused_without_hanging(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    result: list[BaseException] = []
    t = threading.Thread(target=lambda: _catch(result, fifo), daemon=True)
    t.start()
    t.join(timeout=10)
    assert not t.is_alive(), "reading a FIFO spec hung"
    assert isinstance(result[0], FileRefused) and "named pipe" in str(result[0])
    big = tmp_path / "big.toml"
    big.write_text("# padding\n" * 200_000)
    with pytest.raises(FileRefused, match="limit for a spec file"):
        load_spec(big)


def _catch(out: list[BaseException], path: Path) -> None:
    try:
        load_spec(path)
    except BaseException as e:  # noqa: BLE001 - handed to the test thread
        out.append(e)


def test_the_cli_reports_a_spec_error_in_one_line(tmp_path: Path) -> None:
    path = write_world(tmp_path, SPEC.replace('atom = "at(C)"', 'atom = "pos(C)"'))
    code = ("import sys; from tracelab.errors import user_error_message; from tracelab.envs import make_env\n"
            "try:\n    make_env(sys.argv[1])\nexcept Exception as e:\n    print(user_error_message(e))")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == (f"{path}:27: observation.parts[0].atom: 'pos(C)': the program has no "
                                  "predicate 'pos'"), out.stdout + out.stderr


@pytest.mark.parametrize("draw, where, fragment", [
    ('atom = "push(robo, D)"\nover = ["west", "east"]\nmethod = "choice"\nprobabilities = [0.5, 0.5]',
     "random[0].method", "takes no probabilities"),
    ('atom = "push(robo, D)"\nover = { E = ["west"] }', "random[0].over", "one domain per variable"),
    ('atom = ["push(A, D)"]\nover = ["west"]', "random[0].atom", "exactly one variable"),
    ('atom = "push(robo, D)"\nover = ["west", "east"]\nprobabilities = [0.5]', "random[0].probabilities",
     "a list of 2 numbers"),
    ('atom = "push(robo, D)"\nover = ["west", "east"]\nwhen = "goal_reward"', "random[0].when", "expected a boolean"),
    ('atom = "push(robo, D)"\nover = ["west", "east"]\nafter = "over(W)"', "random[0].after", "must be ground"),
    ('atom = "push(robo, D)"\nover = "rows"', "random[0].over", "expected 'cells', a list of constants"),
    ('atom = "push(robo, D)"\nover = ["west"]\n[[random]]\natom = "push(robo, E)"\nover = ["east"]', "random[1]",
     "the draw name 'push' is also the name of random.0"),
])
def test_random_fact_mistakes_are_located(tmp_path: Path, draw: str, where: str, fragment: str) -> None:
    path = write_world(tmp_path, SPEC + "\n[[random]]\n" + draw + "\n")
    with pytest.raises(SpecError) as e:
        load_spec(path)
    msg = str(e.value)[len(str(path)) + 1:]
    assert msg.split(": ", 1)[1].startswith(where) and fragment in msg, msg


def test_draws_follow_the_spec(tmp_path: Path) -> None:
    """A joint start choice over a product, weights that rule values out, `when` over the params."""
    spec = SPEC.replace('facts = ["at(c0_0)", ', 'facts = [') + '''
[[start.choose]]
atom = ["at(C)", "push(robo, D)"]
over = { C = "cells", D = ["west", "east"] }
weights = ["floor(C)", "goal(C)"]

[[random]]
atom = "push(robo, D)"
over = ["west", "east"]
when = "goal_reward > 100"
'''
    path = write_world(tmp_path, spec)
    assert len(load_spec(path).random_facts) == 0 and len(load_spec(path, goal_reward=200).random_facts) == 1
    env = make_env(path)
    starts = set()
    for seed in range(40):
        obs, _ = env.reset(seed=seed)
        starts.add(tuple(obs[:4].tolist()))
    assert starts == {(0, 0, 0, 1)}  # the goal cell is the only one whose weights both hold
    rng = np.random.default_rng(5)  # the product's values, first variable slowest: (c0_3, west) is 6
    assert env.world._choices[0].pick(env.world, rng) in (6, 7)


@pytest.mark.parametrize("old, new, where, fragment", [
    ('rows = ["S..G"]', 'rows = "[\'F\' * 300] * 300"', "8: board.rows", "more than 65536 cells"),
    ('rows = ["S..G"]', 'rows = "[\'F\' * 1000] * 1000"', "8: board.rows", "a value of 1,000,001 items"),
    ('over = "cells"', 'over = "[\'c0_0\'] * 99999 + [\'c0_1\'] * 99999"', "28: observation.parts[0].over",
     "a value of 399,997 items"),
    ('[start]', '[[random]]\natom = ["at(C)", "push(robo, D)"]\nover = { C = "cells", D = "[\'w\'] * 30000" }'
     '\n[start]', "45: random[0].over", "more than 100000 combinations"),
])
def test_specs_that_would_build_too_much_are_refused_first(tmp_path: Path, old: str, new: str, where: str,
                                                           fragment: str) -> None:
    msg = _located(tmp_path, old, new)
    assert msg.startswith(where + ":") and fragment in msg, msg


def test_the_first_world_of_the_docs_runs_as_shown(tmp_path: Path) -> None:
    """docs/worlds.md, "Your first world": its files, run in an empty folder, print what the page shows,
    and its example mistake gives the message shown."""
    import re
    text = (Path(__file__).resolve().parents[1] / "docs" / "worlds.md").read_text()
    section = text.split("## Your first world", 1)[1].split("\n## ", 1)[0]
    rules, spec, script, output = re.findall(r"```[a-z]*\n(.*?)```", section, re.S)
    (tmp_path / "corridor.rules").write_text(rules)
    (tmp_path / "corridor.toml").write_text(spec)
    (tmp_path / "run.py").write_text(script)
    out = subprocess.run([sys.executable, "run.py"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout == output
    (tmp_path / "corridor.toml").write_text(spec.replace('atom = "at(C)"', 'atom = "pos(C)"', 1))
    with pytest.raises(SpecError) as e:
        load_spec(tmp_path / "corridor.toml")
    shown = re.search(r"gives\n`(corridor.toml:[^`]*)`", section).group(1)
    assert str(e.value) == f"{tmp_path / 'corridor.toml'}:{shown.split(':', 1)[1]}"
