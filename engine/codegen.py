"""The source of a step kernel specialised to one rule program (the compiled backend, docs/engine-api.md).

The generated module is the counting kernel (kernel.py) itself, rewritten on its syntax tree with what
one program fixes: the update mode, timestep mode and inconsistency policy become constants, and the
rule table's columns become constants too (one literal when every rule agrees, a constant array indexed
by rule otherwise). numba then folds the branches that the program never takes. Starting from kernel.py's
own source keeps one definition of the semantics: the compiled backend cannot drift from the counting
kernel, and any change of kernel.py changes the generated text and so the cache key.

What this does not specialise (yet): the groundings, watch lists and joins. They depend on the graph and
on the atoms interned while the program runs, not on the program text, so they stay tables.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import inspect
from dataclasses import dataclass

import numpy as np

from . import kernel as K

GENERATOR_VERSION = 1  # bump when the rewriting below changes what it generates


class GenerationError(Exception):
    """kernel.py no longer has the shape this generator rewrites (the compiled backend is not used)."""


@dataclass(frozen=True)
class Specialisation:
    """What one program fixes of the kernel: cfg slots and the rule table (core.py builds both)."""
    mode: int
    reset: bool
    policy: int
    rule_mode: tuple[int, ...]
    rule_delay: tuple[int, ...]
    rule_lower: tuple[float, ...]
    rule_upper: tuple[float, ...]

    @classmethod
    def of(cls, cfg: np.ndarray, rule_i: np.ndarray, rule_f: np.ndarray) -> "Specialisation":
        return cls(mode=int(cfg[K.CFG_MODE]), reset=bool(cfg[K.CFG_RESET]), policy=int(cfg[K.CFG_POLICY]),
                   rule_mode=tuple(int(v) for v in rule_i[:, K.RULE_MODE]),
                   rule_delay=tuple(int(v) for v in rule_i[:, K.RULE_DELAY]),
                   rule_lower=tuple(float(v) for v in rule_f[:, 0]),
                   rule_upper=tuple(float(v) for v in rule_f[:, 1]))


# (table name, column) -> (Specialisation field, constant array name)
_TABLE_COLUMNS = {("rule_i", K.RULE_MODE): ("rule_mode", "_RULE_MODE"),
                  ("rule_i", K.RULE_DELAY): ("rule_delay", "_RULE_DELAY"),
                  ("rule_f", 0): ("rule_lower", "_RULE_LOWER"),
                  ("rule_f", 1): ("rule_upper", "_RULE_UPPER")}
_ARRAY_DTYPES = {"_RULE_MODE": "int64", "_RULE_DELAY": "int64", "_RULE_LOWER": "float64",
                 "_RULE_UPPER": "float64"}
_COLUMN_NAMES = {"RULE_MODE": K.RULE_MODE, "RULE_DELAY": K.RULE_DELAY}
# cfg slots fixed by the program, and the kernel arguments that carry them
_CFG_SLOTS = {"CFG_MODE": "mode", "CFG_RESET": "reset", "CFG_POLICY": "policy"}


def _column(node: ast.expr) -> int | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, int):
        return node.value
    if isinstance(node, ast.Name):
        return _COLUMN_NAMES.get(node.id)
    return None


class _Specialise(ast.NodeTransformer):
    def __init__(self, spec: Specialisation) -> None:
        self.spec = spec
        self.arrays: dict[str, tuple[float | int, ...]] = {}  # constant arrays the module needs
        self.folded = {"table": 0, "cfg": 0, "pinned": 0}

    def _value(self, field: str) -> object:
        v = getattr(self.spec, field)
        if field == "reset":
            return int(v)
        return v

    def visit_Subscript(self, node: ast.Subscript) -> ast.AST:
        self.generic_visit(node)
        if not (isinstance(node.value, ast.Name) and isinstance(node.ctx, ast.Load)):
            return node
        name, idx = node.value.id, node.slice
        if name == "cfg" and isinstance(idx, ast.Name) and idx.id in _CFG_SLOTS:
            self.folded["cfg"] += 1
            return ast.copy_location(ast.Constant(self._value(_CFG_SLOTS[idx.id])), node)
        if name in ("rule_i", "rule_f") and isinstance(idx, ast.Tuple) and len(idx.elts) == 2:
            col = _column(idx.elts[1])
            if (name, col) not in _TABLE_COLUMNS:
                return node
            field, array = _TABLE_COLUMNS[(name, col)]
            values = getattr(self.spec, field)
            self.folded["table"] += 1
            if len(set(values)) == 1:  # every rule agrees: a literal, and its branches fold away
                return ast.copy_location(ast.Constant(values[0]), node)
            self.arrays[array] = values
            sub = ast.Subscript(ast.Name(array, ast.Load()), idx.elts[0], ast.Load())
            return ast.copy_location(sub, node)
        return node

    def visit_FunctionDef(self, node: ast.FunctionDef) -> ast.AST:
        self.generic_visit(node)
        # arguments that carry a fixed cfg value are pinned to it at the top of the function
        pins = []
        args = {a.arg for a in node.args.args}
        if "policy" in args:
            pins.append(("policy", self.spec.policy))
        if "fact_override" in args:
            pins.append(("fact_override", self.spec.mode == K.MODE_OVERRIDE))
        if "reset" in args:
            pins.append(("reset", self.spec.reset))
        stmts = [ast.Assign([ast.Name(n, ast.Store())], ast.Constant(v), lineno=0) for n, v in pins]
        self.folded["pinned"] += len(stmts)
        first = 1 if node.body and isinstance(node.body[0], ast.Expr) and \
            isinstance(getattr(node.body[0], "value", None), ast.Constant) else 0  # after the docstring
        node.body[first:first] = stmts
        return node

    def visit_ImportFrom(self, node: ast.ImportFrom) -> ast.AST:
        if node.level:  # the generated module lives outside the package: make relative imports absolute
            package = K.__name__.rpartition(".")[0]
            return ast.copy_location(ast.ImportFrom(f"{package}{'.' + node.module if node.module else ''}",
                                                    node.names, 0), node)
        return node


@functools.lru_cache(maxsize=1)
def _sources() -> tuple[str, str]:
    """kernel.py's source (the template) and this module's (the rewriting)."""
    return inspect.getsource(K), inspect.getsource(inspect.getmodule(Specialisation))  # type: ignore[arg-type]


@functools.lru_cache(maxsize=1)
def _sources_digest() -> str:
    """A hash of the template and the generator, computed once per process (every engine built with
    kernel="auto" or "compiled" looks its key up)."""
    kernel_src, codegen_src = _sources()
    return hashlib.sha256(kernel_src.encode() + b"\0" + codegen_src.encode()).hexdigest()


def fingerprint(spec: Specialisation) -> str:
    """A text that determines generate(spec): the template, the generator and the program's values. The
    cache key hashes it, so that Engine(kernel="auto") can look a program up without generating it."""
    return f"{GENERATOR_VERSION}\n{_sources_digest()}\n{spec!r}"


@functools.lru_cache(maxsize=8)
def generate(spec: Specialisation) -> str:
    """The Python source of the specialised kernel module (deterministic: equal programs, equal text)."""
    tree = ast.parse(_sources()[0])
    if tree.body and isinstance(tree.body[0], ast.Expr):  # kernel.py's docstring: the header replaces it
        del tree.body[0]
    tx = _Specialise(spec)
    tree = tx.visit(tree)
    if not tx.folded["cfg"] or not tx.folded["table"] or not tx.folded["pinned"] or \
            not any(isinstance(n, ast.FunctionDef) and n.name == "step_worlds" for n in tree.body):
        raise GenerationError(f"kernel.py does not have the shape the generator rewrites ({tx.folded})")
    ast.fix_missing_locations(tree)
    consts = [f"{name} = np.array({list(values)!r}, dtype=np.{_ARRAY_DTYPES[name]})"
              for name, values in sorted(tx.arrays.items())]
    header = (f'"""Generated by tracelab.engine.codegen (version {GENERATOR_VERSION}) from kernel.py for one '
              f'program: {len(spec.rule_mode)} rules. Do not edit; the compile cache owns this file."""\n')
    body = ast.unparse(tree)
    return header + body + "\n\n# the program's rule table, folded in\n" + "\n".join(consts) + "\n"
