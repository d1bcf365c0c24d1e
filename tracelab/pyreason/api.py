"""PyReason's module-level API (`import tracelab.pyreason as pr`): the program is gathered with PyReason's
calls (`load_graphml`, `add_rule`, `add_fact`, ...), and `reason()` translates it (translate.py) and runs
it with the engine through tracelab.reasoning.EpisodeRun, the path `tracelab reason --dialect pyreason`
takes. With `settings.tracelab_run` (or `record(DIR)`) the reasoning is recorded into a tracelab run as
`tracelab reason --run` records it. What tracelab does not have raises UnsupportedFeature naming it.

The state is module-level, as in PyReason: one program per process."""
from __future__ import annotations

import copy
import dataclasses
import os
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.engine import Graph
from tracelab.engine.program import SourceLoc
from tracelab.errors import UserError

from .facts import PFact, read_facts
from tracelab.frozen_imports import import_frozen
from .files import PyReasonFileError
from .graphml import load_pyreason_graphml, load_pyreason_networkx
from .interpretation import Interpretation
from .names import NameMap
from .objects import Fact, Interval, Query, Rule
from .rules import PRule, read_rules, read_rules_txt
from .ruleset_filter import filter_ruleset
from .settings import Settings, settings_dict
from .trace_csv import PyReasonTrace
from .unsupported import UnsupportedFeature, unsupported
from .translate import translate

# reason(timesteps=-1) runs until convergence; a program that never converges stops here with an error
MAX_TIMESTEPS_UNTIL_CONVERGED = 100_000


@dataclass
class _Program:
    """What PyReason's calls have gathered."""
    graph: Graph | None = None
    names: NameMap = field(default_factory=NameMap)  # the graph's predicates; copied for each reasoning
    rules: list[Rule] = field(default_factory=list)
    facts: list[Fact] = field(default_factory=list)
    closed: list[str] = field(default_factory=list)
    ipl: list[tuple[str, str]] = field(default_factory=list)  # add_inconsistent_predicate's pairs
    annotation_functions: dict[str, Callable[..., Any]] = field(default_factory=dict)  # by name
    head_functions: dict[str, Callable[..., Any]] = field(default_factory=dict)  # by name
    reasoning: _Reasoning | None = None  # the last reason()'s, for again=True
    last: Interpretation | None = None
    timestamp: str = ""


settings = Settings()
_program = _Program()
# held by reason() and add_fact(), and by a background poll (temporal_classifier.py) for the whole poll
LOCK = threading.RLock()
_time_moved = threading.Condition(LOCK)  # notified after each reason()
REASONED_TO: list[int] = []  # each reason()'s last timestep, in order (a poller's first one: its start)


class _SettingsClass(type):
    """PyReason's scripts may set a setting on the class `_Settings` itself (examples/temporal_classifier_ex.py:
    `settings = Settings; settings.atom_trace = True`), which in PyReason replaces the property and so
    changes the setting: here it sets (and reads) `settings`'s, type-checked as there."""

    def __setattr__(cls, name: str, value: Any) -> None:
        setattr(settings, name, value)

    def __getattr__(cls, name: str) -> Any:
        return getattr(settings, name)


class _Settings(metaclass=_SettingsClass):
    """PyReason's settings class (`from pyreason.pyreason import _Settings`); its attributes are `settings`'s."""


# ---- state -------------------------------------------------------------------------------------------

def reset() -> None:
    """Forget the graph, the facts, the closed-world predicates and the rules (PyReason's reset). The
    inconsistent predicate list stays, as PyReason's does (nothing of PyReason's clears it)."""
    global _program
    _program = _Program(reasoning=_program.reasoning, last=_program.last, timestamp=_program.timestamp,
                        ipl=_program.ipl)


def reset_rules() -> None:
    """Forget the rules, the annotation and the head functions (PyReason's reset_rules)."""
    _program.rules.clear()
    _program.annotation_functions.clear()
    _program.head_functions.clear()


def reset_settings() -> None:
    settings.reset()


def get_rules() -> list[Rule] | None:
    """The rules added so far, or None when there are none (PyReason's get_rules after reset_rules)."""
    return list(_program.rules) or None


