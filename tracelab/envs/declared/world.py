"""A declared world running: the spec's program on the engine, facts in and atoms out, one world.

Timeline (docs/worlds.md, "How a step runs"):
- built: the engine's t = 0 applies the program's and the board's facts; every atom the env will set
  (actions, random facts, start facts and choices) is set to [0,0] there, so that the rules are grounded
  for them; the state after it is the snapshot every episode starts from.
- reset: the snapshot is restored, the start choices are drawn from np_random (in the spec's order) and
  one engine step applies the start facts and the chosen atoms ([1,1], or the fact's bound).
- step: the action's facts and one value of each random fact (drawn in the spec's order) are set for the
  step; last step's facts that are not set again go back to [0,0]. One engine step; the reward is read.
  Then each `after` random fact whose atom is true is drawn, and if any was, one more engine step applies
  them (the step's facts back to [0,0]) and its reward is added. The observation and ends are read last.
Draws follow gymnasium: "categorical" is `categorical_sample` (one `np_random.random()` u, the first
value whose cumulative probability exceeds u), "choice" is `np_random.choice` over the possible values
(one `integers(0, n)`), so a seeded world draws exactly as gymnasium's toy-text games do."""
from __future__ import annotations

from typing import Any

import numpy as np

from tracelab.engine import Engine
from tracelab.envs.declared.spec import Atom, Draw, WorldSpec


def categorical(cumulative: list[float], rng: np.random.Generator) -> int:
    """gymnasium.envs.toy_text.utils.categorical_sample, draw for draw: one rng.random() u, and the first
    value whose cumulative probability (np.cumsum of the probabilities, the same float64 sums) exceeds u,
    or value 0 when none does (argmax of all-false)."""
    u = rng.random()
    for i, c in enumerate(cumulative):
        if c > u:
            return i
    return 0


class _Drawer:
    """One Draw's engine ids and how it picks a value."""

    def __init__(self, draw: Draw, ids: Any) -> None:
        self.draw = draw
        self.value_ids = [ids(atoms) for atoms in draw.atoms]
        self.value_bounds = [_bounds(atoms) for atoms in draw.atoms]
        self.cumulative = None if draw.probabilities is None else np.cumsum(draw.probabilities).tolist()
        self.weight_ids = None if draw.weights is None else \
            np.array([ids(w) for w in draw.weights], np.int64).reshape(len(draw.weights), -1)
        self.after = None if draw.after is None else ids([draw.after])

    def pick(self, world: DeclaredWorld, rng: np.random.Generator) -> int:
        d = self.draw
        if self.weight_ids is None:
            if d.method == "choice":
                return int(rng.integers(0, len(self.value_ids)))
            return categorical(self.cumulative, rng)  # type: ignore[arg-type]
        w = self.weight_ids
        ok = world.engine.is_true(w.ravel())[0].reshape(w.shape).all(axis=1)
        possible = np.flatnonzero(ok)
        if possible.size == 0:
            raise RuntimeError(f"{world.spec.path}: {'.'.join(map(str, d.key))}: no value's weights "
                               f"({', '.join(map(str, d.weights[0]))}, ...) hold: nothing to draw from")
        if d.method == "choice":
            return int(possible[rng.integers(0, possible.size)])
        p = ok.astype(np.float64)
        p /= p.sum()  # as gymnasium normalises initial_state_distrib
        return categorical(np.cumsum(p).tolist(), rng)


