"""How much memory a declared world will take, estimated from its spec and its number of worlds before
anything is built, and the limit it must fit.

A spec from a stranger can ask for a board of millions of facts, thousands of agents each reading
thousands of atoms, or a million worlds: each is a few lines of TOML and gigabytes once built. spec.py
charges each thing to a `SpecBudget` just before it builds it (the board's facts once counted, each
section's atoms once their domain and the agents are known), and the worlds are charged before the
engine of a batch is made: past the limit the spec is refused in one line naming what asked for too much
and $TRACELAB_SPEC_MEMORY, which raises it. The figures are measured peaks rounded up (tests/bench sizes
are far below them); they tell a world that fits from one off by orders of magnitude."""
from __future__ import annotations


from tracelab.engine.safe_files import MIB, human_bytes, size_setting
from tracelab.errors import UserError

SPEC_MEMORY_ENV = "TRACELAB_SPEC_MEMORY"
# with tracelab's own ~250 MiB (numpy, numba, the engine), a spec refused at the default never takes the
# process past 1 GiB
DEFAULT_SPEC_MEMORY = 640 * MIB
# a board fact: its tuple and Fact in the spec's program, then the engine's atom, vocabulary entry and
# static fact (measured: 327k facts of a 256 x 256 board, 1.2 KiB in load_spec, 2.4 KiB by make_env)
BYTES_PER_BOARD_FACT = 2560
# an atom the spec names for each agent (an action's fact, a part's atom, a reward, an end): its Atom,
# its engine id and the reads' arrays (measured ~0.4 KiB in load_spec, 1 KiB by make_env)
BYTES_PER_SPEC_ATOM = 1024
# one more world of a batch, per engine atom: its bounds, the kernel's rows and the change flags
BYTES_PER_WORLD_ATOM = 64
# one env of gymnasium's SyncVectorEnv (train --env): its own engine, spec tables and wrappers, plus its
# atoms and the groundings over them (measured at 100-200 envs: FrozenLake 374 KiB with 140 atoms, Taxi
# 1.38 MiB with 2,653, war.toml's base 3.5 MiB with 3,264), rounded up
ENV_BYTES = 384 << 10
BYTES_PER_ENV_ATOM = 1024


class SpecTooBig(UserError):
    """A spec whose estimated memory passes the limit; the message is one line and names the limit."""


def spec_memory_limit() -> tuple[int, str]:
    """The limit (bytes) and how it was set: $TRACELAB_SPEC_MEMORY (a size: 2G, 800M), else the default."""
    given = size_setting(SPEC_MEMORY_ENV, SpecTooBig)
    if given is None:
        return DEFAULT_SPEC_MEMORY, f"the default; {SPEC_MEMORY_ENV}=2G raises it"
    return given, f"set by {SPEC_MEMORY_ENV}"


class SpecBudget:
    """What a spec has asked to build so far, in estimated bytes, against the limit."""

    def __init__(self) -> None:
        self.limit, self.source = spec_memory_limit()
        self.board_facts = 0
        self.atoms = 0

    @property
    def bytes(self) -> int:
        return self.board_facts * BYTES_PER_BOARD_FACT + self.atoms * BYTES_PER_SPEC_ATOM

    def board(self, facts: int) -> None:
        """Charge a board's facts (counted, not built); SpecTooBig past the limit."""
        self.board_facts += facts
        self._check(f"a board of {facts:,} facts")

    def charge(self, atoms: int, what: str) -> None:
        """Charge `atoms` ground atoms about to be made for `what` (such as "300 atoms for each of 5,000
        agents"); SpecTooBig past the limit."""
        self.atoms += atoms
        self._check(what)

    def ahead(self, atoms: int, what: str) -> None:
        """Refuse now if `atoms` more atoms, counted from the spec's text before any is made, would pass
        the limit (each is charged again when it is made)."""
        self._check(what, atoms)

    def _check(self, what: str, ahead: int = 0) -> None:
        need = self.bytes + ahead * BYTES_PER_SPEC_ATOM
        if need > self.limit:
            raise SpecTooBig(f"{what} brings the spec to about {human_bytes(need)} once built, over the limit "
                             f"of {human_bytes(self.limit)} ({self.source})")


def check_worlds(worlds: int, atoms: int, what: str = "worlds") -> None:
    """Refuse `worlds` worlds of an engine of `atoms` atoms past the limit, before they are made (`what`:
    how the caller names the number, such as "--num-envs 10000000")."""
    limit, source = spec_memory_limit()
    need = worlds * max(atoms, 1) * BYTES_PER_WORLD_ATOM
    if need > limit:
        raise SpecTooBig(f"{what}: {worlds:,} worlds of {atoms:,} atoms would take about {human_bytes(need)}, "
                         f"over the limit of {human_bytes(limit)} ({source})")


def env_bytes(named_atoms: int) -> int:
    """One env of its own (a declared world whose spec names `named_atoms` atoms, or 0 for another
    gymnasium env), as train --env makes `--num-envs` of them."""
    return ENV_BYTES + named_atoms * BYTES_PER_ENV_ATOM