def record(run_dir: str | os.PathLike[str] | None) -> None:
    """Record each following reason() into the new tracelab run `run_dir` (None: stop recording)."""
    settings.tracelab_run = run_dir


# ---- the graph ---------------------------------------------------------------------------------------

def load_graphml(path: str | os.PathLike[str]) -> None:
    """A GraphML file with PyReason's attribute mapping (docs/pyreason.md, "GraphML")."""
    names = NameMap()
    _program.graph = load_pyreason_graphml(path, names)
    _program.names = names


def load_graph(graph: Any) -> None:
    """A networkx graph (DiGraph; an undirected graph's edges go both ways), mapped as load_graphml."""
    names = NameMap()
    _program.graph = load_pyreason_networkx(graph, names)
    _program.names = names


def load_inconsistent_predicate_list(path: str | os.PathLike[str]) -> None:
    raise unsupported("the inconsistent predicate list from a YAML file (load_inconsistent_predicate_list)",
                      "call add_inconsistent_predicate(a, b) for each pair")


def add_inconsistent_predicate(pred1: str, pred2: str) -> None:
    """Keep pred1 and pred2 complementary on every node or edge: when one is set to [l,u] the other gets
    [1-u,1-l], and a bound that contradicts it is an inconsistency (docs/pyreason.md, "The inconsistent
    predicate list")."""
    for p in (pred1, pred2):
        if not isinstance(p, str) or not p:
            raise UserError(f"add_inconsistent_predicate: a predicate name is a non-empty str, got {p!r}")
    if (pred1, pred2) not in _program.ipl:
        _program.ipl.append((pred1, pred2))


# ---- rules and facts ---------------------------------------------------------------------------------

def add_rule(pr_rule: Rule) -> None:
    """Add a rule; an unnamed one is rule_<n> as in PyReason (a repeated name warns, as there)."""
    if pr_rule.get_rule_name() is None:
        pr_rule.set_rule_name(f"rule_{len(_program.rules)}")
    if any(r.get_rule_name() == pr_rule.get_rule_name() for r in _program.rules):
        warnings.warn(f"Rule {pr_rule.get_rule_name()} has already been added. Duplicate rule names will lead "
                      "to an ambiguous rule trace.", stacklevel=2)
    _program.rules.append(pr_rule)


def add_rules_from_file(file_path: str | os.PathLike[str], infer_edges: bool = False,
                        raise_errors: bool = False) -> None:
    """PyReason's rule text file (one rule a line, `#` comments); infer_edges applies to every rule.
    A rule that does not parse raises a located ValueError with raise_errors, else warns and is skipped
    (PyReason's default here)."""
    for r in read_rules_txt(file_path, _Report(raise_errors).on_error, first=len(_program.rules)):
        r.infer_edges = r.infer_edges or infer_edges
        add_rule(Rule.from_parsed(r))


def add_rule_from_csv(csv_path: str | os.PathLike[str], raise_errors: bool = True) -> None:
    """PyReason's rule CSV (`rule_text,name,infer_edges,set_static`) or, by a .json extension, its rule
    JSON (with custom_thresholds and weights). A bad row, or a name the file repeats, raises a located
    ValueError with raise_errors; else it warns and the row is skipped (a bad option: its default)."""
    report = _Report(raise_errors)
    rules = [Rule.from_parsed(r) for r in _unique(read_rules(csv_path, report.on_error), raise_errors, "rule")]
    report.if_empty(rules, csv_path, "rules")
    for r in rules:
        add_rule(r)


add_rule_from_json = add_rule_from_csv  # read_rules reads the format the extension names


def add_fact(pyreason_fact: Fact) -> None:
    """Add a fact; an unnamed one is fact_<n> as in PyReason."""
    with LOCK:
        _add_fact(pyreason_fact)


def _add_fact(pyreason_fact: Fact) -> None:
    if pyreason_fact.name is None:
        pyreason_fact.name = f"fact_{len(_program.facts)}"
    if any(f.name == pyreason_fact.name for f in _program.facts):
        warnings.warn(f"Fact {pyreason_fact.name} has already been added. Duplicate fact names will lead to an "
                      "ambiguous node and atom traces.", stacklevel=2)
    _program.facts.append(pyreason_fact)


