"""A Box or Dict observation in ONE compiled call: every part that reads truth (index, nearest, count,
onehot) of every agent and world; the `lower` and `bounds` parts are read after it, in numpy
(observe.bound_numbers).

Why: read part by part in numpy, an observation of war.toml's advanced game (7 parts, two of them
`nearest`) cost ~3 ms a step, ten times the engine step (tracelab bench env, docs/benchmarks.md).

The program (ObservationProgram) has one row per number of the observation, agent by agent, part by part:
`table` [numbers, 6] int64 (kind, first and last+1 column of the part's atoms in the truth table, the
first of its numbers in `values` or -1 for the index itself, things, board width), `missing` [numbers]
(NaN: none declared), `values` (every index and nearest part's numbers, float32) and `copy_table` [copies, 3]
(first column, source column, width: an agent that reads what an earlier one reads takes its numbers)."""
from __future__ import annotations

import inspect
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from tracelab.engine import kernel as K
from tracelab.engine.numba_cache import stamp_with_sources
from tracelab.envs.declared.observe import bound_numbers
from tracelab.envs.declared.spec import WorldSpec

if TYPE_CHECKING:
    from tracelab.engine import Engine

SKIP, INDEX, NEAREST, COUNT, TRUTH = 0, 1, 2, 3, 4
KINDS = {"index": INDEX, "nearest": NEAREST, "count": COUNT, "onehot": TRUTH}


class ObservationProgram:
    """The compiled reader's tables of a spec's Box or Dict observation, over engine atom ids
    `part_ids` [part][agent] (DeclaredWorld's). `python_parts`: the parts it leaves to
    observe.bound_numbers, with their first number's column."""

    def __init__(self, spec: WorldSpec, part_ids: list[list[np.ndarray]]) -> None:
        rows, missing, values, atoms = [], [], [np.zeros(0, np.float32)], [np.zeros(0, np.int64)]
        self.python_parts: list[tuple[int, int]] = []  # (part, column) per agent 0; others shifted by width
        # (agent, earlier agent) whose compiled parts read the same atoms (a team's shared view, as the war game's):
        # its rows are skipped and read() copies the earlier agent's numbers (20v20: 1 read of 20)
        self.copies: list[tuple[int, int]] = []
        seen: dict[tuple, int] = {}
        # parts that read the same atoms (the war game's x and y of an agent: its cell) share their truth columns
        placed: dict[bytes, int] = {}
        n_atoms = n_values = 0
        for agent in range(len(spec.agents)):
            key = tuple((k, part_ids[k][agent].tobytes()) for k, part in enumerate(spec.parts)
                        if KINDS.get(part.read, SKIP) != SKIP)
            copied = seen.setdefault(key, agent) != agent
            if copied:
                self.copies.append((agent, seen[key]))
            for k, part in enumerate(spec.parts):
                kind = KINDS.get(part.read, SKIP)
                if kind == SKIP or copied:
                    if agent == 0:
                        self.python_parts.append((k, len(rows)))
                    rows.extend([(SKIP, 0, 0, -1, 0, 0)] * part.width)
                    missing.extend([np.nan] * part.width)
                    continue
                ids = part_ids[k][agent]
                at = placed.setdefault(ids.tobytes(), n_atoms)
                if at == n_atoms:
                    atoms.append(ids)
                    n_atoms += len(ids)
                if kind == TRUTH:
                    rows.extend((TRUTH, at + j, at + j + 1, -1, 0, 0) for j in range(len(ids)))
                    missing.extend([np.nan] * len(ids))
                else:
                    first = -1
                    if kind in (INDEX, NEAREST) and part.value_array is not None:
                        first = n_values
                        values.append(part.value_array)
                        n_values += len(part.value_array)
                    rows.append((kind, at, at + len(ids), first, part.n_things, part.board_width))
                    missing.append(np.nan if part.missing is None else part.missing)
        self.width = len(rows) // max(len(spec.agents), 1)  # numbers per agent
        self.atoms = np.concatenate(atoms).astype(np.int64)  # the truth table's columns
        self.table = np.array(rows, np.int64).reshape(-1, 6)
        self.missing = np.array(missing, np.float64)
        self.values = np.concatenate(values).astype(np.float32)
        self.copy_table = np.array([(agent * self.width, source * self.width, self.width)
                                    for agent, source in self.copies], np.int64).reshape(-1, 3)


@njit(cache=True)
def observe_lower(lower, atoms, truth, table, missing, values, copies, obs):  # noqa: ANN001, ANN201
    """observe() on the truth of `atoms` read off the counting kernel's lower bounds [worlds, atoms]
    (an atom is true where [1,1]: its lower bound is 1)."""
    K.gather_truth(lower, atoms, 1.0, truth)
    observe(truth, table, missing, values, copies, obs)


