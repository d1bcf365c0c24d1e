"""Specs from strangers that ask for too much (issues 37.2 and 43.4): expressions that build gigabytes or
compare nested lists for minutes, boards just under the fact cap, thousands of agents or observation
parts, and batches of millions of worlds. Each is refused in one line `tracelab: error: FILE:LINE: KEY:
...` naming the limit and what raises it, before anything big is built. Commands run in a subprocess
with a timeout (a hang fails, not blocks) and caps on address space and CPU seconds (a regression fails
with MemoryError or SIGXCPU instead of taking the machine)."""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import tracemalloc
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_env_spec import SPEC, write_world
from test_strangers_sizes import one_error_line

from tracelab.expressions import (
    MAX_EXPRESSION_STEPS,
    MAX_VALUE_ITEMS,
    Evaluation,
    ExpressionError,
)
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.spec_size import SPEC_MEMORY_ENV

ADDRESS_SPACE = 3 << 30  # a command's imports and numba fit; the payloads' gigabytes do not
CPU_SECONDS = 120  # a ceiling far above what a refusal takes; main spent minutes on these


def _capped() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))
    resource.setrlimit(resource.RLIMIT_CPU, (CPU_SECONDS, CPU_SECONDS))


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, timeout=300, check=False,
                          preexec_fn=_capped, env={**os.environ, **(env or {})})