def add_fact_from_csv(csv_path: str | os.PathLike[str], raise_errors: bool = True) -> None:
    """PyReason's fact CSV (`fact_text,name,start_time,end_time,static`) or, by a .json extension, its
    fact JSON; bad rows as add_rule_from_csv's."""
    report = _Report(raise_errors)
    facts = [Fact.from_parsed(f) for f in _unique(read_facts(csv_path, report.on_error), raise_errors, "fact")]
    report.if_empty(facts, csv_path, "facts")
    for f in facts:
        add_fact(f)


add_fact_from_json = add_fact_from_csv  # read_facts reads the format the extension names


class _Report:
    """How a loader treats a file's bad rows: raise (`on_error` None), or warn with the located message
    and go on; an empty file warns, as PyReason's loaders do."""

    def __init__(self, raise_errors: bool) -> None:
        self.warned = 0
        self.on_error = None if raise_errors else self._warn

    def _warn(self, e: PyReasonFileError) -> None:
        self.warned += 1
        warnings.warn(str(e), UserWarning, stacklevel=5)

    def if_empty(self, loaded: list[Any], path: str | os.PathLike[str], what: str) -> None:
        if not loaded and not self.warned:
            warnings.warn(f"{os.fspath(path)} contains an empty array or no rows, no {what} loaded", stacklevel=3)


def _unique(items: list[Any], raise_errors: bool, what: str) -> list[Any]:
    """The items of one file whose names it has not used before: a repeated name raises (ValueError)
    with raise_errors, else warns and the item is skipped (PyReason's loaders)."""
    out, seen = [], set()
    for it in items:
        if it.name in seen:
            err = PyReasonFileError(f"Loaded name '{it.name}' is a duplicate - all {what} names must be unique.",
                                    it.loc.file, it.loc.line, it.loc.column, None)
            if raise_errors:
                raise err
            warnings.warn(str(err), UserWarning, stacklevel=3)
            continue
        seen.add(it.name)
        out.append(it)
    return out


def add_closed_world_predicate(predicate_name: str) -> None:
    """In rule bodies an atom of this predicate that is unset or [0,1] reads as [0,0] (`%closed`)."""
    if predicate_name not in _program.closed:
        _program.closed.append(predicate_name)


def add_annotation_function(function: Callable[..., Any]) -> None:
    """A function `f(annotations, weights) -> (lower, upper)` that rule heads name (`p(x):f <- ...`):
    `annotations` per body clause the typed list of its counted atoms' bounds (`.lower`, `.upper`),
    `weights` one per clause (numba_interval.py). A numba `njit` function is compiled for these types
    at its first call."""
    _program.annotation_functions[function.__name__] = function


def add_head_function(function: Callable[..., Any]) -> None:
    """A function `f(args)` that rule heads name in an argument (`Processed(f(X)) <- ...`): `args` per
    argument of the call the typed list of its node names, and `f` returns a typed list of node names.
    tracelab calls it once per grounding, with one name per argument, and takes the one node it returns
    (head_functions.py; docs/pyreason.md "Head functions")."""
    _program.head_functions[function.__name__] = function


# ---- reasoning ---------------------------------------------------------------------------------------

def reason(timesteps: int = -1, convergence_threshold: int = -1, convergence_bound_threshold: float = -1,
           queries: Sequence[Query] | None = None, again: bool = False, restart: bool = True) -> Interpretation:
    """PyReason's reason() (below, _reason), one at a time (LOCK: a classifier may poll from its thread)."""
    with LOCK:
        try:
            return _reason(timesteps, convergence_threshold, convergence_bound_threshold, queries, again, restart)
        finally:
            REASONED_TO.append(current_time())
            _time_moved.notify_all()


def current_time() -> int:
    """The last reasoned timestep (the interpretation's time), -1 before any reason()."""
    return _program.last.time if _program.last is not None else -1


def wait_for_time(ready: Callable[[int], bool], stop: threading.Event, reasonings: int = 0) -> int | None:
    """Wait (woken by each reason()) until `reasonings` reason() calls have ended and ready(current_time());
    that time, or None once `stop` is set."""
    with _time_moved:
        _time_moved.wait_for(lambda: stop.is_set() or len(REASONED_TO) >= reasonings and ready(current_time()))
        return None if stop.is_set() else current_time()


