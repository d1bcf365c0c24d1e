"""PyReason's rules, facts and graph as one tracelab program: the program text (what `tracelab
convert-pyreason` writes), the engine's Program parsed from it with every location pointing back at the
PyReason files, and the graph with PyReason's attribute mapping. docs/pyreason.md lists the mapping."""
from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Container, Mapping, Sequence
from dataclasses import dataclass, field

from tracelab.engine import (
    Graph,
    ProgramError,
    RuleSyntaxError,
    check_program,
    parse_program,
)
from tracelab.engine.parser import line_from_file
from tracelab.engine.program import Program, SourceLoc, constant_text

from .facts import PFact, read_facts
from .graphml import load_pyreason_graphml
from .names import NameMap, variable_names
from .rules import PRule, Threshold, read_rules
from .text import PLiteral

GENERATED = "<pyreason translation>"
# what a translated line may hold of the shared issue-14 syntax: `[>= 50%] p(Y)`, `p(X):average`, `{set_static}`
_SHARED_SYNTAX = re.compile(r"\[(?:forall|[<>=]=?)|\):[a-z_]+\s*<-|\{[^}]*(?:set_static|infer_edges|weights)")
_OPS = {"greater_equal": ">=", "greater": ">", "less_equal": "<=", "less": "<", "equal": "=="}
# PyReason's built-in annotation functions by tracelab's names (the shared syntax of issue 14)
_FUNCTIONS = {"maximum": "max", "minimum": "min", "average": "average", "average_lower": "average_lower"}


@dataclass
class PyReasonProgram:
    """A translated PyReason program. `text` parses back to `program` (with `graph`, if any, given to
    the engine as its graph); `names` maps names both ways."""
    text: str
    program: Program
    graph: Graph | None
    names: NameMap
    origins: list[tuple[SourceLoc, str] | None] = field(default_factory=list)  # per line of text
    ipl_rules: dict[str, str] = field(default_factory=dict)  # the IPL's rules -> the predicate they copy
    ipl_twin_rules: dict[str, str] = field(default_factory=dict)  # ipl_twins' rules -> their rule's name
    # ipl_facts' facts -> (the predicate they copy, the PyReason name of the fact they copy)
    ipl_facts: dict[str, tuple[str, str]] = field(default_factory=dict)
    ipl_partners: dict[str, str] = field(default_factory=dict)  # a PyReason predicate -> its IPL partner


def number(v: float) -> str:
    """A bound as the rule language writes it: no sign, no exponent."""
    if v == int(v):
        return str(int(v))
    text = repr(v)
    if "e" in text:
        text = f"{v:.17f}".rstrip("0")
    return text[1:] if text.startswith("0.") else text


def bound_text(lower: float, upper: float) -> str:
    return "" if (lower, upper) == (1.0, 1.0) else f":[{number(lower)},{number(upper)}]"


def threshold_text(t: Threshold, forall: bool) -> str:
    """`[>= 50%] `, `[< 3 available] `, `[forall] ` or "" (PyReason's default: at least one)."""
    if forall and t.quantifier == "greater_equal" and t.kind == "percent" and t.over == "total" and t.value == 100:
        return "[forall] "
    if t.is_default:
        return ""
    count = number(float(t.value)) + ("%" if t.kind == "percent" else "")
    return f"[{_OPS[t.quantifier]} {count}{' available' if t.over == 'available' else ''}] "


def _literal(lit: PLiteral, names: NameMap, args: Sequence[str]) -> str:
    return f"{names.predicate(lit.pred, len(lit.args))}({','.join(args)})"


# PyReason grounds a variable that only a closed-world clause has (`~h(X)`, `h` closed) over the graph's
# nodes; the translation gives such a variable this predicate's clause, true of every node (static facts
# named DOMAIN_FACT_<k>), which the trace, get_dict and the DataFrames leave out
DOMAIN = "pyreason_node_domain"
DOMAIN_FACT = "pyreason_domain"


