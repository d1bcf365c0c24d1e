"""The complete GraphML reader: expat with Python handlers, for every file the compiled scanner
(graphml_scan.py) does not take. Slower (a Python call per element) but it reads any well-formed XML,
names line and column in its errors, and refuses hostile XML:
- a DTD may not declare entities (no "billion laughs", no external entities), and external entities
  (the external DTD subset included) are never read;
- a DTD may not give attributes default values: one default, copied into every element that lacks the
  attribute, would make a small file cost as much as a huge one;
- a reference to an entity that is not declared is an error, also in the text of a document whose
  external DTD expat does not read (expat would pass over it; inside an attribute value it still does,
  as empty text, and pyexpat has no handler that hears of it).
It is also the definition of what the scanner reads: the scanner hands its <key> elements here."""
from __future__ import annotations

from typing import Any
from xml.parsers import expat

import numpy as np

from .errors import ProgramCheckError
from .graphml_raw import GraphKey, RawGraph, boolean_of_text

_CHUNK = 1 << 20


def read_graphml_expat(file: str) -> RawGraph:
    reader = _Reader(file)
    p = reader.parser
    try:
        with open(file, "rb") as f:
            while chunk := f.read(_CHUNK):
                p.Parse(chunk, False)
            p.Parse(b"", True)
    except expat.ExpatError as e:
        raise ProgramCheckError(f"not a readable GraphML file: {expat.ErrorString(e.code)}", file,
                                e.lineno, e.offset + 1) from None
    except (LookupError, ValueError) as e:  # a declared encoding that Python's codecs cannot give expat
        raise ProgramCheckError(f"not a readable GraphML file: the encoding it declares cannot be read ({e})",
                                file, p.CurrentLineNumber, p.CurrentColumnNumber + 1) from None
    return reader.raw()


def read_key_element(element: bytes, file: str) -> GraphKey | None:
    """The GraphML <key> element `element` (UTF-8, nothing in it that declares or names nodes, edges,
    data or keys) read as a whole document reads it, or None when it is not one key that reads without
    error (the caller then reads the whole file here, which locates the error)."""
    reader = _Reader(file)
    try:
        reader.parser.Parse(element, True)
    except (expat.ExpatError, ProgramCheckError):
        return None
    return next(iter(reader.keys.values())) if len(reader.keys) == 1 else None