def wake_time_waiters() -> None:
    with _time_moved:
        _time_moved.notify_all()


def _reason(timesteps: int, convergence_threshold: int, convergence_bound_threshold: float,
            queries: Sequence[Query] | None, again: bool, restart: bool) -> Interpretation:
    """Run the program for timesteps + 1 steps (t = 0..timesteps), or until it converges with -1.
    Convergence as PyReason's: with both thresholds -1, once no fact starts later and no delayed firing
    is pending; with convergence_threshold n, after a step that changed at most n atoms; with
    convergence_bound_threshold d, after a step whose largest bound change was at most d. `queries`
    keeps only the rules they need (ruleset_filter). As in PyReason the facts are used up: the facts
    added after a reason() are the next one's. `again=True` continues the last reasoning for
    `timesteps` more steps with the facts added since (`restart`: their times count from the first
    new step; else they are absolute), delayed firings still pending included."""
    if isinstance(timesteps, bool) or not isinstance(timesteps, (int, np.integer)) or timesteps < -1:
        raise UserError(f"timesteps must be -1 (until convergence) or an integer >= 0, got {timesteps!r}")
    convergence = _convergence(convergence_threshold, convergence_bound_threshold)
    facts = [PFact(f.name or "", f.literal, f.start_time, f.end_time, f.static, SourceLoc(f"<Fact {f.name}>", 1, 1))
             for f in _program.facts]
    last = _program.reasoning
    if again and last is not None:
        if _program.rules != last.rules:  # rules added (or reset) since: PyReason's again applies them
            if not _program.rules:
                raise UserError("There are no rules, use `add_rule` or `add_rules_from_file`")
            last = _program.reasoning = last.continued_with(_translated(_program.rules, last.facts, last.graph),
                                                            list(_program.rules))
        _program.last = last.again(timesteps, restart, facts, convergence)
        _program.facts.clear()
        return _program.last
    if not _program.rules:
        raise UserError("There are no rules, use `add_rule` or `add_rules_from_file`")
    _program.timestamp = time.strftime("%Y%m%d-%H%M%S")
    rules = filter_ruleset(queries, _program.rules) if queries else _program.rules
    graph = settings.graph_for_engine(_program.graph) if _program.graph is not None else None
    translated = _translated(rules, facts, graph)
    _program.reasoning = _Reasoning(translated, graph, facts, list(_program.rules))
    reference = _on_reference(translated, graph, timesteps)
    try:
        _program.last = _program.reasoning.run(timesteps, convergence, reference=reference)
    except Exception:
        if not reference or settings.tracelab_evaluator == "reference":
            raise
        # no fixpoint, no convergence: the compiled engine runs it again and says why in its own words
        _program.reasoning = _Reasoning(translated, graph, facts, list(_program.rules))
        _program.last = _program.reasoning.run(timesteps, convergence)
    _program.facts.clear()  # used up only once reasoned with: a reason() that failed keeps them
    return _program.last


def _on_reference(translated: Any, graph: Graph | None, timesteps: int) -> bool:
    """Whether this reasoning runs on the reference evaluator (settings.tracelab_evaluator; with "auto", a
    small program, not recorded, without functions of add_annotation_function or add_head_function)."""
    if settings.tracelab_run is not None:
        if settings.tracelab_evaluator == "reference":
            raise UserError("pr.settings.tracelab_run: a recorded reasoning runs on the compiled engine; set "
                            "pr.settings.tracelab_evaluator to 'auto' or 'compiled'")
        return False
    if settings.tracelab_evaluator != "auto":
        return settings.tracelab_evaluator == "reference"
    if _program.annotation_functions or _program.head_functions:
        return False
    from .reference_engine import serves
    return serves(translated.program, graph, timesteps)


def _translated(rules: Sequence[Rule], facts: list[PFact], graph: Graph | None) -> Any:
    """The program of these rules and facts on the graph, with the settings and the registered functions."""
    constants = _ground_components(graph, facts) if settings.allow_ground_rules else frozenset()
    return translate([_with_functions(r.rule, i) for i, r in enumerate(rules)], facts, graph,
                     copy.deepcopy(_program.names), persistent=settings.persistent, closed=_program.closed,
                     constants=constants, directives=settings.directives(),
                     head_functions=_registered_head_functions(), ipl=_program.ipl)