def closed_only_variables(r: PRule, closed: Container[str]) -> list[str]:
    """The rule's body components that only clauses of closed predicates reading [0,0] as true have (such
    a clause does not bind: docs/language.md, "%closed"), in order of appearance."""
    def binds(lit: PLiteral) -> bool:
        if lit.pred in closed:
            return lit.lower > 0
        return not (lit.lower == 0 and lit.upper == 1)
    bound = {a for lit in r.body if binds(lit) for a in lit.args}
    out: list[str] = []
    for lit in r.body:
        out += [a for a in lit.args if a not in bound and a not in out and lit.pred in closed]
    return out


def rule_text(r: PRule, names: NameMap, constants: Container[str] = frozenset(),
              head_functions: Mapping[str, str] | None = None, closed: Container[str] = frozenset()) -> str:
    """One PyReason rule as one tracelab rule statement. Components in `constants` (PyReason's ground
    rules, `allow_ground_rules`: a component that names a node) are constants, and so are the head's
    components that no body clause has (PyReason grounds such a head variable to the node of its name);
    the others are variables. A head function call `f(x)` names the engine's function `head_functions[f]`
    (api.add_head_function)."""
    body_components = {a for lit in r.body for a in lit.args}
    head_components = [a for a, c in zip(r.head.args, r.head.calls or [None] * len(r.head.args)) for a in
                       (c[1] if c is not None else (a,))]
    constants = {a for a in head_components if a in constants or a not in body_components} | {
        a for a in body_components if a in constants}
    components = [*head_components, *(a for lit in r.body for a in lit.args)]
    var = variable_names([a for a in components if a not in constants])
    var.update({a: constant_text(a) for a in components if a in constants})
    head = _literal(r.head, names, [_head_arg(a, c, var, head_functions or {})
                                    for a, c in zip(r.head.args, r.head.calls or [None] * len(r.head.args))])
    options: list[str] = []
    if r.head.function:
        fn = _FUNCTIONS.get(r.head.function, r.head.function)
        weights = r.weights or [1.0] * len(r.body)
        if fn == "average" and len(set(weights)) > 1:
            fn = "weighted_average"
        user_fn = r.head.function not in _FUNCTIONS
        if fn == "weighted_average" or (user_fn and r.weights is not None):  # PyReason hands weights to any function
            options.append("weights=" + ",".join(number(w) for w in weights))
        head += f":{fn}"
    else:
        head += bound_text(r.head.lower, r.head.upper)
    body = [threshold_text(t, c.forall) + _literal(c, names, [var[a] for a in c.args]) + bound_text(c.lower, c.upper)
            for c, t in zip(r.body, r.thresholds)]
    body += [f"{DOMAIN}({var[a]})" for a in closed_only_variables(r, closed) if a not in constants]
    if r.set_static:
        options.append("set_static")
    if r.infer_edges and len(r.head.args) == 2:  # PyReason ignores it on node rules
        options.append("infer_edges")
    opts = f" {{{', '.join(options)}}}" if options else ""
    return f"{names.statement(r.name)}: {head} <-{r.delay} {', '.join(body)}{opts}"


def _head_arg(arg: str, call: tuple[str, tuple[str, ...]] | None, var: Mapping[str, str],
              head_functions: Mapping[str, str]) -> str:
    if call is None:
        return var[arg]
    fn, args = call
    # an unregistered name stays as it is: the engine's check names it (a located error)
    return f"{head_functions.get(fn, fn)}({','.join(var[a] for a in args)})"


def fact_text(f: PFact, names: NameMap) -> str:
    lit = f.literal
    atom = f"{names.predicate(lit.pred, len(lit.args))}({','.join(constant_text(a) for a in lit.args)})"
    when = " static" if f.static else (f" @{f.start}" if f.start == f.end else f" @{f.start}..{f.end}")
    return f"{names.statement(f.name)}: {atom}{bound_text(lit.lower, lit.upper)}{when}"


