"""The compiled backend (kernel="compiled": engine/codegen.py, compile_cache.py, backend_compiled.py).

Differential: the compiled kernel and the counting kernel, stepped in lockstep on the same inputs, must
give the same intervals, the same trace rows in the same order and the same statistics, and fail at the
same step with the same error. Each distinct rule program is one numba compile (tens of seconds), so the
random programs are two fixed ones (hypothesis, derandomized), with different facts per world; compiled
kernels are kept in the normal cache (tracelab.engine.compile_cache.cache_root) so that a rerun pays
nothing.
"""
from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from strategies import Scenario, scenarios
from test_engine_vs_reference import MAX_IMMEDIATE, MAX_PASSES, WORLDS, run_and_compare
from tracelab.commands._args import ENGINE_KERNELS
from tracelab.engine import Engine, parse_program
from tracelab.engine import compile_cache as cc
from tracelab.engine.backend_compiled import unsupported
from tracelab.engine.codegen import Specialisation, generate
from tracelab.engine.core import KERNELS
from tracelab.engine.errors import FixpointError, InconsistencyError
from tracelab.engine.program import Rule
from tracelab.bench.sims import team_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds

FEW_PROGRAMS = settings(max_examples=2, derandomize=True, database=None, deadline=None,
                        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
SMALL = """
r1: b(X) <-0 a(X), e(X,Y)
r2: c(Y):[0.2,0.9] <-1 b(X), e(X,Y)
r3: a(Y) <-0 c(Y):[0.5,1]
a(n1)
e(n1,n2)
e(n2,n1)
"""


def _tables(text: str, **kw: object) -> Specialisation:
    eng = Engine(parse_program(text), kernel="counting", **kw)
    return Specialisation.of(eng._cfg, eng._rule_i, eng._rule_f)


def test_kernel_choices_of_the_cli_are_the_engines() -> None:
    assert ENGINE_KERNELS == KERNELS


def test_generated_source_folds_the_programs_tables() -> None:
    src = generate(_tables(SMALL))
    assert "rule_i[r, RULE_MODE]" not in src and "cfg[CFG_POLICY]" not in src
    assert "_RULE_UPPER = np.array([1.0, 0.9, 1.0]" in src  # bounds differ: a constant array
    assert "_RULE_DELAY = np.array([0, 1, 0]" in src
    spec, other_spec = _tables(SMALL), _tables("%inconsistency keep_old\n" + SMALL)
    assert generate(other_spec) != src
    assert cc.CacheEntry(other_spec).key != cc.CacheEntry(spec).key
    renamed = _tables(SMALL.replace("r1:", "first:") + "a(n2)\n")  # names and facts are not compiled in
    assert cc.CacheEntry(renamed).key == cc.CacheEntry(spec).key


def test_the_cache_key_follows_library_versions(monkeypatch: pytest.MonkeyPatch) -> None:
    spec = _tables(SMALL)
    key = cc.CacheEntry(spec).key
    real = cc.versions()
    monkeypatch.setattr(cc, "versions", lambda: {**real, "numba": real["numba"] + ".post1"})
    assert cc.CacheEntry(spec).key != key


def test_auto_takes_the_compiled_kernel_only_when_cached(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(cc.CACHE_ENV, str(tmp_path))
    eng = Engine(parse_program(SMALL))
    assert eng.kernel == "counting" and eng.kernel_notice is None
    assert not (tmp_path / "compiled").exists()  # nothing generated, nothing compiled


@dataclasses.dataclass(frozen=True)
class _FutureRule(Rule):
    """A rule with a language feature the compiled backend does not know (as issue 14 adds them)."""
    threshold: str | None = None  # not `quantifier`: that name is Rule's method


def test_a_program_with_an_unknown_feature_falls_back_with_a_notice(caplog: pytest.LogCaptureFixture) -> None:
    program = parse_program(SMALL)
    program.rules[1] = _FutureRule(**{f.name: getattr(program.rules[1], f.name)
                                      for f in dataclasses.fields(Rule)}, threshold=">= 50%")
    assert unsupported(program) == "rule r2 (<string>:3:1) uses threshold"
    eng = Engine(program, kernel="compiled")
    assert eng.kernel == "counting"
    (notice,) = caplog.records  # one warning on the engine's logger
    err = notice.getMessage()
    assert "rule r2" in err and "threshold" in err and "counting kernel" in err


# ---- differential: compiled against counting ----

def _lockstep(make, drive, steps: int) -> None:  # noqa: ANN001
    """make(kernel) -> (engine owner, engine); drive(owner, t) steps it. Compares after every step."""
    a_owner, a = make("counting")
    b_owner, b = make("compiled")
    assert (a.kernel, b.kernel) == ("counting", "compiled")
    for t in range(steps):
        errors = []
        for owner in (a_owner, b_owner):
            try:
                drive(owner, t)
                errors.append(None)
            except (InconsistencyError, FixpointError) as e:
                errors.append((type(e), str(e)))
        assert errors[0] == errors[1], f"t={t}"
        ta, tb = a.take_trace(), b.take_trace()
        assert ta.keys() == tb.keys()
        for col in ta:
            np.testing.assert_array_equal(ta[col], tb[col], err_msg=f"trace column {col} at t={t}")
        np.testing.assert_array_equal(a.lower, b.lower)
        np.testing.assert_array_equal(a.upper, b.upper)
        np.testing.assert_array_equal(a.static, b.static)
        for name, col in a.stats.items():
            np.testing.assert_array_equal(col, b.stats[name], err_msg=f"stat {name} at t={t}")
        if errors[0] is not None:
            return


def _run_program(sc: Scenario) -> None:
    per_world = bool(sc.world_externals)

    def make(kernel: str):  # noqa: ANN202
        eng = Engine(sc.program, sc.graph, worlds=WORLDS, trace=True, max_passes=MAX_PASSES,
                     max_immediate=MAX_IMMEDIATE, kernel=kernel)
        return eng, eng

    def drive(eng: Engine, t: int) -> None:
        for w in range(WORLDS if per_world else 1):
            for f in (sc.world_externals[w][t] if per_world else sc.externals[t]):
                eng.add_fact(eng.atom(f.pred, *f.args), f.lower, f.upper, world=w if per_world else None,
                             static=f.static)
        eng.step()

    _lockstep(make, drive, sc.steps)


@FEW_PROGRAMS
@given(scenarios(per_world=WORLDS))
def test_random_programs(sc: Scenario) -> None:
    """Against the counting kernel in lockstep, then against the reference (the same compiled kernel)."""
    _run_program(sc)
    run_and_compare(sc, kernel="compiled")


@pytest.mark.parametrize(("agents", "worlds", "steps"), [(1, 1, 300), (1, 4, 300), (5, 3, 300), (20, 1, 30)])
def test_the_game_batched_with_restores(agents: int, worlds: int, steps: int) -> None:
    """GridWar's spec (war.toml's base game: team size and map are facts, not compiled in) at 1, 5 and 20
    agents a team, its worlds stepped by the declared batch (the counting kernel inside the world's fused
    step, the compiled one on its own); 300 steps see episodes end and worlds restored, 20v20 (slow to step)
    is checked for its first 30."""
    spec = team_spec(agents)
    Engine(spec.program, kernel="compiled").step()  # compiled here (or loaded): a world does it in a child
    restores = []

    def make(kernel: str):  # noqa: ANN202
        batch = DeclaredWorlds(spec, worlds, kernel=kernel)
        batch.use_generators([np.random.default_rng(7 + w) for w in range(worlds)])
        batch.engine.trace_on[:] = True
        batch.reset(np.arange(worlds))
        return (batch, np.random.default_rng(7)), batch.engine

    def drive(owner, t: int) -> None:  # noqa: ANN001
        batch, rng = owner
        done = batch.terminated() | batch.truncated(None)
        if done.any():  # episode ends: those worlds are restored to the start state
            restores.append(t)
            batch.reset(np.flatnonzero(done))
        # red random from a generator seeded alike; blue: the rules' opponent with the worlds' own draws
        batch.step(rng.integers(0, batch.n_actions, (worlds, batch.n_agents)))

    _lockstep(make, drive, steps)
    if steps >= 300:  # the run did restore worlds (otherwise this test would not cover restores)
        assert restores


def test_compile_command_then_cached_load(tmp_path) -> None:
    """`tracelab compile` on a program already compiled above reports the cached kernel; a program the
    backend cannot take is a one-line user error."""
    rules = tmp_path / "small.rules"
    rules.write_text(SMALL)
    Engine(parse_program(SMALL), kernel="compiled").step()  # compiled (or loaded) in the normal cache
    out = subprocess.run([sys.executable, "-m", "tracelab.cli", "compile", str(rules)], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "loaded (already cached)" in out.stderr and "3 rules" in out.stderr
    assert (cc.cache_root() / out.stdout.strip().rsplit("/", 1)[-1] / "ready.json").exists()
    bad = tmp_path / "missing.rules"
    out = subprocess.run([sys.executable, "-m", "tracelab.cli", "compile", str(bad)], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 1 and out.stderr.startswith("tracelab: error:") and out.stderr.count("\n") == 1
