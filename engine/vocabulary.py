"""Nodes, labels and ground atoms interned to dense integer ids (append-only, so ids stay valid)."""
from __future__ import annotations

import numpy as np


class Vocabulary:
    def __init__(self, nodes: list[str] | tuple[str, ...] = ()) -> None:
        self.nodes: list[str] = []
        self.node_ids: dict[str, int] = {}
        self.labels: list[str] = []
        self.label_ids: dict[str, int] = {}
        self.label_arity: list[int] = []
        self._atom_label: list[int] = []
        self._atom_arg0: list[int] = []
        self._atom_arg1: list[int] = []
        self.atom_ids: dict[tuple[int, int, int], int] = {}
        for n in nodes:
            self.node(n)

    @property
    def n_atoms(self) -> int:
        return len(self._atom_label)

    def node(self, name: str) -> int:
        nid = self.node_ids.get(name)
        if nid is None:
            nid = self.node_ids[name] = len(self.nodes)
            self.nodes.append(name)
        return nid

    def label(self, name: str, arity: int) -> int:
        lid = self.label_ids.get(name)
        if lid is None:
            lid = self.label_ids[name] = len(self.labels)
            self.labels.append(name)
            self.label_arity.append(arity)
        elif self.label_arity[lid] != arity:
            raise ValueError(f"label {name!r} has arity {self.label_arity[lid]}, used here with {arity}")
        return lid

    def atom_key(self, label: int, args: tuple[int, ...]) -> tuple[int, int, int]:
        return (label, args[0], args[1] if len(args) > 1 else -1)

    def atom(self, label: int, args: tuple[int, ...]) -> int:
        """The id of label(args) (node ids), interned on first use."""
        key = self.atom_key(label, args)
        aid = self.atom_ids.get(key)
        if aid is None:
            aid = self.atom_ids[key] = len(self._atom_label)
            self._atom_label.append(key[0])
            self._atom_arg0.append(key[1])
            self._atom_arg1.append(key[2])
        return aid

    def atom_by_name(self, pred: str, args: tuple[str, ...]) -> int:
        return self.atom(self.label(pred, len(args)), tuple(self.node(a) for a in args))

    def atom_parts(self, aid: int) -> tuple[str, tuple[str, ...]]:
        label = self.labels[self._atom_label[aid]]
        a0, a1 = self._atom_arg0[aid], self._atom_arg1[aid]
        args = (self.nodes[a0],) if a1 < 0 else (self.nodes[a0], self.nodes[a1])
        return label, args

    def atom_text(self, aid: int) -> str:
        label, args = self.atom_parts(aid)
        return f"{label}({','.join(args)})"

    def arrays(self) -> dict[str, object]:
        """The columnar form the trace store keeps."""
        return {
            "nodes": list(self.nodes),
            "labels": list(self.labels),
            "label_arity": np.asarray(self.label_arity, np.int8),
            "atom_label": np.asarray(self._atom_label, np.int32),
            "atom_arg0": np.asarray(self._atom_arg0, np.int32),
            "atom_arg1": np.asarray(self._atom_arg1, np.int32),
        }