def graph_fact_lines(graph: Graph) -> list[str]:
    """The graph's facts as static program facts (convert-pyreason --graph)."""
    out = []
    for i in range(graph.n_facts):
        f = graph.fact(i)
        out.append(f"{f.text}{bound_text(f.literal.lower, f.literal.upper)} static")
    return out


def load_pyreason(rule_files: Sequence[str | os.PathLike[str]], fact_files: Sequence[str | os.PathLike[str]] = (),
                  graph_file: str | os.PathLike[str] | None = None, *, persistent: bool = False,
                  embed_graph: bool = False) -> PyReasonProgram:
    """Read PyReason files and translate them (`translate`). With `embed_graph` the graph's facts are
    written into the text (a self-contained program) instead of being handed over as a Graph."""
    names = NameMap()
    graph = load_pyreason_graphml(graph_file, names) if graph_file is not None else None
    rules = [r for path in rule_files for r in read_rules(path)]
    facts = [f for path in fact_files for f in read_facts(path)]
    return translate(rules, facts, graph, names, persistent=persistent, embed_graph=embed_graph)


def translate(rules: Sequence[PRule], facts: Sequence[PFact], graph: Graph | None, names: NameMap, *,
              persistent: bool = False, embed_graph: bool = False, closed: Sequence[str] = (),
              constants: Container[str] = frozenset(), directives: Sequence[str] = (),
              head_functions: Mapping[str, str] | None = None, ipl: Sequence[tuple[str, str]] = ()
              ) -> PyReasonProgram:
    """PyReason's rules, facts and graph (its predicates named through `names`) as one checked tracelab
    program. PyReason's defaults become directives: non-persistent timesteps (`%timesteps reset`) unless
    `persistent`; intersection updates and reset-and-freeze on inconsistency are tracelab's defaults too.
    `closed`: PyReason's closed-world predicates (`%closed`); `constants`: rule components read as
    constants (PyReason's `allow_ground_rules`); `directives`: more directive lines (settings.py);
    `head_functions`: PyReason's head function names -> the engine's (api.add_head_function); `ipl`: the
    inconsistent predicate list (ipl_rule_lines)."""
    lines: list[str] = ["# translated from PyReason by tracelab (docs/pyreason.md)"]
    origins: list[tuple[SourceLoc, str] | None] = [None]
    if not persistent:
        lines.append("%timesteps reset  # PyReason's default: atoms go back to [0,1] at each timestep")
        origins.append(None)
    if graph is not None and not embed_graph:
        lines.append("%edge_heads graph  # PyReason's: an edge rule sets only the graph's edges unless {infer_edges}")
        origins.append(None)
    lines += directives
    origins += [None] * len(directives)
    for r in rules:
        lines.append(rule_text(r, names, constants, head_functions, frozenset(closed)))
        origins.append((r.loc, r.text))
    if closed:  # after the rules and facts: a predicate's name depends on the arities it is used with
        lines.append("%closed " + ", ".join(tl for p in closed for tl in names.predicates_named(p)) +
                     "  # add_closed_world_predicate")
        origins.append(None)
    ipl_rules: dict[str, str] = {}
    for line, source in ipl_rule_lines(ipl, names, _arities(rules, facts, graph, names)):
        lines.append(line)
        origins.append(None)
        ipl_rules[line.split(":", 1)[0]] = source
    ipl_twin_rules: dict[str, str] = {}
    for twin, source, of in ipl_twins(rules, ipl):
        lines.append(rule_text(twin, names, constants, head_functions, frozenset(closed)))
        origins.append((twin.loc, twin.text))
        ipl_rules[lines[-1].split(":", 1)[0]] = source
        ipl_twin_rules[lines[-1].split(":", 1)[0]] = of
    ipl_fact_names: dict[str, tuple[str, str]] = {}
    for k, f in enumerate(facts):
        lines.append(fact_text(f, names))
        origins.append((f.loc, ""))
        for partner in ipl_facts(f, ipl):
            name = f"pyreason_ipl_fact_{k}_{len(ipl_fact_names)}"
            lines.append(fact_text(dataclasses.replace(partner, name=name), names))
            origins.append((f.loc, ""))
            ipl_fact_names[lines[-1].split(":", 1)[0]] = (f.literal.pred, f.name)
    if any(f"{DOMAIN}(" in line for line in lines):
        nodes = dict.fromkeys([*(graph.nodes if graph is not None else ()),
                               *(a for f in facts for a in f.literal.args)])
        lines += [f"{DOMAIN_FACT}_{k}: {DOMAIN}({constant_text(n)}) static" for k, n in enumerate(nodes)]
        origins += [None] * len(nodes)
    if graph is not None and embed_graph:
        lines.append("# the graph's facts; facts carry no edge set, so edge rules are not restricted to the graph's "
                     "edges as in PyReason (`tracelab reason --dialect pyreason` with the graph keeps that)")
        lines += graph_fact_lines(graph)
        origins += [None] + [(SourceLoc(graph.file, 0, 0), "")] * graph.n_facts
        graph = None
    text = "\n".join(lines) + "\n"
    try:
        program = parse_program(text, GENERATED)
        program = _relocated(program, origins)
        check_program(program, graph.predicates() if graph is not None else None)
    except ProgramError as e:
        raise _located(e, origins, lines) from None
    program.files = sorted({str(o[0].file) for o in origins if o is not None})
    return PyReasonProgram(text, program, graph, names, origins, ipl_rules, ipl_twin_rules, ipl_fact_names,
                           {**{a: b for a, b in ipl}, **{b: a for a, b in ipl}})


