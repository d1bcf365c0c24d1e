"""RuleSim (the game as rules on the engine) against RefSim (hand-written), step by step, plus the rule
game's explainable trace.

The differential test draws a scenario (a built-in one, or a small generated map with 1-3 agents a team,
shooting on or off, sometimes slow agents, random starts, other ammo / health / damage / rewards),
1-4 worlds, and a stream of actions mixing uniform random ids from scenario.action_ids and each
simulator's scripted policy. Both simulators get the same actions; every StepResult field must be equal
(value, shape and dtype) after every step and every reset, including per-world resets of finished
worlds and steps sent to finished worlds before their reset.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tracelab.game.facts import agent_name, bullet_name
from tracelab.game.refsim import RefSim
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import (
    Rewards,
    Scenario,
    ScenarioError,
    SlowAgents,
    builtin_scenario,
    generate_scenario,
)
from tracelab.game.state import WINNER_RED, StepResult

FIELDS = [f.name for f in dataclasses.fields(StepResult)]
UP, LEFT, S_UP, S_RIGHT, NOP = 0, 2, 4, 7, 8
# Integer rewards, all different, so that a term counted under the wrong event cannot go unseen (the
# method's values have unsafe == got_shot) and sums are exact whatever their order.
DISTINCT_REWARDS = Rewards(win=1000, loss=-3000, hit_opponent=70, got_shot=-11, valid_action=-2,
                           unsafe=-300, invalid=-5)


# ----------------------------------------------------------------------------------------------------
# Scenarios and plans
# ----------------------------------------------------------------------------------------------------
@st.composite
def generated_scenarios(draw) -> Scenario:
    """A small generated map; sometimes random starts, slow agents, other ammo, health, damage, rewards."""
    width, height = draw(st.integers(3, 6)), draw(st.integers(3, 6))
    n = draw(st.integers(1, 3))
    sc = generate_scenario(width, height, n, draw(st.sampled_from([0.0, 0.1, 0.2, 0.3])),
                           seed=draw(st.integers(0, 2**16)), advanced=draw(st.booleans()),
                           max_steps=draw(st.integers(4, 40)))
    changes: dict = {}
    if draw(st.booleans()):  # random starts put agents near each other and their bullets
        free = [(x, y) for x in range(width) for y in range(height) if (x, y) not in sc.mountains]
        for t, key in enumerate(("red_starts", "blue_starts")):
            cells = [c for c in free if c != sc.bases[1 - t]]
            changes[key] = tuple(draw(st.lists(st.sampled_from(cells), min_size=n, max_size=n)))
    if draw(st.booleans()):
        changes["slow_agents"] = SlowAgents(
            red=draw(st.lists(st.integers(0, n - 1), max_size=n, unique=True)),
            blue=draw(st.lists(st.integers(0, n - 1), max_size=n, unique=True)))
    changes["ammo"] = draw(st.sampled_from([3, 3, 0, 1, 2]))
    health = draw(st.sampled_from([1.0, 1.0, 0.5, 2.0]))
    changes["health"] = health
    # one-hit kills, and 2, 3 or 4 hits to kill
    changes["damage"] = health * draw(st.sampled_from([1.0, 1.0, 1.5, 0.5, 0.34, 0.25]))
    if draw(st.booleans()):
        changes["rewards"] = DISTINCT_REWARDS
    try:
        return dataclasses.replace(sc, **changes)
    except ScenarioError:  # a start in a pocket cut off by mountains: keep the bases as starts
        changes.pop("red_starts", None), changes.pop("blue_starts", None)
        return dataclasses.replace(sc, **changes)


@st.composite
def builtin_scenarios(draw) -> Scenario:
    sc = builtin_scenario(draw(st.sampled_from(["base", "advanced", "nonmarkov"])))
    # shorter games, so that truncation and per-world resets happen within a short run
    return dataclasses.replace(sc, max_steps=draw(st.sampled_from([sc.max_steps, 6, 15, 30])))


@dataclasses.dataclass(frozen=True)
class Plan:
    scenario: Scenario
    n_worlds: int
    stack_previous: bool
    seed: int          # the scripted policy's rng (the same in both simulators)
    action_seed: int   # the stream of random actions and of choices below
    p_scripted: float  # per team and step: scripted policy, else uniform random actions
    p_reset: float     # per step with a finished world: reset the finished worlds now (else step on)
    steps: int
    kernel: str = "counting"  # the engine kernel of RuleSim

    def __repr__(self) -> str:  # what hypothesis prints for a falsifying example
        s = self.scenario
        return (f"Plan(n_worlds={self.n_worlds}, stack_previous={self.stack_previous}, seed={self.seed}, "
                f"action_seed={self.action_seed}, p_scripted={self.p_scripted}, p_reset={self.p_reset}, "
                f"steps={self.steps}, kernel={self.kernel!r}, scenario=\n{s.to_toml()})")


plans = st.builds(
    Plan,
    scenario=st.one_of(builtin_scenarios(), generated_scenarios(), generated_scenarios()),
    n_worlds=st.integers(1, 4),
    stack_previous=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
    action_seed=st.integers(0, 2**32 - 1),
    p_scripted=st.sampled_from([0.0, 0.5, 0.8, 1.0]),
    p_reset=st.sampled_from([1.0, 0.5]),
    steps=st.integers(10, 80),
    kernel=st.sampled_from(["counting", "lanes"]),
)


# ----------------------------------------------------------------------------------------------------
# Comparison
# ----------------------------------------------------------------------------------------------------
def assert_same_arrays(what: str, ref: np.ndarray, rule: np.ndarray) -> None:
    ref, rule = np.asarray(ref), np.asarray(rule)
    assert ref.shape == rule.shape, f"{what}: shape {ref.shape} (RefSim) != {rule.shape} (RuleSim)"
    assert ref.dtype == rule.dtype, f"{what}: dtype {ref.dtype} (RefSim) != {rule.dtype} (RuleSim)"
    if not np.array_equal(ref, rule):
        where = np.argwhere(ref != rule)[:5].tolist()
        raise AssertionError(f"{what} differs at {where}: RefSim {[ref[tuple(i)] for i in where]} "
                             f"!= RuleSim {[rule[tuple(i)] for i in where]}")


def assert_same_result(step_no: int, ref: StepResult, rule: StepResult, finished: np.ndarray,
                       stack_previous: bool) -> None:
    """All fields equal; `finished`: worlds that were already over before this step."""
    for name in FIELDS:
        a, b = getattr(ref, name), getattr(rule, name)
        assert_same_arrays(f"step {step_no}: {name}", a, b)


def run_side_by_side(plan: Plan) -> tuple[int, int]:
    """Step both simulators with the plan's actions, comparing everything; returns (episodes ended, hits)."""
    sc, n_worlds = plan.scenario, plan.n_worlds
    sims = [RefSim(sc, n_worlds, seed=plan.seed, stack_previous=plan.stack_previous),
            RuleSim(sc, n_worlds, seed=plan.seed, stack_previous=plan.stack_previous, kernel=plan.kernel)]
    assert_same_arrays("reset obs", *(s.reset() for s in sims))
    rng = np.random.default_rng(plan.action_seed)
    ids = np.array(sc.action_ids)
    shape = (n_worlds, sc.agents_per_team)
    ended = hits = 0
    done_before = np.zeros(n_worlds, bool)
    stepped_when_over = np.zeros(n_worlds, bool)  # worlds stepped after they finished, not reset since
    for k in range(plan.steps):
        acts = []
        for team in ("red", "blue"):
            if rng.random() < plan.p_scripted:
                ref_a, rule_a = (s.scripted_actions(team) for s in sims)  # same state, same rng: same choice
                assert_same_arrays(f"step {k}: scripted actions of {team}", ref_a, rule_a)
                acts.append(ref_a)
            else:
                acts.append(ids[rng.integers(0, len(ids), shape)])
        results = [s.step(*acts) for s in sims]
        stepped_when_over |= done_before
        assert_same_result(k, *results, finished=done_before, stack_previous=plan.stack_previous)
        ref = results[0]
        hits += int(ref.hits_taken.sum())
        ended += int((ref.done & ~done_before).sum())
        done_before = ref.done.copy()
        if ref.done.any():
            if rng.random() < plan.p_reset:  # otherwise finished worlds get (ignored) actions first
                mask = ref.done.copy()
                done_before[mask] = stepped_when_over[mask] = False
                worlds = mask if rng.random() < 0.5 else np.flatnonzero(mask)  # a mask or indices
                obs = [s.reset(worlds=worlds) for s in sims]
                assert_same_arrays(f"step {k}: obs after reset(worlds={worlds})", *obs)
                for name in ("alive", "ammo", "pos", "t", "terminated", "winner"):
                    assert_same_arrays(f"step {k}: state.{name} after reset",
                                       *(getattr(s.state, name) for s in sims))
        elif rng.random() < 0.03:  # now and then, restart some worlds in mid-game, or all with a new seed
            if rng.random() < 0.7:
                mask = rng.random(n_worlds) < 0.5
                obs = [s.reset(worlds=mask) for s in sims]
            else:
                mask = np.ones(n_worlds, bool)
                obs = [s.reset(seed=k) for s in sims]
            assert_same_arrays(f"step {k}: obs after reset(worlds={mask}) in mid-game", *obs)
            done_before[mask] = stepped_when_over[mask] = False
    # the observation each simulator hands out now (obs of the last step or reset)
    for team in ("red", "blue"):
        a, b = (s.observe(team) for s in sims)
        assert_same_arrays(f"final observe({team})", a, b)
    return ended, hits


