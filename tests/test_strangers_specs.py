"""Environment specs from strangers (issue 37 §1, §3, §4, §8, §9; docs/worlds.md, "Files from
strangers"): a spec makes tracelab read no file outside its folder (links resolved), is read in time
linear in its size, cannot make a world that never ends, and every mistake in it (a value of the wrong
type, a NUL byte in a path, a misspelt name, a state its observation cannot read) is one located line,
never a traceback. What could hang or grow runs in its own process under CPU and memory rlimits: a hang
or a blow-up fails the test instead of the machine."""
from __future__ import annotations

import hashlib
import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from strategies import toml_values
from test_cli_errors import COMPILE_NOTICE
from test_env_spec import SPEC, write_world

from tracelab.cli import main
from tracelab.envs import make_env
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.spec_file import SpecError, WorldStateError
from tracelab.errors import UserError

CPU_SECONDS = 240       # generous: each of these commands takes seconds; a hang or a cubic read takes hours
ADDRESS_SPACE = 4 << 30  # a command's imports and numba fit; the refused inputs would take far more
SECRET = "stolen-secret-7f3a"


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_CPU, (CPU_SECONDS, CPU_SECONDS))
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def tracelab(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """`tracelab ARGS` in its own process under the rlimits (timeout: a ceiling, never the assertion)."""
    return subprocess.run([sys.executable, "-m", "tracelab", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=2 * CPU_SECONDS, preexec_fn=_limited, check=False,
                          env={**os.environ, "HOME": str(cwd), "COLUMNS": "200"})


def one_error_line(p: subprocess.CompletedProcess) -> str:
    """The one line of a user error: exit 1, no traceback, not killed by a limit."""
    assert p.returncode == 1, (p.returncode, p.stderr[-2000:])
    assert "Traceback" not in p.stderr, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.strip() and not ln.startswith(COMPILE_NOTICE)]
    assert len(lines) == 1 and lines[0].startswith("tracelab: error: "), p.stderr
    return lines[0]


def hashes(root: Path) -> dict[str, str]:
    """Every file under root with its content's hash (links as their targets)."""
    out = {}
    for folder, _, files in os.walk(root):
        for name in files:
            p = Path(folder) / name
            out[str(p)] = "link " + os.readlink(p) if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def in_process_error(capsys: pytest.CaptureFixture, *argv: str) -> str:
    code = main(list(argv))
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracelab: error: "), err
    return lines[0]


# ---- §1: a spec reads no file outside its folder, whatever links it holds ----------------------------

@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A folder beside the spec's with a private file, and a rule file that would parse if read."""
    o = tmp_path / "private"
    o.mkdir()
    (o / "notes.txt").write_text(f"{SECRET} ( not rules\n")
    (o / "valid.rules").write_text(f"% mode override\nfact_{SECRET.replace('-', '_')}: at(c0_0)\n")
    return o


@pytest.mark.parametrize("how", ["file in a subfolder", "file beside the spec", "linked subfolder",
                                 "valid rules through a link"])
def test_a_rule_file_linked_outside_the_spec_folder_is_not_read(tmp_path: Path, outside: Path, how: str) -> None:
    world = tmp_path / "world"
    world.mkdir()
    (world / "sub").mkdir()
    name, link, target = {
        "file in a subfolder": ("sub/x.rules", world / "sub" / "x.rules", outside / "notes.txt"),
        "file beside the spec": ("x.rules", world / "x.rules", outside / "notes.txt"),
        "linked subfolder": ("far/notes.txt", world / "far", outside),
        "valid rules through a link": ("extra.rules", world / "extra.rules", outside / "valid.rules"),
    }[how]
    link.symlink_to(target)
    spec = write_world(world, SPEC.replace('rules = ["corridor.rules"]', f'rules = ["corridor.rules", "{name}"]'))
    before = hashes(tmp_path)
    p = tracelab("play", "--env", str(spec), "--episodes", "1", "--run", str(world / "run"), cwd=tmp_path)
    line = one_error_line(p)
    assert f"{spec}:2: env.rules[1]: '{name}': a link to a file outside the folder" in line
    assert SECRET not in p.stderr + p.stdout and SECRET.replace("-", "_") not in p.stderr + p.stdout
    assert hashes(tmp_path) == before  # no run written, nothing changed
    with pytest.raises(SpecError, match="a link to a file outside the folder"):
        load_spec(spec)


def test_a_link_that_stays_inside_the_folder_is_read(tmp_path: Path) -> None:
    write_world(tmp_path)
    (tmp_path / "rules").mkdir()
    (tmp_path / "rules" / "same.rules").symlink_to(tmp_path / "corridor.rules")
    spec = write_world(tmp_path, SPEC.replace('rules = ["corridor.rules"]', 'rules = ["rules/same.rules"]'))
    assert load_spec(spec).program.files == [str(tmp_path.resolve() / "corridor.rules")]


@pytest.mark.parametrize("name", ["corridor.rules\\u0000x", "\\u0000", "/etc/passwd", "../corridor.rules", ""])
def test_a_path_with_a_nul_byte_or_outside_is_one_located_line(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                                 name: str) -> None:
    spec = write_world(tmp_path, SPEC.replace('rules = ["corridor.rules"]', f'rules = ["{name}"]'))
    line = in_process_error(capsys, "play", "--env", str(spec), "--no-trace", "--episodes", "1")
    assert f"{spec}:2: env.rules[0]: " in line


# ---- §3: reading a spec is linear in its size ------------------------------------------------------------

@pytest.mark.parametrize("payload, fragment", [
    ("[" + " " * 20_000 + "a\n", "not valid TOML"),               # the header pattern's cubic backtracking
    ("[" + " " * 20_000 + "a" + " " * 20_000 + "\n", "not valid TOML"),
    ("[[" + "\t" * 30_000 + "x" + " " * 30_000 + "]\n", "not valid TOML"),
    ("a" + ".a" * 200_000 + " = 1\n", "more than 10 parts"),       # tomllib rebuilds every prefix: quadratic
    ("[" + "a." * 200_000 + "a]\n", "more than 10 parts"),
    ("[env]\nx = {" + "b." * 100_000 + "c = 1}\n", "more than 10 parts"),
], ids=["header-spaces", "header-spaces-both-sides", "array-header-tabs", "dotted-key", "dotted-header",
        "dotted-inline-key"])
def test_an_adversarial_spec_is_read_within_a_cpu_limit(tmp_path: Path, payload: str, fragment: str) -> None:
    spec = tmp_path / "big.toml"
    spec.write_text(payload)
    line = one_error_line(tracelab("play", "--env", str(spec), "--no-trace", "--episodes", "1", cwd=tmp_path))
    assert re.match(rf"tracelab: error: {re.escape(str(spec))}:[12]\b", line) and fragment in line, line


def test_strings_and_comments_full_of_dots_are_not_keys(tmp_path: Path) -> None:
    dots = "a." * 50
    spec = write_world(tmp_path, f"# {dots}\n" + SPEC.replace("[params]", f'[params]\nnote = "{dots}"\n'
                                                             f"other = '''{dots}\n{dots}'''"))
    assert load_spec(spec).params["note"] == dots


# ---- §4: a world that cannot end is refused when read -----------------------------------------------------

NO_END = SPEC[:SPEC.index("[end]")] + SPEC[SPEC.index("[start]"):]


def test_a_spec_without_an_end_is_refused_before_playing(tmp_path: Path) -> None:
    spec = write_world(tmp_path, NO_END)
    with pytest.raises(SpecError, match="the episode can never end: expected `terminated`, `truncated` or "
                                        "`max_steps`"):
        make_env(spec)
    line = one_error_line(tracelab("play", "--env", str(spec), "--episodes", "2", "--run", str(tmp_path / "run"),
                                   cwd=tmp_path))
    assert f"{spec}: end: the episode can never end" in line
    assert not (tmp_path / "run").exists()


def test_max_steps_alone_is_an_end(tmp_path: Path) -> None:
    env = make_env(write_world(tmp_path, NO_END + "\n[end]\nmax_steps = 3\n"))
    env.reset(seed=0)
    assert [env.step(2)[3] for _ in range(3)] == [False, False, True]


# ---- §8: a world state the spec cannot read is one located line -------------------------------------------

NEVER_INDEX = SPEC.replace("[reward]", '[[observation.parts]]\nname = "won"\nread = "index"\natoms = ["over(w)"]\n\n'
                                       "[reward]")
NO_WEIGHT = SPEC + '[[start.choose]]\natom = "at(C)"\nover = "cells"\nweights = "bot(C)"\n'


@pytest.mark.parametrize("spec_text, where, fragment", [
    (NEVER_INDEX, ":34: observation.parts[2]: ", "no atom of over(...) is true, so the part has no index"),
    (NO_WEIGHT, ":48: start.choose[0].weights: ", "no value's weights (bot(c0_0), ...) hold"),
], ids=["index-part-never-true", "no-start-weight-holds"])
def test_a_state_the_spec_cannot_read_is_one_located_line(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                           spec_text: str, where: str, fragment: str) -> None:
    spec = write_world(tmp_path, spec_text)
    with pytest.raises(WorldStateError) as e:
        make_env(spec).reset(seed=0)
    assert isinstance(e.value, RuntimeError) and str(e.value).startswith(f"{spec}{where}{fragment}")
    line = in_process_error(capsys, "play", "--env", str(spec), "--no-trace", "--episodes", "1")
    assert line == f"tracelab: error: {e.value}"


# ---- §8: a value of the wrong type at any key is one located line -----------------------------------------

_KEY_LINE = re.compile(r"^(\s*(?:[A-Za-z0-9_]+|\"[^\"]*\")\s*=\s*)(.*)$")
ROOT = Path(__file__).resolve().parent.parent
FROZEN_LAKE = ROOT / "rules" / "toytext" / "frozen_lake.toml"
SPECS = {"corridor": (SPEC, "corridor.rules"), "frozen_lake": (FROZEN_LAKE.read_text(), "frozen_lake.rules")}


def _key_lines(text: str) -> list[int]:
    return [i for i, ln in enumerate(text.splitlines()) if _KEY_LINE.match(ln)]


def _with_value(text: str, line: int, value: str) -> str:
    lines = text.splitlines()
    lines[line] = _KEY_LINE.match(lines[line]).group(1) + value
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("which", SPECS)
def test_any_value_at_any_key_plays_or_is_refused_in_one_located_line(tmp_path: Path, which: str) -> None:
    text, rules = SPECS[which]
    if which == "frozen_lake":
        (tmp_path / rules).write_text((FROZEN_LAKE.parent / rules).read_text())
    else:
        write_world(tmp_path)
    spec = tmp_path / f"{which}.toml"

    @settings(max_examples=150, deadline=None, database=None)
    @given(line=st.sampled_from(_key_lines(text)), value=toml_values())
    def plays_or_one_line(line: int, value: str) -> None:
        spec.write_text(_with_value(text, line, value))
        try:
            env = make_env(spec)
            env.reset(seed=0)
            for action in (0, 1, 1, 2):
                if any(env.step(action)[2:4]):
                    break
        except UserError as e:  # SpecError, WorldStateError, or a rule file's located error
            message = str(e)
            assert "\n" not in message and message.startswith(str(spec)), message

    plays_or_one_line()


@pytest.mark.parametrize("key, value, fragment", [
    ('atom = "at(C)"', "atom = 1", ':27: observation.parts[0].atom: expected an atom such as "p(a)", got the number 1'),
    ('atom = "at(C)"', "atom = [1]", ":27: observation.parts[0].atom: expected an atom"),
    ('atom = "at(C)"', "atom = 1979-05-27", ":27: observation.parts[0].atom: expected an atom"),
    ('over = "cells"', 'over = ["c0_0", {a = 1}]', ":28: observation.parts[0].over: expected"),
    ('rules = ["corridor.rules"]', "rules = [1]", ":2: env.rules: expected a list of strings, got a list of 1"),
])
def test_wrong_types_through_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture, key: str, value: str,
                                              fragment: str) -> None:
    spec = write_world(tmp_path, SPEC.replace(key, value))
    assert in_process_error(capsys, "play", "--env", str(spec), "--no-trace", "--episodes", "1") \
        .startswith(f"tracelab: error: {spec}{fragment}")


