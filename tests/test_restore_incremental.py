"""The counting kernel's restore rebuilds a world's active lists from the snapshot instead of copying
every grounding's entries (engine/restore_kernel.py). Against the full copy it replaced: random programs
(aggregates and every inconsistency policy included) and the game at 1 and 5 agents a team, random
snapshots and restores of random worlds, and every array that is read afterwards, and every trace row,
must be the same."""
from __future__ import annotations

import os

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from strategies import scenarios
from test_lanes import assert_same
from tracelab.engine import Engine
from tracelab.engine.errors import FixpointError, InconsistencyError

from tracelab.bench.sims import team_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds

SCALE = float(os.environ.get("TRACELAB_EXAMPLES", "1"))


def full_copy_restore(eng: Engine, snap: dict, worlds: np.ndarray, source: np.ndarray | None = None) -> None:
    """Engine.restore, then the groundings' arrays copied whole from the snapshot (the code before);
    `source`: the snapshot's worlds they take (Engine.restore's)."""
    worlds = np.flatnonzero(worlds) if np.asarray(worlds).dtype == np.bool_ else np.asarray(worlds)
    Engine.restore(eng, snap, worlds, source)
    st_ = eng._state
    if snap["unsat"].shape == st_._unsat.shape and snap["lower"].shape[1] == st_.n_atoms:  # else it recounts
        for key, arr in (("unsat", st_._unsat), ("act", st_._act), ("act_pos", st_._act_pos),
                         ("act_n", st_._act_n)):
            arr[worlds] = snap[key][worlds if source is None else np.asarray(source)]


def assert_same_groundings(a: Engine, b: Engine, where: str) -> None:
    sa, sb = a._state, b._state
    np.testing.assert_array_equal(sa._unsat, sb._unsat, err_msg=f"unsat {where}")
    np.testing.assert_array_equal(sa._act_pos, sb._act_pos, err_msg=f"act_pos {where}")
    np.testing.assert_array_equal(sa._act_n, sb._act_n, err_msg=f"act_n {where}")
    for w in range(a.n_worlds):  # the lists' live prefixes, in order (the firing order follows them)
        for k, base in enumerate(sa._kind_base):
            n = sa._act_n[w, k]
            np.testing.assert_array_equal(sa._act[w, base:base + n], sb._act[w, base:base + n],
                                          err_msg=f"active list {k} of world {w} {where}")


@settings(max_examples=int(80 * SCALE), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sc=scenarios(per_world=3, aggregates=True), seed=st.integers(0, 2**16))
def test_restore_matches_the_full_copy_on_random_programs(sc, seed: int) -> None:  # noqa: ANN001
    rng = np.random.default_rng(seed)
    a = Engine(sc.program, sc.graph, kernel="counting", worlds=3, max_passes=40, max_immediate=200, trace=True)
    b = Engine(sc.program, sc.graph, kernel="counting", worlds=3, max_passes=40, max_immediate=200, trace=True)
    snaps: list[tuple[dict, dict]] = []
    for t in range(sc.steps + 3):
        for w, per_step in enumerate(sc.world_externals or []):
            for f in (per_step[t] if t < len(per_step) else []):
                for eng in (a, b):
                    eng.add_fact(eng.atom(f.pred, *f.args), f.lower, f.upper, world=w, static=f.static)
        try:
            a.step()
        except (InconsistencyError, FixpointError):
            return  # the kernels' own tests cover errors; restores are what is tested here
        b.step()
        assert_same(a, b, t)
        assert_same_groundings(a, b, f"at t={t}")
        if rng.random() < 0.5:
            snaps.append((a.snapshot(), b.snapshot()))
        if snaps and rng.random() < 0.6:
            sa, sb = snaps[rng.integers(len(snaps))]
            back = np.flatnonzero(rng.random(3) < 0.5)
            a.restore(sa, back)
            full_copy_restore(b, sb, back)
            assert_same_groundings(a, b, f"after the restore of worlds {back.tolist()} at t={t}")


def test_restore_matches_the_full_copy_in_the_game() -> None:
    """GridWar's spec (war.toml's base game) on the declared batch: its resets (a restore of a start state
    at every episode end) against the full copy."""
    for agents, steps in ((1, 300), (5, 120)):
        spec = team_spec(agents)
        batches = [DeclaredWorlds(spec, 4, kernel="counting") for _ in range(2)]
        for b in batches:
            b.use_generators([np.random.default_rng(1 + w) for w in range(4)])
            b.engine.trace_on[:] = True
            b.reset(np.arange(4))
        a, b = batches
        b.engine.restore = lambda snap, worlds, source=None, eng=b.engine: full_copy_restore(  # the code before
            eng, snap, worlds, source)
        rng = np.random.default_rng(agents)
        restored = 0
        for t in range(steps):
            red = rng.integers(0, a.n_actions, (4, agents))
            for x in batches:
                x.step(red)
            assert_same(a.engine, b.engine, t)
            done = a.terminated() | a.truncated(None)
            np.testing.assert_array_equal(done, b.terminated() | b.truncated(None))
            if done.any():
                for x in batches:
                    x.reset(np.flatnonzero(done))
                restored += 1
                assert_same_groundings(a.engine, b.engine, f"after resets at step {t}")
        assert restored  # episodes ended, so that resets were compared