@njit(cache=True)
def observe(truth, table, missing, values, copies, obs):  # noqa: ANN001, ANN201
    """obs [worlds, numbers] (float32) from truth [worlds, program atoms]: per row of `table`, an index
    part's number (the first true atom's), a nearest part's (the cell of the thing nearest the `from`
    cell, rows plus columns, a tie to the thing listed first), a count of true atoms, or one atom's truth;
    then the copied agents' numbers (`copies`: the program's copy_table)."""
    _observe_rows(truth, table, missing, values, obs)
    for w in range(obs.shape[0]):
        for r in range(copies.shape[0]):
            at, source, width = copies[r, 0], copies[r, 1], copies[r, 2]
            for k in range(width):  # not a slice assignment: its shape check's message took 5.7 s to compile
                obs[w, at + k] = obs[w, source + k]


@njit(cache=True)
def _observe_rows(truth, table, missing, values, obs):  # noqa: ANN001, ANN201
    """observe()'s numbers of every row of `table` (an index part over the same columns as the index part
    before it, as the war game's y after its x, takes that part's position)."""
    for w in range(truth.shape[0]):
        last_lo, last_hi, last_i = -1, -1, -1
        for c in range(table.shape[0]):
            kind, lo, hi, first, things, width = table[c, 0], table[c, 1], table[c, 2], table[c, 3], \
                table[c, 4], table[c, 5]
            if kind == SKIP:
                continue
            if kind == TRUTH:
                obs[w, c] = 1.0 if truth[w, lo] else 0.0
                continue
            if kind == COUNT:
                n = 0
                for j in range(lo, hi):
                    if truth[w, j]:
                        n += 1
                obs[w, c] = n
                continue
            if kind == INDEX:
                i = last_i if lo == last_lo and hi == last_hi else _first_true(truth, w, lo, hi)
                last_lo, last_hi, last_i = lo, hi, i
            else:
                cells = (hi - lo) // (1 + things)
                i = -1
                here = _first_true(truth, w, lo, lo + cells)
                if here >= 0:
                    best = -1
                    for t in range(things):
                        start = lo + (1 + t) * cells
                        at = _first_true(truth, w, start, start + cells)
                        if at >= 0:
                            d = abs(at // width - here // width) + abs(at % width - here % width)
                            if best < 0 or d < best:
                                best, i = d, at
            if i < 0 and missing[c] == missing[c]:  # not NaN: the part's number for none
                obs[w, c] = missing[c]
            elif first < 0:
                obs[w, c] = i
            else:
                obs[w, c] = values[first + max(i, 0)]


@njit(cache=True)
def _first_true(truth, w, lo, hi):  # noqa: ANN001, ANN201
    """The position from `lo` of the first true column in [lo, hi) of world w's row, -1 when none."""
    for j in range(lo, hi):
        if truth[w, j]:
            return j - lo
    return -1


for _f in (observe_lower, observe, _observe_rows, _first_true):
    stamp_with_sources(_f, (inspect.getmodule(observe), K))


class ObservationReader:
    """A program's buffers for `worlds` worlds of an engine, and the read of every agent's numbers."""

    def __init__(self, program: ObservationProgram, spec: WorldSpec, part_ids: list[list[np.ndarray]],
                 worlds: int) -> None:
        self.program, self._spec, self._part_ids = program, spec, part_ids
        self._truth = np.zeros((worlds, len(program.atoms)), np.bool_)
        self.numbers = np.zeros((worlds, len(program.table)), np.float32)

    @property
    def arrays(self) -> tuple[np.ndarray, ...]:
        """What observe_lower reads and writes after `lower`: (atoms, truth, table, missing, values, copies,
        numbers), for a caller that reads inside its own compiled step (vector_fused.step_worlds)."""
        p = self.program
        return p.atoms, self._truth, p.table, p.missing, p.values, p.copy_table, self.numbers

    def read(self, engine: Engine) -> np.ndarray:
        """numbers [worlds, agents * width] as the engine stands (the counting kernel's bounds are read
        in place; another kernel's truth comes from Engine.is_true)."""
        p, out = self.program, self.numbers
        if engine.kernel == "counting":
            observe_lower(engine.lower, *self.arrays)
        else:
            observe(engine.is_true(p.atoms), p.table, p.missing, p.values, p.copy_table, out)
        return self.finish(engine)

    def finish(self, engine: Engine) -> np.ndarray:
        """The parts the compiled read leaves to numpy (`lower`, `bounds`), after it; returns the numbers."""
        p, out = self.program, self.numbers
        for k, col in p.python_parts:  # lower and bounds: the engine's bounds, in numpy
            part = self._spec.parts[k]
            for agent, ids in enumerate(self._part_ids[k]):
                at = agent * p.width + col
                out[:, at:at + part.width] = bound_numbers(part, engine, ids)
        return out


def split_parts(spec: WorldSpec, numbers: np.ndarray) -> list[np.ndarray]:
    """One agent's numbers [worlds, width] as each part's [worlds, part.width], in the spec's order."""
    edges = np.cumsum([0] + [p.width for p in spec.parts])
    return [numbers[:, a:b] for a, b in zip(edges[:-1], edges[1:])]