def _with_functions(rule: PRule, index: int) -> PRule:
    """A rule whose head names a function of add_annotation_function, naming a registered adapter
    instead (numba_interval.adapter) with weights that number the clauses; other rules as they are."""
    fn = _program.annotation_functions.get(rule.head.function)
    if fn is None:
        return rule
    from tracelab.engine import register_annotation
    from .numba_interval import adapter
    n = len(rule.body)
    name = f"pyreason_{index}_" + "".join(c if c.isalnum() else "_" for c in rule.head.function.lower())
    register_annotation(name, adapter(fn, rule.weights or [1.0] * n))
    return dataclasses.replace(rule, head=dataclasses.replace(rule.head, function=name),
                               weights=[float(k) for k in range(1, n + 1)])


def _registered_head_functions() -> dict[str, str]:
    """Register add_head_function's functions with the engine: PyReason's name -> the engine's."""
    from tracelab.engine import register_head_function
    from .head_functions import adapter, engine_name
    out = {}
    for i, (name, fn) in enumerate(_program.head_functions.items()):
        out[name] = engine_name(i, fn)
        register_head_function(out[name], adapter(fn))
    return out


def _ground_components(graph: Graph | None, facts: Sequence[PFact]) -> frozenset[str]:
    """allow_ground_rules: the names a rule component may be a constant of (the graph's nodes and the
    facts' components)."""
    out = set(graph.nodes) if graph is not None else set()
    out.update(a for f in facts for a in f.literal.args)
    return frozenset(out)


@dataclass(frozen=True)
class _Convergence:
    mode: str  # perfect | delta_interpretation | delta_bound
    delta: float


def _convergence(threshold: int, bound_threshold: float) -> _Convergence:
    if bound_threshold != -1:
        return _Convergence("delta_bound", float(bound_threshold))
    if threshold != -1:
        return _Convergence("delta_interpretation", float(threshold))
    return _Convergence("perfect", 0.0)


