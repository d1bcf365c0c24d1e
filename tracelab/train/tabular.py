"""The optimal tabular policy of a declared world, by value iteration over the rules' own transitions.

The transitions are not read from any table: from each state the world reaches, every action and every
value of each random fact (with its declared probability) is stepped through the engine, the world put
back into the state before each try (DeclaredWorld.save_state / load_state). A state is its observation
(a Discrete one, as the toy-text games have); the step limit makes it a finite-horizon problem, so the
value at the start with γ = 1 and a reward of 1 for the goal is the best success rate any policy reaches
within the limit (docs/experiments/toytext.md)."""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tracelab.envs.declared.spec import WorldSpec
from tracelab.envs.declared.world import DeclaredWorld

MAX_STATES = 100_000  # a world with more observations is no tabular problem: refused before it grows


@dataclass
class Transitions:
    """outcomes[s][a]: (probability, next state, reward, terminated) of each way the step can go;
    start: the probability of each state at the start of an episode."""
    n_states: int
    n_actions: int
    outcomes: dict[int, list[list[tuple[float, int, float, bool]]]]
    start: dict[int, float]


def _draw_values(spec: WorldSpec) -> list[list[tuple[int, float]]]:
    """Per random fact drawn before a step, its possible (value index, probability)."""
    out = []
    for d in spec.random_facts:
        if d.after is not None:  # drawn only if its atom holds after the step: _NoDraws refuses it then
            continue
        if d.probabilities is None or d.method != "categorical":
            raise ValueError(f"{spec.path}: random fact {d.name!r}: value iteration enumerates draws with fixed "
                             f"probabilities only")
        out.append([(i, float(p)) for i, p in enumerate(d.probabilities) if p > 0])
    return out


class _NoDraws:
    """The generator of an enumerated step: every draw before the step is given, so a draw here is an
    `after` random fact that fired (Taxi's fickle passenger), which value iteration does not enumerate."""

    def random(self) -> float:
        raise ValueError("an `after` random fact was drawn: value iteration enumerates draws before the step only")

    integers = random


def enumerate_transitions(spec: WorldSpec, start_seeds: int = 64) -> Transitions:
    """Every transition of the states reachable from the start, stepped through the engine. The start
    distribution is read from `start_seeds` seeded resets (exact for a world with one start state)."""
    if spec.space != "Discrete" or len(spec.agents) != 1:
        raise ValueError(f"{spec.path}: value iteration needs one agent and a Discrete observation")
    world = DeclaredWorld(spec)
    n_actions = len(spec.action_names)
    draws = _draw_values(spec)
    starts: dict[int, float] = {}
    saved: dict[int, tuple] = {}
    for seed in range(start_seeds):
        world.reset(np.random.default_rng(seed))
        s = int(world.observation())
        starts[s] = starts.get(s, 0.0) + 1.0 / start_seeds
        if s not in saved and not world.terminated():
            saved[s] = world.save_state()
    todo = list(saved)
    outcomes: dict[int, list[list[tuple[float, int, float, bool]]]] = {}
    while todo:
        s = todo.pop()
        state = saved[s]
        outcomes[s] = per_action = []
        for a in range(n_actions):
            ways = []
            for combo in itertools.product(*draws):
                world.load_state(state)
                world.step(a, _NoDraws(), draws=[v for v, _ in combo])
                nxt, reward, term = int(world.observation()), float(world.last_rewards[0]), world.terminated()
                ways.append((float(np.prod([p for _, p in combo])), nxt, reward, term))
                if not term and nxt not in saved:
                    if len(saved) >= MAX_STATES:
                        raise ValueError(f"{spec.path}: more than {MAX_STATES:,} states: no tabular problem")
                    saved[nxt] = world.save_state()
                    todo.append(nxt)
            per_action.append(ways)
    n_states = max([*saved, *(w[1] for per in outcomes.values() for ways in per for w in ways)]) + 1
    return Transitions(n_states, n_actions, outcomes, starts)


def value_iteration(tr: Transitions, horizon: int, gamma: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(V [S] of the optimal policy with `horizon` steps left, its greedy actions [S] at that horizon)."""
    v = np.zeros(tr.n_states)
    policy = np.zeros(tr.n_states, np.int64)
    for _ in range(horizon):
        new = np.zeros(tr.n_states)
        for s, per_action in tr.outcomes.items():
            q = [sum(p * (r + (0.0 if term else gamma * v[s2])) for p, s2, r, term in ways) for ways in per_action]
            policy[s] = int(np.argmax(q))
            new[s] = max(q)
        v = new
    return v, policy


def optimal_start_value(tr: Transitions, horizon: int, gamma: float = 1.0) -> float:
    """The optimal expected return from the start (a success rate when the goal pays 1 and nothing else
    pays)."""
    v, _ = value_iteration(tr, horizon, gamma)
    return float(sum(p * v[s] for s, p in tr.start.items()))