# A bound excluding exactly the atoms within the engine's EPS of [0,1] (never set, or set back to it): a
# clause `p(X):[IPL_SET,1]` holds when p(X) > [0,1] from below, `p(X):[0,1-IPL_SET]` from above
IPL_SET = "0.000000002"
IPL_BELOW_ONE = "0.999999998"


def ipl_rule_lines(ipl: Sequence[tuple[str, str]], names: NameMap, arity: Mapping[str, set[int]]
                   ) -> list[tuple[str, str]]:
    """PyReason's inconsistent predicate list as rules (docs/pyreason.md, "The inconsistent predicate
    list"): for a pair (a, b), whenever a(x) is set to [l,u] (not [0,1]), b(x) gets [1-u,1-l] in the next
    pass (`~b(X):max <-0 a(X):...`: `max` of the one atom is its bound, and the `~` head sets its
    complement), and the other way round. A conflict is then an ordinary inconsistency of b(x), resolved
    by the program's policy (PyReason's: [0,1], frozen). Returns (rule line, the predicate it copies)."""
    out = []
    for k, (a, b) in enumerate(ipl):
        for n in sorted(arity.get(a, set()) | arity.get(b, set())):  # none: nothing to keep complementary
            out += _ipl_pair(k, a, b, n, names)
    return out


def ipl_twins(rules: Sequence[PRule], ipl: Sequence[tuple[str, str]]) -> list[tuple[PRule, str, str]]:
    """For each rule whose head predicate has an IPL partner, its twin: the same body, the partner as
    head with the complement bound ([1-u,1-l]), so that the partner is set in the same pass as PyReason
    sets it inside the rule's update, and a conflict resets both atoms as PyReason does (the pass's
    groups of both atoms conflict). A delayed rule's twin has its delay: both firings land in pass 0 with
    the facts and their IPL partners (ipl_facts), as PyReason applies them. Rules whose head bound comes
    from an annotation function have none.
    Returns (twin, the head predicate it copies, the rule's name)."""
    out = []
    for i, r in enumerate(rules):
        if r.head.function:
            continue
        for a, b in ipl:
            for src, dst in ((a, b), (b, a)):
                if r.head.pred != src:
                    continue
                # unrounded, as the pair's `~` rules and PyReason compute it (1 - 0.8 = 0.19999999999999996)
                head = dataclasses.replace(r.head, pred=dst, lower=1 - r.head.upper, upper=1 - r.head.lower)
                # a `set_static` rule freezes the partner too (PyReason's _update_node: set_static(static))
                out.append((dataclasses.replace(r, name=f"pyreason_ipl_twin_{i}_{dst}", head=head), src, r.name))
    return out