class _Reasoning:
    """One reasoning: the engine (through EpisodeRun, recorded when asked), its trace in PyReason's
    layout, and the convergence test after each step; `again` continues it."""

    def __init__(self, translated: Any, graph: Graph | None, facts: list[PFact], rules: list[Rule]) -> None:
        from tracelab.reasoning import ReasoningInputs
        self.translated = translated
        self.graph, self.facts, self.rules = graph, facts, rules  # what it was translated from
        graph_facts = graph.n_facts if graph is not None else 0
        self.inputs = ReasoningInputs(translated.program, graph, translated.names, graph_facts, "pyreason",
                                      translation=translated.text)
        self.graph_facts = graph_facts
        self.last_fact = max([f.end for f in translated.program.facts if not f.static] +
                             [f.start for f in translated.program.facts], default=0)
        self.t_last = -1
        self.passes = 0
        self.passes_before = 0  # of the reasoning this one continues (continued_with)
        self.recorded = False
        self.external: list[tuple[PFact, int]] = []  # facts of again(), with their first step

    def run(self, timesteps: int, convergence: _Convergence, reference: bool = False) -> Interpretation:
        """Reason `timesteps` steps (-1: until convergence) on the compiled engine, or on the reference
        evaluator (reference_engine.py: not recorded)."""
        writer, recorder = (None, None) if reference else self._recorder(timesteps)
        self.recorded = writer is not None
        try:
            self.episode = self._reference_episode() if reference else self._engine_episode(recorder)
            self.trace = PyReasonTrace(self.episode.engine, self.translated.names, self.graph_facts,
                                       self.translated.ipl_rules,
                                       skip_graph_facts=not settings.save_graph_attributes_to_trace,
                                       ipl_twin_rules=self.translated.ipl_twin_rules,
                                       ipl_facts=self.translated.ipl_facts,
                                       ipl_partners=self.translated.ipl_partners)
            converged = self._steps(timesteps + 1 if timesteps >= 0 else -1, convergence)
            self.episode.finish()
        except BaseException:
            if writer is not None:
                writer.close(status="failed")
            raise
        if writer is not None:
            writer.close()
        return self._interpretation(timesteps, converged)

    def _engine_episode(self, recorder: Any) -> Any:
        import_frozen("tracelab.engine.core")  # numba's and the engine's modules, kept out of collections
        from tracelab.reasoning import EpisodeRun, plan_episodes
        return EpisodeRun(self.inputs, plan_episodes(self.inputs)[0], trace=True, recorder=recorder)

    def _reference_episode(self) -> Any:
        from .reference_engine import ReferenceEngine, ReferenceEpisode
        return ReferenceEpisode(ReferenceEngine(self.inputs.program, self.inputs.graph))

    def continued_with(self, translated: Any, rules: list[Rule]) -> _Reasoning:
        """This reasoning going on in a new engine built from `translated` (its rules changed): world 0's
        atoms keep their bounds and static flags, the clock, the trace so far and the facts of again() go
        on; delayed firings still pending are dropped (as PyReason drops them at the end of a reason())."""
        if self.recorded:
            raise unsupported("reason(again=True) after a recorded reasoning (settings.tracelab_run)")
        from tracelab.reasoning import EpisodeRun, plan_episodes
        new = _Reasoning(translated, self.graph, self.facts, rules)
        new.episode = EpisodeRun(new.inputs, plan_episodes(new.inputs)[0], trace=True)
        old, eng = self.episode.engine, new.episode.engine
        held = np.flatnonzero((old.lower[0] != 0.0) | (old.upper[0] != 1.0) | old.static[0])
        atoms = [eng.atom(pred, *args) for pred, args in (old.vocab.atom_parts(int(a)) for a in held)]
        eng.set_bounds(np.array(atoms, np.int64), old.lower[0, held], old.upper[0, held], old.static[0, held])
        eng.t = old.t
        new.trace = PyReasonTrace(eng, translated.names, new.graph_facts, translated.ipl_rules,
                                  skip_graph_facts=self.trace.skip_graph_facts,
                                  ipl_twin_rules=translated.ipl_twin_rules, ipl_facts=translated.ipl_facts,
                                  ipl_partners=translated.ipl_partners)
        new.trace.carry(self.trace)
        new.t_last, new.passes, new.passes_before = self.t_last, self.passes, self.passes
        new.external, new.last_fact = list(self.external), max(new.last_fact, self.last_fact)
        return new

    def again(self, timesteps: int, restart: bool, facts: Sequence[PFact], convergence: _Convergence) -> Interpretation:
        """`timesteps` more steps (-1: until convergence) with `facts` (their times from the first new
        step when `restart`, else absolute) given to the engine as external facts, step by step."""
        if self.recorded:
            raise unsupported("reason(again=True) after a recorded reasoning (settings.tracelab_run)")
        first = self.t_last + 1
        for f in facts:
            offset = first if restart else 0
            self.external.append((f, offset))
            self.last_fact = max(self.last_fact, offset + (f.start if f.static else f.end))
        converged = self._steps(timesteps, convergence)
        return self._interpretation(timesteps, converged)

    def _steps(self, steps: int, convergence: _Convergence) -> bool:
        """Step the engine `steps` times (-1: until convergence); whether it converged."""
        engine = self.episode.engine
        first = self.t_last + 1
        self._feed(first)
        for k, rows in self.episode.steps(steps if steps >= 0 else MAX_TIMESTEPS_UNTIL_CONVERGED,
                                          rows_each_step=True):
            t = first + k
            self.trace.add(rows, self.passes, t)
            self.passes = self.passes_before + int(engine.stats["passes"][0])
            self.t_last = t
            if self._converged(engine, rows, t, convergence):
                return True
            self._feed(t + 1)
        return False

    def _feed(self, t: int) -> None:
        """The external facts (of again()) that hold at step t, for the engine's next step."""
        engine = self.episode.engine
        next_id = engine.next_external_id()  # the facts queued for one step take ids next_id, next_id + 1, ...
        for f, offset in self.external:
            start, end = offset + f.start, offset + f.end
            if (t == start) if f.static else (start <= t <= end):
                lit = f.literal
                atom = engine.atom(self.translated.names.predicate(lit.pred, len(lit.args)), *lit.args)
                self.trace.external_names[next_id] = f.name
                next_id += 1
                engine.add_fact(atom, lit.lower, lit.upper, static=f.static)

    def _interpretation(self, timesteps: int, converged: bool) -> Interpretation:
        if timesteps < 0 and not converged:
            raise UserError(f"reason(timesteps=-1): no convergence in {MAX_TIMESTEPS_UNTIL_CONVERGED} timesteps; "
                            "give timesteps")
        engine, graph = self.episode.engine, self.inputs.graph
        edges = [(graph.nodes[a], graph.nodes[b]) for a, b in graph.edges.tolist()] if graph is not None else []
        return Interpretation(engine, self.trace, list(engine.vocab.nodes), edges, self.t_last, self.passes,
                              settings.persistent, settings.atom_trace)

    def _converged(self, engine: Any, rows: dict[str, np.ndarray], t: int, convergence: _Convergence) -> bool:
        from tracelab.engine import CAUSE_RESET
        changed = (rows["world"] == 0) & (rows["cause_kind"] != CAUSE_RESET)
        if convergence.mode == "delta_interpretation":
            return int(changed.sum()) <= convergence.delta
        if convergence.mode == "delta_bound":
            delta = np.maximum(np.abs(rows["new_lower"] - rows["old_lower"]),
                               np.abs(rows["new_upper"] - rows["old_upper"]))[changed]
            return float(delta.max(initial=0.0)) <= convergence.delta
        return t >= self.last_fact and not engine.pending(0)

    def _recorder(self, timesteps: int) -> tuple[Any, Any]:
        """The run's writer and recorder when settings.tracelab_run names a directory, else (None, None)."""
        if settings.tracelab_run is None:
            return None, None
        from tracelab.reasoning import open_reasoning_run
        from tracelab.store.layout import check_new_run_dir
        from tracelab.store.reasoning import ReasoningRecorder
        run_dir = Path(settings.tracelab_run)
        check_new_run_dir(run_dir, "pr.settings.tracelab_run")
        writer = open_reasoning_run(run_dir, self.inputs, f"tracelab.pyreason.reason(timesteps={timesteps})",
                                    {"steps": timesteps + 1 if timesteps >= 0 else None,
                                     "pyreason_settings": settings_dict(settings)})
        return writer, ReasoningRecorder(writer)


