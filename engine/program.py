"""The parsed form of a rule program: plain, immutable data shared by the parser, the grounder,
the compiled engine and the reference evaluator."""
from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

# the bound test and the spelling of names live in light modules (a reader of runs needs them alone);
# the engine's modules import them from here too
from .bounds import EPS, effective_bound, satisfies  # noqa: F401
from .spelling import CONSTANT_RE, PREDICATE_RE  # noqa: F401

UPDATE_MODES = ("intersection", "override")
TIMESTEP_MODES = ("persistent", "reset")
INCONSISTENCY_POLICIES = ("reset_freeze", "keep_old", "take_new", "hull", "abort")
EDGE_HEAD_MODES = ("any", "graph")  # `%edge_heads`: where a binary rule head may set atoms
# Limits of the compiled engine, checked with the program (docs/language.md). Times are stored in int32
# and a delayed firing is due at t + delay, so times and delays stay well inside it; the kernel counts a
# grounding's unsatisfied binding clauses in an int8.
MAX_TIME = 1_000_000_000
MAX_BINDING_CLAUSES = 127



def constant_text(name: str) -> str:
    """A constant as the rule language writes it: bare when it is a plain constant, else quoted ("X",
    "a b(c)"; 'say "hi"' when it holds a double quote), so that printed atoms parse back."""
    if CONSTANT_RE.fullmatch(name):
        return name
    return f"'{name}'" if '"' in name else f'"{name}"'


def unwritable_constant(name: str) -> str | None:
    """Why `name` cannot be written as a constant of the rule language (quotes have no escapes and end on
    their line), or None."""
    if not name:
        return "it is empty"
    if '"' in name and "'" in name:
        return "it holds both quote characters"
    if "\n" in name or "\r" in name:
        return "it holds a line break"
    return None


@dataclass(frozen=True)
class SourceLoc:
    file: str
    line: int
    column: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"


@dataclass(frozen=True)
class Term:
    name: str  # a call's is its text, `first(X)`
    is_var: bool
    # a head function call `first(X, b)` in a rule head (engine/head_functions.py): its name and arguments
    function: str | None = None
    call_args: tuple[Term, ...] = ()

    @property
    def variables(self) -> tuple[str, ...]:
        """The variables this argument reads: itself, or a call's variable arguments."""
        if self.is_var:
            return (self.name,)
        return tuple(a.name for a in self.call_args if a.is_var)


@dataclass(frozen=True)
class Literal:
    pred: str
    args: tuple[Term, ...]
    lower: float = 1.0
    upper: float = 1.0
    negated: bool = False  # `~p(X)`: the complement [1-u, 1-l] of p's interval is what is tested / set
    loc: SourceLoc | None = field(default=None, compare=False)

    @property
    def variables(self) -> tuple[str, ...]:
        return tuple(v for t in self.args for v in t.variables)

    @property
    def calls(self) -> bool:
        """Whether an argument is a head function call."""
        return any(t.function is not None for t in self.args)

    @property
    def binds(self) -> bool:
        """A clause binds its variables unless its bound contains [0,1] (then every atom satisfies it)."""
        return not (self.lower <= 0.0 and self.upper >= 1.0)

    def __str__(self) -> str:
        args = ",".join(t.name for t in self.args)
        neg = "~" if self.negated else ""
        return f"{neg}{self.pred}({args}):[{self.lower:g},{self.upper:g}]"


COMPARISONS = (">=", ">", "<=", "<", "==")


@dataclass(frozen=True)
class Quantifier:
    """`[>= 50% available]` before a body clause: how many of the clause's candidates (per head grounding)
    must satisfy it (docs/language.md, "Quantifiers"). `value` is a count, or a percentage when `percent`."""
    op: str  # one of COMPARISONS
    value: float
    percent: bool = False
    available: bool = False  # count only candidates whose atom is not [0,1]
    loc: SourceLoc | None = field(default=None, compare=False)

    def __str__(self) -> str:
        if self.op == "==" and self.percent and self.value == 100.0:
            count = "forall"
        else:
            count = f"{self.op} {self.value:g}{'%' if self.percent else ''}"
        return f"[{count}{' available' if self.available else ''}]"