def ipl_facts(f: PFact, ipl: Sequence[tuple[str, str]]) -> list[PFact]:
    """The facts PyReason's IPL sets with fact `f`: its partners with the complement of its bound, at the
    same times, applied right after it in the same pass (PyReason sets them inside the fact's update).
    A conflict with one of them is then a conflict of facts, reset in pass 0 as PyReason resets it."""
    lit = f.literal
    if (lit.lower, lit.upper) == (0.0, 1.0):
        return []
    out = []
    for a, b in ipl:
        for src, dst in ((a, b), (b, a)):
            if lit.pred == src:  # unrounded, as PyReason computes it (1 - 0.8 = 0.19999999999999996)
                partner = dataclasses.replace(lit, pred=dst, lower=1 - lit.upper, upper=1 - lit.lower)
                out.append(dataclasses.replace(f, literal=partner))
    return out


def _ipl_pair(k: int, a: str, b: str, n: int, names: NameMap) -> list[tuple[str, str]]:
    """The four rules of one pair on predicates of arity n."""
    # an edge pair holds on inferred edges too (PyReason adds them to its graph): {infer_edges}
    args, opts = ("X", "") if n == 1 else ("X,Y", " {infer_edges}")
    out = []
    for src, dst in ((a, b), (b, a)):
        for j, clause in enumerate((f"[{IPL_SET},1]", f"[0,{IPL_BELOW_ONE}]")):
            name = f"pyreason_ipl_{k}_{names.predicate(src, n)}_{j}"
            out.append((f"{name}: ~{names.predicate(dst, n)}({args}):max <-0 {names.predicate(src, n)}({args}):"
                        f"{clause}{opts}", src))
    return out


def _arities(rules: Sequence[PRule], facts: Sequence[PFact], graph: Graph | None, names: NameMap
             ) -> dict[str, set[int]]:
    """PyReason predicate -> the numbers of arguments it is used with, in the rules, facts and graph."""
    out: dict[str, set[int]] = {}
    for lit in [*(lit for r in rules for lit in (r.head, *r.body)), *(f.literal for f in facts)]:
        out.setdefault(lit.pred, set()).add(len(lit.args))
    if graph is not None:
        for tl, n in graph.predicates().items():
            out.setdefault(names.original_predicate(tl), set()).add(n)
    return out


def _relocated(program: Program, origins: list[tuple[SourceLoc, str] | None]) -> Program:
    """Rules and facts located in the PyReason files they came from, not in the generated text."""
    def moved(item):
        o = origins[item.loc.line - 1] if item.loc and item.loc.file == GENERATED else None
        return dataclasses.replace(item, loc=o[0]) if o is not None else item
    program.rules = [moved(r) for r in program.rules]
    program.facts = [moved(f) for f in program.facts]
    return program


def _located(e: ProgramError, origins: list[tuple[SourceLoc, str] | None], lines: list[str]) -> ProgramError:
    """An error found in the translation, located at the PyReason statement it came from."""
    if e.file == GENERATED and 0 < e.line <= len(origins) and origins[e.line - 1] is not None:
        loc, text = origins[e.line - 1]
        msg = f"{e.message} (in its translation: {lines[e.line - 1]})"
        if isinstance(e, RuleSyntaxError) and _SHARED_SYNTAX.search(lines[e.line - 1]):
            msg += ("; the translation uses the quantifiers, annotation functions or rule options of issue 14, "
                    "which this tracelab's rule parser may not read yet")
        # a rule made in Python (pr.Rule, file "<Rule ...>") has no file to read its line from
        source = text if loc.file.startswith("<") else line_from_file(loc.file, loc.line)
        return type(e)(msg, loc.file, loc.line, loc.column, source)
    if e.file != GENERATED and e.line > 0 and e.source_line is None:
        return type(e)(e.message, e.file, e.line, e.column, line_from_file(e.file, e.line))
    return e