# ---- reading the interpretation ----------------------------------------------------------------------

def _interp(interpretation: Any) -> Interpretation:
    if not isinstance(interpretation, Interpretation):
        raise UserError(f"expected the interpretation pr.reason() returned, got {type(interpretation).__name__}")
    return interpretation


def filter_and_sort_nodes(interpretation: Interpretation, labels: Sequence[str], bound: Interval = Interval(0.0, 1.0),
                          sort_by: str = "lower", descending: bool = True) -> list[Any]:
    """Per timestep a DataFrame (component, one column per label) of the nodes whose label changed then."""
    return _interp(interpretation).filter_and_sort(False, labels, bound, sort_by, descending)


def filter_and_sort_edges(interpretation: Interpretation, labels: Sequence[str], bound: Interval = Interval(0.0, 1.0),
                          sort_by: str = "lower", descending: bool = True) -> list[Any]:
    """As filter_and_sort_nodes, for edges (component: a (source, target) tuple)."""
    return _interp(interpretation).filter_and_sort(True, labels, bound, sort_by, descending)


def get_rule_trace(interpretation: Interpretation) -> tuple[Any, Any]:
    """(nodes, edges) DataFrames in PyReason's rule-trace layout."""
    return _interp(interpretation).rule_trace()


def save_rule_trace(interpretation: Interpretation, folder: str | os.PathLike[str] = "./") -> None:
    """rule_trace_nodes_<timestamp>.csv and rule_trace_edges_<timestamp>.csv in `folder`."""
    interpretation = _interp(interpretation)
    interpretation.trace.write(folder, _program.timestamp or None, interpretation.atom_trace)


def get_interpretation() -> Interpretation:
    if _program.last is None:
        raise UserError("No interpretation found. Please run `pr.reason()` first")
    return _program.last


def get_time() -> int:
    return _program.last.time + 1 if _program.last is not None else 0
