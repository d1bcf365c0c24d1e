"""The on-disk cache of a program's grounding: a declared world's build grounds the same program over the same
atoms at every start (war.toml: about half a second of CPU), so the result of each of its first closes is
kept in tracelab's cache folder (`grounded/` beside the compile cache's `compiled/`) and read back next time.

The key is a hash of everything a close reads: the rules (their full text, places included), the vocabulary
(nodes, labels, atoms), the grounder's state (its groundings, settable atoms and relations so far, its
limit), and the code that grounds (the sources of grounding.py, vocabulary.py, program.py, bounds.py and of
this module and array_file.py) with the versions of tracelab, numpy and Python. A program with a head
function (Python code the key cannot see) is never cached. Old keys are never read again, so the folder is
kept bounded: a new entry removes the least recently used ones beyond FOLDER_CAP bytes or MAX_ENTRIES
entries (a hit marks its entry used). Deleting the folder is always safe.

An entry holds what the close added, as plain arrays (array_file.py): the atoms it interned, its new
groundings' rows, the settable atoms and the relations. It is a file from a stranger: read under a size cap,
then every array checked (dtypes, shapes, every id in range, every new atom new, every grounding an instance
of its rule: each clause's atom is the clause with the grounding's values) before anything of it is used.
An entry that fails is refused in one warning, removed and grounded again; a folder that cannot be used
(unwritable, another user's) leaves the build as it was without the cache, saying nothing.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import sys
from importlib import metadata
from pathlib import Path

import numpy as np

from . import array_file, bounds, grounding, program, vocabulary
from .array_file import read_arrays, write_arrays
from .compile_cache import CacheRefused, cache_root, private_folder
from .grounding import Grounder
from .notices import library_logger
from .safe_files import MIB, FileRefused

FOLDER = "grounded"
FORMAT = 1  # part of every key: bump when an entry's arrays or their meaning change
FILE_CAP = 256 * MIB  # a bigger grounding is not cached (war.toml's: well under 1 MiB)
FOLDER_CAP = 512 * MIB  # the folder's entries together, after a new one is written
MAX_ENTRIES = 256  # every spec, size and param set a user builds makes one or two
SUFFIX = ".grounding"
# the arrays of an entry: numpy dtype and number of dimensions
ARRAYS = {"atoms": ("<i4", 2), "rule": ("<i4", 1), "head": ("<i4", 1), "vals": ("<i4", 2), "body": ("<i4", 2),
          "settable": ("|u1", 1), "relation_ptr": ("<i8", 1), "relation_atoms": ("<i8", 1)}
log = library_logger(__name__)


def cache_folder() -> Path:
    return cache_root().parent / FOLDER


@functools.cache
def _code_digest() -> bytes:
    h = hashlib.sha256(f"format {FORMAT}".encode())
    for module in (grounding, vocabulary, program, bounds, array_file, sys.modules[__name__]):
        h.update(Path(module.__file__ or "").read_bytes())
    for dist in ("tracelab", "numpy"):
        try:
            h.update(f"{dist} {metadata.version(dist)}".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{dist} none".encode())
    h.update(sys.version.encode())
    return h.digest()


def cache_key(g: Grounder) -> str | None:
    """The key of g's next close, or None when it cannot be cached (a head function's result is code's)."""
    if any(call is not None for cr in g.compiled_rules for call in cr.head_calls):
        return None
    h = hashlib.sha256(_code_digest())
    v = g.vocab
    parts = [json.dumps([[repr(r) for r in g.rules], v.nodes, v.labels, v.label_arity]).encode(),
             v.atom_label.tobytes(), v.atom_arg0.tobytes(), v.atom_arg1.tobytes(), *g.state_parts()]
    for part in parts:  # each with its length: no two states hash the same parts' bytes
        h.update(len(part).to_bytes(8, "little"))
        h.update(part)
    return h.hexdigest()[:32]