class _Reader:
    """expat handlers that append to flat lists."""

    def __init__(self, file: str) -> None:
        self.file = file
        p = expat.ParserCreate()
        p.buffer_text = True
        p.buffer_size = 1 << 16
        p.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
        p.StartElementHandler = self.start
        p.EndElementHandler = self.end
        p.CharacterDataHandler = self.text
        p.EntityDeclHandler = self.refuse_entity
        p.ExternalEntityRefHandler = self.refuse_external
        p.AttlistDeclHandler = self.refuse_attribute_default
        p.SkippedEntityHandler = self.refuse_skipped_entity
        self.parser = p
        self.keys: dict[str, GraphKey] = {}
        self.node_ids: dict[str, int] = {}
        self.nodes: list[str] = []
        self.edges: list[tuple[int, int, int]] = []  # source, target, directed (-1: the graph's default)
        # data values: element kind (0 node / 1 edge), element index, key id, text, line, column
        self.data: list[tuple[int, int, str]] = []
        self.texts: list[str] = []
        self.places: list[tuple[int, int]] = []
        self.graph_undirected = False
        self.graphs = 0
        self.current: tuple[int, int] | None = None  # (kind, index) of the open node or edge
        self.data_key: str | None = None
        self.key_open: GraphKey | None = None
        self.in_default = False
        self.buf: list[str] = []

    def fail(self, msg: str) -> ProgramCheckError:
        p = self.parser
        return ProgramCheckError(msg, self.file, p.CurrentLineNumber, p.CurrentColumnNumber + 1)

    def refuse_entity(self, name: str, *_: Any) -> None:
        raise self.fail(f"the document declares the entity '{name}': entity declarations are refused "
                        "(entity expansion and external entities are a way to attack an XML reader)")

    def refuse_external(self, *_: Any) -> int:
        raise self.fail("the document refers to an external entity: refused")

    def refuse_attribute_default(self, element: str, attribute: str, _type: str, default: str | None,
                                 _required: bool) -> None:
        if default is not None:
            raise self.fail(f"the document's DTD gives attribute '{attribute}' of <{element}> a default value: "
                            "attribute defaults are refused (one default copied into every element can make "
                            "a small file as costly to read as a huge one)")

    def refuse_skipped_entity(self, name: str, _is_parameter_entity: bool) -> None:
        raise self.fail(f"the document refers to the entity '{name}', which it does not declare (an "
                        "external DTD is never read): refused")

    def node(self, name: str) -> int:
        nid = self.node_ids.get(name)
        if nid is None:
            nid = self.node_ids[name] = len(self.nodes)
            self.nodes.append(name)
        return nid

    def start(self, tag: str, attrs: dict[str, str]) -> None:
        tag = tag.rpartition(":")[2]
        if tag == "edge":
            src, dst = attrs.get("source"), attrs.get("target")
            if src is None or dst is None:
                raise self.fail("an <edge> needs a source and a target attribute")
            directed = attrs.get("directed")
            if directed not in (None, "true", "false"):
                raise self.fail(f"an <edge> has directed={directed!r} (expected true or false)")
            self.current = (1, len(self.edges))
            self.edges.append((self.node(src), self.node(dst), -1 if directed is None else int(directed == "true")))
        elif tag == "data":
            if self.current is not None:
                self.data_key = attrs.get("key")
                if self.data_key is None:
                    raise self.fail("a <data> element needs a key attribute")
                self.buf = []
                self.places.append((self.parser.CurrentLineNumber, self.parser.CurrentColumnNumber + 1))
        elif tag == "node":
            nid = attrs.get("id")
            if nid is None:
                raise self.fail("a <node> has no id attribute")
            if self.current is not None:
                raise self.fail("nested graphs are not supported")
            self.current = (0, self.node(nid))
        elif tag == "graph":
            self.graphs += 1
            if self.graphs > 1:
                raise self.fail("more than one <graph>: a GraphML file for tracelab holds one graph")
            self.graph_undirected = attrs.get("edgedefault", "directed") == "undirected"
        elif tag == "key":
            kid = attrs.get("id")
            if kid is None:
                raise self.fail("a <key> needs an id attribute")
            self.key_open = self.keys[kid] = GraphKey.of(kid, attrs, self.fail)
        elif tag == "default" and self.key_open is not None:
            self.in_default = True
            self.buf = []

    def text(self, data: str) -> None:
        if self.data_key is not None or self.in_default:
            self.buf.append(data)

    def end(self, tag: str) -> None:
        tag = tag.rpartition(":")[2]
        if tag == "data":
            if self.data_key is not None and self.current is not None:
                self.data.append((self.current[0], self.current[1], self.data_key))
                self.texts.append("".join(self.buf))
            self.data_key = None
        elif tag in ("node", "edge"):
            self.current = None
        elif tag == "default" and self.key_open is not None:
            self.key_open.default = "".join(self.buf)
            self.in_default = False
        elif tag == "key":
            self.key_open = None

    def raw(self) -> RawGraph:
        key_ids = list(dict.fromkeys(k for _, _, k in self.data))
        key_index = {k: i for i, k in enumerate(key_ids)}
        data = np.array([(kind, elem, key_index[k]) for kind, elem, k in self.data], np.int64).reshape(-1, 3)
        texts = self.texts
        return RawGraph(
            file=self.file, nodes=self.nodes, edges=np.array(self.edges, np.int64).reshape(-1, 3),
            graph_undirected=self.graph_undirected, keys=self.keys, data=data, data_keys=key_ids,
            text=texts.__getitem__, place=self.places.__getitem__,
            numbers=np.array([_number(x) for x in texts], np.float64),
            booleans=np.array([boolean_of_text(x) for x in texts], np.int8))


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")