class DeclaredWorld:
    """One world of `spec` on its own engine (`kernel`: the engine's; `trace`: its change log)."""

    def __init__(self, spec: WorldSpec, *, kernel: str = "auto", trace: bool = False) -> None:
        self.spec = spec
        self.engine = eng = Engine(spec.program, worlds=1, trace=trace, kernel=kernel)
        ids = self._ids
        self._action_ids = [ids(facts) for facts in spec.action_facts[0]]
        self._action_bounds = [_bounds(f) for f in spec.action_facts[0]]
        self._choices = [_Drawer(d, ids) for d in spec.start_choices]
        self._before = [_Drawer(d, ids) for d in spec.random_facts if d.after is None]
        self._after = [_Drawer(d, ids) for d in spec.random_facts if d.after is not None]
        self._start_ids, self._start_bounds = ids(spec.start_facts), _bounds(spec.start_facts)
        env_set = [self._start_ids, *self._action_ids]
        for drawer in (*self._choices, *self._before, *self._after):
            env_set.extend(drawer.value_ids)
        env_set_ids = np.unique(np.concatenate([np.zeros(0, np.int64), *env_set]))
        if env_set_ids.size:
            eng.add_facts(env_set_ids, 0.0, 0.0)
        # what is read after each step
        self._part_ids = [ids(p.atoms) for p in spec.parts]
        self._mask_ids = ids(spec.mask[0]) if spec.mask is not None else None
        self._table_ids = ids(a for a, _ in spec.reward_table)
        self._table_values = np.array([v for _, v in spec.reward_table], np.float64)
        self._scaled_ids = ids(a for a, _ in spec.reward_scaled)
        self._scales = np.array([s for _, s in spec.reward_scaled], np.float64)
        self._term_ids, self._trunc_ids = ids(spec.terminated), ids(spec.truncated)
        board = spec.board
        self._marks = [] if board is None else \
            [(ch, np.array([eng.atom(pred, c) for c in board.cells], np.int64)) for pred, ch in board.marks.items()]
        eng.step()  # t = 0: the program's and the board's facts
        self._snapshot = eng.snapshot()
        self._set_now = np.zeros(0, np.int64)  # the step facts set by the last engine step
        self.steps = 0
        self.last_reward = 0.0

    def _ids(self, atoms: Any) -> np.ndarray:
        return np.array([self.engine.atom(a.pred, *a.args) for a in atoms], np.int64)

    # ---- episode ----

    def reset(self, rng: np.random.Generator) -> None:
        self.engine.restore(self._snapshot, np.array([0]))
        atoms, bounds = [self._start_ids], [self._start_bounds]
        for drawer in self._choices:
            i = drawer.pick(self, rng)
            atoms.append(drawer.value_ids[i])
            bounds.append(drawer.value_bounds[i])
        self._step_engine(np.concatenate(atoms), np.concatenate(bounds))
        self._set_now = np.zeros(0, np.int64)
        self.steps = 0

    def step(self, action: int, rng: np.random.Generator) -> None:
        """Set the action's facts and this step's random facts, step the engine (twice when an `after`
        random fact is drawn); the reward of the step is then `last_reward`."""
        new, bounds = [self._action_ids[action]], [self._action_bounds[action]]
        for drawer in self._before:
            i = drawer.pick(self, rng)
            new.append(drawer.value_ids[i])
            bounds.append(drawer.value_bounds[i])
        self._set_step_facts(np.concatenate(new), np.concatenate(bounds))
        reward = self._read_reward()
        if self._after:
            new, bounds = [], []
            for drawer in self._after:
                if self.true(drawer.after)[0]:
                    i = drawer.pick(self, rng)
                    new.append(drawer.value_ids[i])
                    bounds.append(drawer.value_bounds[i])
            if new:
                self._set_step_facts(np.concatenate(new), np.concatenate(bounds))
                reward += self._read_reward()
        self.last_reward = reward
        self.steps += 1

    def _set_step_facts(self, now: np.ndarray, bounds: np.ndarray) -> None:
        """One engine step with `now` set and the last step's facts that are not set again false."""
        again = set(now.tolist())
        off = np.array([a for a in self._set_now.tolist() if a not in again], np.int64)
        self._step_engine(np.concatenate([off, now]), np.concatenate([np.zeros((len(off), 2)), bounds]))
        self._set_now = now

    def _step_engine(self, atoms: np.ndarray, bounds: np.ndarray) -> None:
        eng = self.engine
        n = len(atoms)
        rows = np.empty((n, 3), np.int64)
        rows[:, 0] = atoms
        rows[:, 1] = 0
        rows[:, 2] = eng.next_external_id() + np.arange(n)
        eng.step(external=(np.array([0, n], np.int64), rows, np.ascontiguousarray(bounds, np.float64)))

    # ---- reading ----

    def true(self, ids: np.ndarray) -> np.ndarray:
        return self.engine.is_true(ids)[0]

    def part_values(self, i: int) -> np.ndarray:
        """Observation part i's numbers (an index: one int64; else float32)."""
        part, ids = self.spec.parts[i], self._part_ids[i]
        if part.read == "index":
            hit = self.true(ids)
            if not hit.any():
                raise RuntimeError(f"{self.spec.path}: observation part {part.name!r}: no atom of "
                                   f"{part.atoms[0].pred}(...) is true, so it has no index")
            return np.array([int(np.argmax(hit))], np.int64)
        if part.read == "onehot":
            return self.true(ids).astype(np.float32)
        lower = self.engine.lower[0, ids].astype(np.float32)
        if part.read == "lower":
            return lower
        return np.stack([lower, self.engine.upper[0, ids].astype(np.float32)], axis=1).ravel()

    def _read_reward(self) -> float:
        r = float(self._table_values[self.true(self._table_ids)].sum()) if len(self._table_ids) else 0.0
        if len(self._scaled_ids):
            r += float((self.engine.lower[0, self._scaled_ids] * self._scales).sum())
        return r

    def terminated(self) -> bool:
        return bool(len(self._term_ids) and self.true(self._term_ids).any())

    def truncated(self) -> bool:
        limit = self.spec.max_steps
        return bool((limit is not None and self.steps >= limit)
                    or (len(self._trunc_ids) and self.true(self._trunc_ids).any()))

    def action_mask(self) -> np.ndarray | None:
        return None if self._mask_ids is None else self.true(self._mask_ids).astype(np.int8)

    def marked_cells(self) -> dict[str, str]:
        """Board cell -> the mark of a `marks` predicate true there (for the text rendering)."""
        cells = self.spec.board.cells if self.spec.board is not None else []
        return {cells[k]: ch for ch, aids in self._marks for k in np.flatnonzero(self.true(aids))}


def _bounds(atoms: tuple[Atom, ...]) -> np.ndarray:
    return np.array([[a.lower, a.upper] for a in atoms], np.float64).reshape(len(atoms), 2)