@dataclass(frozen=True)
class Rule:
    name: str
    head: Literal
    body: tuple[Literal, ...]
    delay: int = 0
    immediate: bool = False
    mode: str | None = None  # None: the program's mode
    loc: SourceLoc | None = field(default=None, compare=False)
    text: str = field(default="", compare=False)
    set_static: bool = False  # `{set_static}`: the head atom is frozen once the rule fires
    infer_edges: bool = False  # `{infer_edges}`: under `%edge_heads graph`, an edge head may leave the graph's edges
    # per body clause its quantifier or None; () when no clause has one
    quantifiers: tuple[Quantifier | None, ...] = ()
    annotation: str | None = None  # an annotation function computes the head's bound (`p(X):average`)
    weights: tuple[float, ...] = ()  # per body clause, for the annotation function (`{weights=1,2}`)

    @property
    def described(self) -> str:
        """'rule NAME (FILE:LINE:COL)', as messages name it (without a place when it has none)."""
        return _described("rule", self.name, self.loc)

    def quantifier(self, i: int) -> Quantifier | None:
        return self.quantifiers[i] if i < len(self.quantifiers) else None

    @property
    def aggregated(self) -> bool:
        """Evaluated per head grounding (a quantified clause or an annotation function)."""
        return self.annotation is not None or any(q is not None for q in self.quantifiers)

    def binding_clauses(self, closed: Collection[str] = ()) -> list[int]:
        """Indices of the clauses that enumerate (bind) variables: not quantified, and not true of an atom
        nothing set (`clause_binds`; `closed`: the program's %closed predicates)."""
        return [i for i, c in enumerate(self.body) if self.quantifier(i) is None and clause_binds(c, c.pred in closed)]

    def watched_clauses(self) -> list[int]:
        """Indices of the clauses each grounding tests (the counting kernel watches their atoms): not
        quantified (a quantified clause is counted per head group) and not true of every interval."""
        return [i for i, c in enumerate(self.body) if self.quantifier(i) is None and c.binds]

    @property
    def variables(self) -> tuple[str, ...]:
        """Variables in order of first appearance, head first: the order that sorts groundings."""
        seen: dict[str, None] = {}
        for lit in (self.head, *self.body):
            for v in lit.variables:
                seen.setdefault(v, None)
        return tuple(seen)


@dataclass(frozen=True)
class Fact:
    name: str
    literal: Literal  # ground
    start: int = 0
    end: int = 0
    static: bool = False
    loc: SourceLoc | None = field(default=None, compare=False)
    text: str = field(default="", compare=False)

    @property
    def described(self) -> str:
        """'fact NAME (FILE:LINE:COL)', as messages name it (without a place when it has none)."""
        return _described("fact", self.name, self.loc)


def _described(kind: str, name: str, loc: SourceLoc | None) -> str:
    return f"{kind} {name} ({loc})" if loc else f"{kind} {name}"


@dataclass
class Program:
    rules: list[Rule] = field(default_factory=list)
    facts: list[Fact] = field(default_factory=list)
    mode: str = "intersection"
    timesteps: str = "persistent"
    inconsistency: str = "reset_freeze"
    edge_heads: str = "any"  # `%edge_heads graph`: edge heads without {infer_edges} stay on the graph's edges
    closed: tuple[str, ...] = ()  # `%closed p`: predicates whose [0,1] atoms read as [0,0] in bodies
    files: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def constants(self) -> list[str]:
        """Every constant of the program, in order of first appearance (facts and rules in file order)."""
        seen: dict[str, None] = {}
        for item in sorted([*self.facts, *self.rules], key=_file_order):
            lits = (item.literal,) if isinstance(item, Fact) else (item.head, *item.body)
            for lit in lits:
                for t in lit.args:
                    for c in t.call_args if t.function is not None else (t,):  # a call's constant arguments
                        if not c.is_var:
                            seen.setdefault(c.name, None)
        return list(seen)


def _file_order(item: Rule | Fact) -> tuple[str, int, int]:
    loc = item.loc
    return (loc.file, loc.line, loc.column) if loc else ("", 0, 0)


def ordered_nodes(program: Program, graph_nodes: list[str] | tuple[str, ...] = ()) -> list[str]:
    """The node order both evaluators use: graph nodes first, then the program's other constants in order
    of first appearance. Nodes met later (external facts) are appended in order of arrival."""
    seen: dict[str, None] = dict.fromkeys(graph_nodes)
    for c in program.constants():
        seen.setdefault(c, None)
    return list(seen)


# Bounds come from text and from 1 - x (complements); a small tolerance keeps 1 - 0.9 inside [0.1, 1].
def clause_binds(lit: Literal, closed: bool) -> bool:
    """Whether a body clause enumerates its variables: it does not hold of an atom nothing ever set
    ([0,1], read as [0,0] on a closed predicate), so each of its groundings needs a settable atom. A
    clause that holds of unset atoms cannot enumerate: it is only tested (if it is not trivially true,
    `Literal.binds` false, it is still watched)."""
    return lit.binds and not (closed and satisfies(0.0, 0.0, lit))