@settings(max_examples=90, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(plan=plans)
def test_rulesim_matches_refsim_step_by_step(plan):
    run_side_by_side(plan)


def test_history_of_a_finished_world_stepped_again():
    # base, max_steps=1, stack_previous: red moves up and the world is truncated; a second step is sent
    # before reset. Both simulators repeat the last observation, history half included (docs/game.md).
    sc = dataclasses.replace(builtin_scenario("base"), max_steps=1)
    sims = [cls(sc, stack_previous=True) for cls in (RefSim, RuleSim)]
    for s in sims:
        s.reset()
    first = [s.step([UP], [NOP]).copy() for s in sims]  # kept past the next step
    assert first[0].truncated[0] and first[1].truncated[0]
    assert_same_result(0, *first, finished=np.zeros(1, bool), stack_previous=False)
    again = [s.step([UP], [NOP]) for s in sims]  # ignored by the finished world
    assert_same_arrays("obs of the ignored step", again[0].obs, again[1].obs)
    np.testing.assert_array_equal(again[0].obs, first[0].obs)


def test_differential_runs_reach_the_interesting_situations():
    # A fixed, busy run: many shots, hits, deaths and per-world resets, so the comparison is not vacuous
    # even if hypothesis happens to draw quiet games.
    sc = dataclasses.replace(generate_scenario(5, 5, 3, 0.1, seed=7, advanced=True, max_steps=25),
                             slow_agents=SlowAgents(red=[2], blue=[0]))
    ended, hits = run_side_by_side(Plan(sc, n_worlds=4, stack_previous=True, seed=1, action_seed=2,
                                        p_scripted=0.7, p_reset=1.0, steps=150))
    assert ended >= 20 and hits >= 50  # this run: 40 episodes, 198 hits


# ----------------------------------------------------------------------------------------------------
# The rule game leaves an explainable trace
# ----------------------------------------------------------------------------------------------------


def trace_rows(sim: RuleSim) -> list[dict]:
    """The engine's change rows since the last call, each with the atom's text and the cause's name."""
    tr = sim.engine.take_trace()
    e = sim.engine
    return [{"atom": e.atom_text(int(tr["atom"][i])),
             "cause": e.cause_name(int(tr["cause_kind"][i]), int(tr["cause_id"][i])),
             "why": e.grounding_text(int(tr["grounding"][i])),
             "old": (tr["old_lower"][i], tr["old_upper"][i]), "new": (tr["new_lower"][i], tr["new_upper"][i]),
             "world": int(tr["world"][i])}
            for i in range(len(tr["atom"]))]


def situation(red, blue, mountains=()) -> Scenario:
    return Scenario(name="trace", width=8, height=8, red_base=(7, 0), blue_base=(0, 7), mountains=mountains,
                    red_starts=red, blue_starts=blue, advanced=True)


@pytest.mark.parametrize("kind", ["point_blank", "bullet"])
def test_trace_explains_a_hit_and_the_death_it_causes(kind):
    red, blue = agent_name(0, 0), agent_name(1, 0)
    bullet = bullet_name(0, 0, 0)
    if kind == "point_blank":  # red shoots on its own cell, where blue stands
        sim = RuleSim(situation([(3, 1)], [(3, 1)]), trace=True)
        sim.reset()
        trace_rows(sim)
        r = sim.step([S_UP], [NOP])
        hit_atom, hit_rule, count_rule = f"blanked({bullet},{blue})", "w_blank", "hm_blanked"
    else:  # red's bullet flies right from (1,1) and reaches blue on (3,1) at the third step
        sim = RuleSim(situation([(1, 1)], [(3, 1)]), trace=True)
        sim.reset()
        sim.step([S_RIGHT], [NOP])
        r = sim.step([NOP], [NOP])
        assert r.alive.all()
        trace_rows(sim)
        r = sim.step([NOP], [NOP])
        hit_atom, hit_rule, count_rule = f"struck({bullet},{blue})", "b_hit", "hm_struck"
    assert not r.alive[0, 1, 0] and r.winner[0] == WINNER_RED  # the game saw the kill
    rows = trace_rows(sim)
    hit = [x for x in rows if x["atom"] == hit_atom]
    assert len(hit) == 1 and hit[0]["cause"] == hit_rule and hit[0]["new"] == (1.0, 1.0)
    assert f"A={blue}" in hit[0]["why"] and f"B={bullet}" in hit[0]["why"]  # which bullet, which agent
    # the hit is counted against blue's health (hitMe names the bullet), that count kills, the kill is
    # the death
    counted = [x for x in rows if x["atom"] == f"hitMe({bullet},{blue})"]
    assert len(counted) == 1 and counted[0]["cause"] == count_rule and f"B={bullet}" in counted[0]["why"]
    killed = [x for x in rows if x["atom"] == f"killed({blue})"]
    assert len(killed) == 1 and killed[0]["cause"] == "h_killed" and killed[0]["new"] == (1.0, 1.0)
    death = [x for x in rows if x["atom"] == f"alive({blue})"]
    assert len(death) == 1 and death[0]["old"] == (1.0, 1.0) and death[0]["new"] == (0.0, 0.0)
    assert death[0]["cause"] == "d_killed" and f"A={blue}" in death[0]["why"]
    assert not any(x["atom"] == f"alive({red})" for x in rows)  # the shooter is untouched


@pytest.mark.parametrize("red_start, mountains, rule", [((7, 1), [(6, 1)], "u_left_mtn"),   # into a mountain
                                                        ((0, 3), [], "u_left_edge")])      # off the map
def test_trace_explains_an_unsafe_move_and_the_shield(red_start, mountains, rule):
    sim = RuleSim(situation([red_start], [(0, 7)], mountains), trace=True)
    sim.reset()
    trace_rows(sim)
    r = sim.step([LEFT], [NOP])
    red = agent_name(0, 0)
    assert r.unsafe[0, 0, 0] and tuple(r.positions[0, 0, 0]) == red_start
    rows = trace_rows(sim)
    unsafe = [x for x in rows if x["atom"] == f"unsafe({red})"]
    assert len(unsafe) == 1 and unsafe[0]["new"] == (1.0, 1.0)
    assert unsafe[0]["cause"].startswith("u_") and unsafe[0]["cause"] == rule
    # the shield: the agent's location atoms do not change in this step (no move, no dest either)
    assert not [x for x in rows if x["atom"].startswith(f"atLoc({red},") or x["atom"].startswith(f"dest({red},")]
    cell = red_start[1] * 8 + red_start[0]
    assert sim.engine.query(f"atLoc({red},{cell})") == (1.0, 1.0)
    r = sim.step([UP], [NOP])  # a safe move afterwards: the trace shows the agent leave and arrive
    rows = trace_rows(sim)
    moved = {x["atom"]: (x["new"], x["cause"]) for x in rows if x["atom"].startswith(f"atLoc({red},")}
    assert moved == {f"atLoc({red},{cell})": ((0.0, 0.0), "m_leave"),
                     f"atLoc({red},{cell + 8})": ((1.0, 1.0), "m_go")}
    assert not r.unsafe.any()


def test_an_agent_on_no_cell_reads_back_as_minus_one_not_the_last_cell():
    """A broken rule that leaves an agent on no cell shows as position (-1, -1), not as the map's last
    cell (what indexing the cell table with 'not found' would read)."""
    from tracelab.game.rulesim_kernel import read_and_settle

    sim = RuleSim(builtin_scenario("base"), 1, seed=0, fused=False)
    truth = sim.engine.is_true(sim._read_atoms)
    truth[:, sim._read_tables[0][0]] = False  # red agent 0 on no cell
    read_and_settle(truth, *sim._settle_args)
    pos = sim._state_buffers["pos"]
    assert pos[0, 0, 0].tolist() == [-1, -1]
    assert (pos[0, 1, 0] >= 0).all()