def play(spec: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return run("-m", "tracelab", "play", "--env", str(spec), "--episodes", "1", "--no-trace", env=env)


def payload_world(folder: Path, old: str, new: str) -> Path:
    assert old in SPEC
    return write_world(folder, SPEC.replace(old, new, 1))


# ---- expressions (issue 37.2) -------------------------------------------------------------------------

NESTED = "[[[[[0] * 1000] * 1000] * 1000] * 1000] * 1000"  # 10^15 items, shared: 4 KB until walked


@pytest.mark.parametrize("old, new, where, fragment", [
    # a 1 GB, 5.1 GB and 2 GB string from a 60-byte expression
    ("scale = 2", "scale = \"len('%0999999999d' % 0)\"", "37: reward.scale", "width or precision of 999999999"),
    ("scale = 2", "scale = \"len('%04999999999d' % 0)\"", "37: reward.scale", "of 4999999999"),
    ("scale = 2", "scale = \"len('%.999999999f' % 1.5)\"", "37: reward.scale", "at most 100"),
    # a row string built by % reached 1 GB before the board's cell count refused it
    ('rows = ["S..G"]', "rows = \"['S%04999999999d' % 0]\"", "8: board.rows", "width or precision"),
    # nested list comparisons: 21-54 s of CPU, or (10^15 items) never ending and deaf to Ctrl-C
    ("scale = 2", f'scale = "1 if {NESTED} == {NESTED} else 2"', "37: reward.scale", "items"),
    ('rows = ["S..G"]', "rows = \"[['F'] * 100000] * 20000\"", "8: board.rows", "a value of 100,001 items"),
])
def test_expressions_that_would_build_too_much_are_refused_first(tmp_path: Path, old: str, new: str, where: str,
                                                                  fragment: str) -> None:
    spec = payload_world(tmp_path, old, new)
    line = one_error_line(play(spec))
    assert line.startswith(f"tracelab: error: {spec}:{where}:") and fragment in line, line


def test_comparing_big_nested_values_spends_the_step_budget() -> None:
    """Two distinct lists of 80,000 items each may be built, but comparing them again and again is paid
    item by item from the budget and stops there, not after minutes."""
    a = "[[[0] * 20] * 20] * 200"
    e = Evaluation({"a": [[[0] * 20] * 20] * 200, "b": [[[0] * 20] * 20] * 200})
    with pytest.raises(ExpressionError, match="more than 1,000,000 steps"):
        e.run(" == ".join(["a", "b"] * 20))
    assert e.steps <= MAX_EXPRESSION_STEPS + 2 * 84_201
    assert Evaluation({}).run(f"{a} == {a}") is True  # within budget it is computed


# A random expression over the language's every operation, its numbers and strings chosen to hit the
# limits: huge repeat counts and widths, nested lists, formats, comparisons, calls.
_ATOMS = st.sampled_from([
    "0", "1", "-1", "7", "999999999", "10000000000000000000", "1.5", "1e308", "'a'", "'F' * 300", "''",
    "'%s'", "'%099d'", "'%0999999d'", "'%.99f'", "'%(k)s'", "'%*d'", "'%%'", "'%c'", "'%r'", "[]", "[0]",
    "[[0] * 300] * 300", "['x'] * 99", "m", "n", "s", "True", "None", "'9' * 4000",
])
_CALLS = ("len", "min", "max", "abs", "float", "int")
_BINARY = ("+", "-", "*", "/", "//", "%", "==", "<", "in", "!=", ">=", "and", "or")


def _expression(children: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    return st.one_of(
        st.tuples(children, st.sampled_from(_BINARY), children).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(st.sampled_from(_CALLS), children).map(lambda t: f"{t[0]}({t[1]})"),
        st.lists(children, max_size=4).map(lambda xs: f"[{', '.join(xs)}]"),
        st.tuples(children, children, children).map(lambda t: f"({t[0]} if {t[1]} else {t[2]})"),
        st.tuples(children, children).map(lambda t: f"{t[0]}[{t[1]}]"),
        children.map(lambda x: f"(not {x})"), children.map(lambda x: f"(-{x})"),
    )


EXPRESSIONS = st.recursive(_ATOMS, _expression, max_leaves=12)
NAMES = {"m": {"k": "v" * 1000}, "n": [[1, 2], [3]], "s": "SFFG"}


def _items(v: object, cap: int) -> int:
    """v's size through every nesting (a string's characters), counted up to `cap`."""
    if isinstance(v, str):
        return len(v)
    if isinstance(v, (list, dict)):
        total = 1
        for x in (v if isinstance(v, list) else [*v, *v.values()]):
            total += _items(x, cap - total)
            if total > cap:
                break
        return total
    return 1


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(EXPRESSIONS)
def test_any_expression_is_computed_within_budget_or_refused_in_one_line(text: str) -> None:
    e = Evaluation(NAMES)
    tracemalloc.start()
    try:
        value = e.run(text)
    except ExpressionError as err:
        assert "\n" not in str(err) and str(err)
        value = None
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert e.steps <= MAX_EXPRESSION_STEPS
    assert _items(value, 10 * MAX_VALUE_ITEMS) <= MAX_VALUE_ITEMS + 1
    assert peak < 64 << 20, (text, peak)  # a value of 100,000 items is a few MB at most


def test_expression_errors_through_a_spec_are_located(tmp_path: Path) -> None:
    spec = payload_world(tmp_path, "scale = 2", "scale = \"len('%s' % [1, 2])\"")
    with pytest.raises(Exception) as err:
        load_spec(spec)
    assert str(err.value).startswith(f"{spec}:37: reward.scale: ") and "numbers and strings" in str(err.value)


# ---- sizes (issue 43.4) -------------------------------------------------------------------------------

def _board_spec(folder: Path, rows: int, cols: int, far: int) -> Path:
    """The corridor world on a rows x cols board with `far` more neighbour offsets: a cell's legend fact
    and 2 + far neighbour facts (edge = "none" drops those leaving the board)."""
    offsets = ", ".join(f"[0, {k}]" for k in range(1, far + 1))
    spec = payload_world(folder, "neighbours = { west = [0, -1], east = [0, 1] }",
                         f"neighbours = {{ west = [0, -1], east = [0, 1], far = [{offsets}] }}")
    with (folder / "corridor.rules").open("a") as rules:  # a predicate no rule reads is refused by name
        rules.write("far_seen:  far_seen(C) <-! at(C), far(C,E)\n")
    return _rewrite(spec, 'rows = ["S..G"]', f"rows = \"['S' + '.' * {cols - 2} + 'G'] * {rows}\"")


def _rewrite(spec: Path, old: str, new: str) -> Path:
    text = spec.read_text()
    assert old in text
    spec.write_text(text.replace(old, new, 1))
    return spec


def test_a_board_just_under_the_fact_cap_is_refused_before_its_facts_are_built(tmp_path: Path) -> None:
    spec = _board_spec(tmp_path, 256, 256, 26)  # 1,900,800 facts counted, under the 2,000,000 cap
    line = one_error_line(play(spec))
    assert f"{spec}:7: board: a board of 1,900,800 facts" in line and "over the limit of 640 MiB" in line, line
    assert f"{SPEC_MEMORY_ENV}=2G raises it" in line


def test_the_spec_memory_variable_sets_the_limit(tmp_path: Path) -> None:
    spec = _board_spec(tmp_path, 32, 32, 2)  # 5,120 facts: about 12.5 MiB
    line = one_error_line(play(spec, env={SPEC_MEMORY_ENV: "5M"}))
    assert "over the limit of 5 MiB (set by TRACELAB_SPEC_MEMORY)" in line, line
    assert play(spec).returncode == 0
    line = one_error_line(play(spec, env={SPEC_MEMORY_ENV: "lots"}))
    assert "TRACELAB_SPEC_MEMORY='lots': expected a size such as 8G" in line, line


def test_a_thousand_observation_parts_over_a_big_board_are_refused(tmp_path: Path) -> None:
    part = '[[observation.parts]]\nname = "w{i}"\nread = "onehot"\natom = "at(C)"\nover = "cells"\n'
    spec = payload_world(tmp_path, '[[observation.parts]]\nname = "where"',
                         "".join(part.format(i=i) for i in range(1000)) + '[[observation.parts]]\nname = "where"')
    _rewrite(spec, 'rows = ["S..G"]', "rows = \"['S' + '.' * 62 + 'G'] * 64\"")
    line = one_error_line(play(spec))  # counted from the text, before the board's facts are made
    assert f"{spec}:14: agents.names: 4,100,109 atoms brings the spec to about" in line, line


def test_fifty_thousand_agents_are_refused_before_their_atoms_are_made(tmp_path: Path) -> None:
    agents = ", ".join(f'"a{i}"' for i in range(50_000))
    spec = payload_world(tmp_path, 'names = ["robo"]', f"names = [{agents}]")
    line = one_error_line(play(spec))
    assert f"{spec}:14: agents.names: 17 atoms for each of 50,000 agents brings the spec to about" in line, line


def test_a_batch_of_ten_million_worlds_is_refused_before_its_engine(tmp_path: Path) -> None:
    spec = write_world(tmp_path)
    p = run("-c", "import sys; from tracelab.envs import make_vec_env\n"
                  "from tracelab.errors import UserError\n"
                  f"try: make_vec_env({str(spec)!r}, 10_000_000)\n"
                  "except UserError as e: sys.exit(str(e))")
    err = p.stderr.decode().strip()
    assert p.returncode == 1 and "\n" not in err, err
    assert err.startswith("num_envs=10,000,000: 10,000,000 worlds of ") and "over the limit of 640 MiB" in err