def close(g: Grounder) -> None:
    """g.close(), its result read from the cache when an entry holds it, else grounded and kept there."""
    key = cache_key(g) if g.has_pending else None
    folder = cache_folder()
    try:
        if key is not None:
            private_folder(folder.parent, follow_symlinks=True)
            private_folder(folder, follow_symlinks=False)
    except CacheRefused:
        key = None
    if key is None:
        g.close()
        return
    path = folder / f"{key}{SUFFIX}"
    try:
        if _load(g, key, path):
            return
    except FileRefused as e:
        log.warning(f"grounding cache: {e}; grounded again")
        _remove(path)
    except OSError:  # unreadable: grounded, and written over if the folder lets it
        pass
    before = (g.vocab.n_atoms, g.n_groundings, g.estimated)
    g.close()
    try:
        _store(g, key, path, *before)
        prune(folder, keep=path)
    except OSError:  # an unwritable folder, a full disk: the next build grounds again
        pass


def prune(folder: Path, keep: Path, max_entries: int | None = None, max_bytes: int | None = None) -> None:
    """Remove the least recently used entries (by modification time: a hit touches its entry) until at
    most `max_entries` (MAX_ENTRIES) remain, of `max_bytes` (FOLDER_CAP) together; `keep` (the entry just
    written) stays. Only this cache's own files (the suffix, regular files) are looked at or removed."""
    max_entries = MAX_ENTRIES if max_entries is None else max_entries
    max_bytes = FOLDER_CAP if max_bytes is None else max_bytes
    found = []
    with os.scandir(folder) as listing:
        for entry in listing:
            if entry.name.endswith(SUFFIX) and entry.is_file(follow_symlinks=False):
                st = entry.stat(follow_symlinks=False)
                found.append((st.st_mtime_ns, st.st_size, entry.path))
    count, total = len(found), sum(size for _, size, _ in found)
    for _, size, where in sorted(found):  # the oldest first
        if count <= max_entries and total <= max_bytes:
            break
        if where != str(keep):
            _remove(Path(where))
            count, total = count - 1, total - size


