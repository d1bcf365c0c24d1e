"""Nodes, labels and ground atoms interned to dense integer ids (append-only, so ids stay valid).

Atoms live in numpy columns (label, arg0, arg1) and are found through a packed int64 key: a sorted key
array for the bulk of them (filled by `atoms()`, vectorised) and a dict for the few interned one at a
time since the last merge. A million atoms cost ~30 bytes each, not a Python tuple and dict entry each.
"""
from __future__ import annotations

import numpy as np

from .program import constant_text

# key = label << 48 | arg0 << 24 | (arg1 + 1): labels < 2^15, nodes < 2^24 - 1
_LABEL_SHIFT, _ARG0_SHIFT = 48, 24
MAX_LABELS, MAX_NODES = 1 << 15, (1 << 24) - 1


class Vocabulary:
    def __init__(self, nodes: list[str] | tuple[str, ...] = ()) -> None:
        self.nodes: list[str] = []
        self.node_ids: dict[str, int] = {}
        self.labels: list[str] = []
        self.label_ids: dict[str, int] = {}
        self.label_arity: list[int] = []
        self._n = 0
        self._cols = np.zeros((3, 1024), np.int32)  # label, arg0, arg1 per atom (capacity doubles)
        self._skeys = np.zeros(0, np.int64)  # sorted keys of atoms 0.._n_sorted
        self._sids = np.zeros(0, np.int32)
        self._recent: dict[int, int] = {}  # key -> id of atoms interned one at a time since the last merge
        self.add_nodes(nodes)

    @property
    def n_atoms(self) -> int:
        return self._n

    @property
    def atom_label(self) -> np.ndarray:
        return self._cols[0, :self._n]

    @property
    def atom_arg0(self) -> np.ndarray:
        return self._cols[1, :self._n]

    @property
    def atom_arg1(self) -> np.ndarray:
        """The second node of an edge atom, -1 for a node atom."""
        return self._cols[2, :self._n]

    # ---- nodes and labels ----

    def node(self, name: str) -> int:
        nid = self.node_ids.get(name)
        if nid is None:
            nid = self.node_ids[name] = len(self.nodes)
            if nid >= MAX_NODES:
                raise ValueError(f"more than {MAX_NODES} nodes")
            self.nodes.append(name)
        return nid

    def add_nodes(self, names: list[str] | tuple[str, ...]) -> np.ndarray:
        """Node ids of names, interned in order."""
        if not self.nodes and len(names) > 1000:  # a graph's node list: one dict build, not a call each
            self.node_ids = dict(zip(names, range(len(names))))
            if len(self.node_ids) == len(names):  # distinct names (the usual case): ids are positions
                if len(names) > MAX_NODES:
                    raise ValueError(f"more than {MAX_NODES} nodes")
                self.nodes = list(names)
                return np.arange(len(names), dtype=np.int32)
            self.node_ids = {}
        return np.fromiter((self.node(n) for n in names), np.int32, len(names))

    def label(self, name: str, arity: int) -> int:
        lid = self.label_ids.get(name)
        if lid is None:
            lid = self.label_ids[name] = len(self.labels)
            if lid >= MAX_LABELS:
                raise ValueError(f"more than {MAX_LABELS} labels")
            self.labels.append(name)
            self.label_arity.append(arity)
        elif self.label_arity[lid] != arity:
            raise ValueError(f"label {name!r} has arity {self.label_arity[lid]}, used here with {arity}")
        return lid

    # ---- atoms ----

    @staticmethod
    def _key(label: int, a0: int, a1: int) -> int:
        return (label << _LABEL_SHIFT) | (a0 << _ARG0_SHIFT) | (a1 + 1)

    @staticmethod
    def _keys(labels: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
        return (np.asarray(labels, np.int64) << _LABEL_SHIFT) | (np.asarray(a0, np.int64) << _ARG0_SHIFT) \
            | (np.asarray(a1, np.int64) + 1)

    def find(self, label: int, args: tuple[int, ...]) -> int | None:
        """The id of label(args) if it was interned, else None."""
        key = self._key(label, args[0], args[1] if len(args) > 1 else -1)
        aid = self._recent.get(key)
        if aid is not None:
            return aid
        i = int(np.searchsorted(self._skeys, key))
        return int(self._sids[i]) if i < len(self._skeys) and self._skeys[i] == key else None

    def atom(self, label: int, args: tuple[int, ...]) -> int:
        """The id of label(args) (node ids), interned on first use."""
        aid = self.find(label, args)
        if aid is None:
            a1 = args[1] if len(args) > 1 else -1
            aid = self._append(np.array([label]), np.array([args[0]]), np.array([a1]))
            self._recent[self._key(label, args[0], a1)] = aid
            if len(self._recent) > max(1024, len(self._skeys) // 4):
                self._merge()
        return aid

    def atoms(self, labels: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
        """Ids of many atoms at once (a1 = -1 for node atoms); new ones are interned in order of first
        appearance, as one `atom()` call per element would."""
        self._merge()
        keys = self._keys(labels, a0, a1)
        if not len(keys):
            return np.zeros(0, np.int64)
        order = np.argsort(keys, kind="stable")  # sorted queries: distinct keys, cache-friendly lookups
        sk = keys[order]
        head = np.concatenate([[True], sk[1:] != sk[:-1]])
        uniq, group = sk[head], np.cumsum(head) - 1
        first = order[head]  # the first element of each distinct key
        pos = np.searchsorted(self._skeys, uniq)
        pos_c = np.minimum(pos, max(len(self._skeys) - 1, 0))
        found = (pos < len(self._skeys)) & (self._skeys[pos_c] == uniq) if len(self._skeys) else \
            np.zeros(len(uniq), np.bool_)
        ids = np.empty(len(uniq), np.int64)
        ids[found] = self._sids[pos_c[found]]
        missing = np.flatnonzero(~found)
        if len(missing):
            by_first = missing[np.argsort(first[missing], kind="stable")]  # new ids in order of appearance
            ids[by_first] = self._n + np.arange(len(by_first))
            m = first[by_first]
            self._append(np.asarray(labels)[m], np.asarray(a0)[m], np.asarray(a1)[m])
            self._insert_sorted(uniq[missing], ids[missing])
        out = np.empty(len(keys), np.int64)
        out[order] = ids[group]
        return out

    def are_new(self, labels: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> bool:
        """Whether these atoms are distinct and none of them is interned yet."""
        self._merge()
        keys = np.sort(self._keys(labels, a0, a1))
        if len(keys) > 1 and (keys[1:] == keys[:-1]).any():
            return False
        pos = np.minimum(np.searchsorted(self._skeys, keys), max(len(self._skeys) - 1, 0))
        return not len(self._skeys) or not (self._skeys[pos] == keys).any()

    def append_atoms(self, labels: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> None:
        """Intern atoms known to be new and distinct (are_new), in order (the grounding cache's)."""
        self._merge()
        first = self._append(labels, a0, a1)
        keys = self._keys(labels, a0, a1)
        order = np.argsort(keys)
        self._insert_sorted(keys[order], first + order)

    def _append(self, labels: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> int:
        n, k = self._n, len(labels)
        if n + k > self._cols.shape[1]:
            cols = np.zeros((3, max(n + k, 2 * self._cols.shape[1])), np.int32)
            cols[:, :n] = self._cols[:, :n]
            self._cols = cols
        self._cols[0, n:n + k] = labels
        self._cols[1, n:n + k] = a0
        self._cols[2, n:n + k] = a1
        self._n = n + k
        return n

    def _merge(self) -> None:
        if self._recent:
            keys = np.fromiter(self._recent.keys(), np.int64, len(self._recent))
            ids = np.fromiter(self._recent.values(), np.int64, len(self._recent))
            self._recent = {}
            order = np.argsort(keys)
            self._insert_sorted(keys[order], ids[order])

    def _insert_sorted(self, keys: np.ndarray, ids: np.ndarray) -> None:
        """Merge sorted, new keys into the sorted index."""
        at = np.searchsorted(self._skeys, keys)
        self._skeys = np.insert(self._skeys, at, keys)
        self._sids = np.insert(self._sids, at, ids.astype(np.int32))

    def atom_by_name(self, pred: str, args: tuple[str, ...]) -> int:
        return self.atom(self.label(pred, len(args)), tuple(self.node(a) for a in args))

    def atom_parts(self, aid: int) -> tuple[str, tuple[str, ...]]:
        label = self.labels[int(self._cols[0, aid])]
        a0, a1 = int(self._cols[1, aid]), int(self._cols[2, aid])
        args = (self.nodes[a0],) if a1 < 0 else (self.nodes[a0], self.nodes[a1])
        return label, args

    def atom_text(self, aid: int) -> str:
        label, args = self.atom_parts(aid)
        return f"{label}({','.join(map(constant_text, args))})"

    def arrays(self) -> dict[str, object]:
        """The columnar form the trace store keeps."""
        return {
            "nodes": list(self.nodes),
            "labels": list(self.labels),
            "label_arity": np.asarray(self.label_arity, np.int8),
            "atom_label": self.atom_label.copy(),
            "atom_arg0": self.atom_arg0.copy(),
            "atom_arg1": self.atom_arg1.copy(),
        }