# ---- §9: a name the program does not know is a located error with a did-you-mean -------------------------

@pytest.mark.parametrize("old, new, fragment", [
    ('G = ["floor", "goal"]', 'G = ["floor", "gaol"]',
     ":9: board.legend.G[1]: no rule and no atom of the spec reads the predicate 'gaol'; did you mean goal?"),
    ("west = [0, -1], east", "wets = [0, -1], east",
     ":10: board.neighbours.wets: no rule and no atom of the spec reads the predicate 'wets'; did you mean west?"),
    ('over = "cells"', 'over = ["c0_0", "c0_1", "c0_2", "c0_03"]',
     ":28: observation.parts[0].over[3]: the program, the board and the agents have no constant 'c0_03'; "
     "did you mean c0_3"),
    ('"at(c0_3)" = "goal_reward"', '"at(c03)" = "goal_reward"',
     ":35: reward.table.at(c03): 'at(c03)': the program, the board and the agents have no constant 'c03'; "
     "did you mean c0_3"),
])
def test_a_misspelt_name_is_located_with_a_suggestion(tmp_path: Path, capsys: pytest.CaptureFixture, old: str,
                                                       new: str, fragment: str) -> None:
    assert old in SPEC
    spec = write_world(tmp_path, SPEC.replace(old, new))
    with pytest.raises(SpecError) as e:
        make_env(spec)
    assert str(e.value).startswith(f"{spec}{fragment}"), str(e.value)
    assert in_process_error(capsys, "play", "--env", str(spec), "--no-trace", "--episodes", "1") \
        == f"tracelab: error: {e.value}"


def test_a_start_choice_over_an_unknown_constant_is_refused(tmp_path: Path) -> None:
    spec = write_world(tmp_path, SPEC + '[[start.choose]]\natom = "at(C)"\nover = ["c0_0", "ful"]\n')
    with pytest.raises(SpecError, match=r":47: start\.choose\[0\]\.over\[1\]: the program, the board and the "
                                        r"agents have no constant 'ful'"):
        load_spec(spec)