def _remove(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


def _store(g: Grounder, key: str, path: Path, atoms_before: int, groundings_before: int,
           estimated_before: int) -> None:
    v = g.vocab
    arrays = {"atoms": np.stack([v.atom_label, v.atom_arg0, v.atom_arg1])[:, atoms_before:],
              **g.grown_since(groundings_before)}
    if sum(a.nbytes for a in arrays.values()) > FILE_CAP - array_file.HEADER_CAP:
        return
    fields = {"key": key, "atoms_before": atoms_before, "groundings_before": groundings_before,
              "estimated_added": g.estimated - estimated_before}
    write_arrays(path, fields, arrays)


def _load(g: Grounder, key: str, path: Path) -> bool:
    """Take the entry's close into g (True), or False when there is none; FileRefused when it fails a check."""
    try:
        fields, arrays = read_arrays(path, FILE_CAP, ARRAYS)
    except FileNotFoundError:
        return False
    why = _mismatch(g, key, fields, arrays)
    if why:
        raise FileRefused(f"{path}: {why}")
    g.vocab.append_atoms(*arrays["atoms"])
    g.take_grown(arrays, fields["estimated_added"])
    try:
        os.utime(path)  # used now: prune() keeps the recently used
    except OSError:
        pass
    return True


def _mismatch(g: Grounder, key: str, fields: dict, arrays: dict[str, np.ndarray]) -> str | None:
    """Why the entry cannot be g's next close (None when it can): every check before any of it is used."""
    v = g.vocab
    n_atoms, n_groundings = v.n_atoms, g.n_groundings
    if fields.get("key") != key or fields.get("atoms_before") != n_atoms \
            or fields.get("groundings_before") != n_groundings:
        return "made for another key or state"
    added = fields.get("estimated_added")
    if type(added) is not int or added < 0:
        return "no valid estimated_added"
    new, rule, head, vals, body = (arrays[k] for k in ("atoms", "rule", "head", "vals", "body"))
    n_nodes, arity = len(v.nodes), np.asarray(v.label_arity, np.int64)
    if new.shape[0] != 3 or not _within(new[0], 0, len(arity)) or not _within(new[1], 0, n_nodes) \
            or not _within(new[2], -1, n_nodes) or ((new[2] < 0) != (arity[new[0]] == 1)).any():
        return "an atom of an unknown label or node, or of the wrong arity"
    if not v.are_new(*new):
        return "an atom it adds is already interned or added twice"
    total = n_atoms + new.shape[1]
    m = len(rule)
    if (len(head), vals.shape, body.shape) != (m, (m, g.max_vars), (m, g.max_body)) \
            or n_groundings + m > g.max_groundings:
        return "groundings of the wrong shape, or more than the limit"
    if not _within(rule, 0, len(g.rules)) or not _within(head, 0, total):
        return "a grounding of an unknown rule or head atom"
    labels = np.concatenate([v.atom_label, new[0]]).astype(np.int64)
    args = (np.concatenate([v.atom_arg0, new[1]]).astype(np.int64),
            np.concatenate([v.atom_arg1, new[2]]).astype(np.int64))
    for r in np.unique(rule):
        if why := _not_instances(g.compiled_rules[r], vals[rule == r], body[rule == r], head[rule == r],
                                 labels, args, n_nodes):
            return f"rule {g.rules[r].name!r}: {why}"
    return _relations_mismatch(g, arrays, labels, total)


def _within(a: np.ndarray, low: int, high: int) -> bool:
    return not a.size or (int(a.min()) >= low and int(a.max()) < high)


def _not_instances(cr: grounding._CompiledRule, vals: np.ndarray, body: np.ndarray, head: np.ndarray,
                   labels: np.ndarray, args: tuple[np.ndarray, np.ndarray], n_nodes: int) -> str | None:
    """Why some of these groundings are not instances of the rule: values and atoms in range, and each
    clause's atom (the head's too) the clause's label over the grounding's values."""
    nv, nb = cr.n_vars, len(cr.clause_labels)
    if not _within(vals[:, :nv], 0, n_nodes) or (vals[:, nv:] != -1).any():
        return "a variable's value out of range"
    if not _within(body[:, :nb], 0, len(labels)) or (body[:, nb:] != -1).any():
        return "a body atom out of range"
    rows = vals[:, :nv].astype(np.int64)
    clauses = [(head, cr.head_label, cr.head_args)] + \
        [(body[:, ci].astype(np.int64), lab, a) for ci, (lab, a) in enumerate(zip(cr.clause_labels, cr.clause_args))]
    for atoms, label, clause_args in clauses:
        if (labels[atoms] != label).any():
            return "an atom of another predicate than its clause's"
        for p, col in enumerate(Grounder.argument_columns(clause_args, rows)):
            if (args[p][atoms] != col).any():
                return "an atom that is not its clause over the grounding's values"
    return None


def _relations_mismatch(g: Grounder, arrays: dict[str, np.ndarray], labels: np.ndarray, total: int) -> str | None:
    """Why the settable atoms and relations are not a close's from g's: every settable atom stays
    settable and is in its label's relation once, the heads are settable, and the relations so far are
    their prefixes."""
    settable, ptr, atoms = arrays["settable"], arrays["relation_ptr"], arrays["relation_atoms"]
    if len(settable) != total or not _within(settable, 0, 2) or not settable[arrays["head"]].all():
        return "settable atoms of the wrong size, values, or without the heads"
    if (g.settable_mask(g.vocab.n_atoms) & (settable[:g.vocab.n_atoms] == 0)).any():
        return "an atom settable before is not"
    if len(ptr) != len(g.vocab.labels) + 1 or ptr[0] != 0 or (np.diff(ptr) < 0).any() or ptr[-1] != len(atoms):
        return "relations of the wrong shape"
    if not _within(atoms, 0, total) or (labels[atoms] != np.repeat(np.arange(len(ptr) - 1), np.diff(ptr))).any():
        return "a relation's atom out of range or of another label"
    if len(atoms) != int(settable.sum()) or not settable[atoms].all() or len(np.unique(atoms)) != len(atoms):
        return "relations that are not the settable atoms, each once"
    old_ptr, old_atoms = g.relations()
    for label in range(len(ptr) - 1):
        old = old_atoms[old_ptr[label]:old_ptr[label + 1]]
        if not np.array_equal(atoms[ptr[label]:ptr[label] + len(old)], old):
            return "relations that do not extend the ones so far"
    return None
