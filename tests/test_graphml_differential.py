"""The compiled GraphML scanner against the expat reader (the definition): documents mixing valid and
invalid XML, each read by both. Either expat refuses it and so does the scanner (it leaves the file to
expat, whose error names file, line and column), or both give the same raw graph (nodes, edges, keys,
values, places) and the same graph of facts. Then one explicit case per XML rule the scanner must keep,
and the entity-expansion attacks on both readers (through the command in a process with a time limit
where a regression could hang)."""
from __future__ import annotations

import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tracelab.engine import Graph, ProgramCheckError, load_graphml
from tracelab.engine.graph import _scan, _to_graph, read_raw_graphml
from tracelab.engine.graphml_expat import read_graphml_expat
from tracelab.engine.graphml_raw import RawGraph

# ---------------------------------------------------------------------------------------------------------
# documents: pieces of GraphML, each with whether the scanner must take it ("plain": valid XML inside the
# scanner's subset); a document all of plain pieces must be read by the scanner itself


@dataclass(frozen=True)
class Doc:
    data: bytes
    plain: bool

    def __repr__(self) -> str:  # what hypothesis prints for a failing example
        return f"Doc(plain={self.plain}, data={self.data!r})"


def _plain(*pieces: bytes) -> list[tuple[bytes, bool]]:
    return [(p, True) for p in pieces]


def _other(*pieces: bytes) -> list[tuple[bytes, bool]]:
    return [(p, False) for p in pieces]


BOMS = _plain(b"", b"", b"", b"\xef\xbb\xbf")
DECLARATIONS = _plain(b"", b"", b'<?xml version="1.0" encoding="UTF-8"?>\n', b"<?xml version='1.0'?>",
                      b'<?xml version="1.1" encoding="utf-8" standalone="yes" ?>\r\n') + _other(
    b'<?xml version="1.0" encoding="utf8"?>',  # the scanner reads such a file only if it is all ASCII
    b'<?xml version="1.0" encoding="ISO-8859-1"?>', b'<?xml version="1.0" encoding="x-nope"?>',
    b'<?xml version="1.0" encoding="UTF-16"?>', b'<?xml encoding="UTF-8"?>', b' <?xml version="1.0"?>',
    b'<?xml version="2.0"?>', b"<?xml version='1.0' standalone='no' encoding='UTF-8'?>", b"<?xml?>")
PROLOG_MISC = _plain(b"", b"\n", b"<!-- written by hand -->\n", b"<?tool run?>\n", b"<!---->") + _other(
    b"<!-- a -- b -->", b"<!--->", b"<?xml-stylesheet href='s.css'?>", b"<?XML x?>", b"<!DOCTYPE graphml>",
    b'<!DOCTYPE graphml SYSTEM "graphml.dtd">', b'<!DOCTYPE graphml [<!ENTITY e "0.5">]>',
    b'<!DOCTYPE graphml [<!ATTLIST node id CDATA "dflt">]>', b'<!DOCTYPE graphml [<!ELEMENT graphml ANY>]>',
    b'<!DOCTYPE graphml [<!ENTITY % p "x">]>', b"junk", b"\x0c")
PREFIXES = ("", "", "g:")
ROOT_ATTRIBUTES = _plain(b"", b"", b'\n  xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"\n'
                         b'  xsi:schemaLocation="http://graphml.graphdrawing.org/xmlns\n\t graphml.xsd"') + _other(
    b' xmlns="a" xmlns="b"', b' x="&#10;"')
KEY_TYPES = _plain(b"double", b"boolean", b"string", b"int") + _other(b"bogus")
KEY_DEFAULTS = _plain(b"", b"", b"<default>0.5</default>", b"<default>true</default>", b"<default/>",
                      b"<default>[0.2,0.4]</default>", b"<desc>hp</desc><default> 1 </default>",
                      b"<default>0.<!-- c -->5</default>", b"<default>0.<?pi?>5</default>",
                      b"<default>0.5</default><default>0.25</default>", b"<default>\r\n0.5\r\n</default>",
                      b"<default>0.5<x/></default>") + _other(
    b"<default>&#48;.5</default>", b"<default><![CDATA[0.5]]></default>", b"<default>&bad;</default>",
    b"<node id='k'/>", b"<data key='k0'>1</data>")
VALUES = _plain(b"0.5", b" 1 ", b"1", b"0", b"true", b"FALSE", b"\xc2\xa0true", b"[0.2,0.5]", b"0.2,0.9",
                b"1e-1", b"abc", b"", b"0.12345678901234567", b"\n0.25\n", b"caf\xc3\xa9", b">", b"]]",
                b"\xf0\x9f\x98\x80", b"\xef\xbf\xbd") + _other(
    b"0.2,\r\n0.9", b"1\r", b"&lt;", b"&#48;.5", b"&#x30;.5", b"<![CDATA[0.5]]>", b"0.<!--c-->5", b"0.<?pi?>5",
    b"<b/>", b"&foo;", b"\x01", b"]]>", b"\xff", b"\xef\xbf\xbe", b"\xed\xa0\x80", b"&#0;", b"&#xFFFE;",
    b"\xc0\xae", b"a<!-- x -- y -->")
IDS = _plain(b"a", b"b", b"n1", b"Cell 3", b"caf\xc3\xa9", b"\xf0\x9f\x98\x80", b"a>b", b"x'y", b"q:r") + _other(
    b"a\tb", b"a\nb", b"a\r\nb", b"a\rb", b"a&amp;b", b"a&#10;b", b"&#9;", b"a&lt;b", b"a&foo;b", b"a<b",
    b"\x01", b"&#0;", b"&#xFFFE;", b"\xef\xbf\xbe", b"\xff", b"\xc3")
DIRECTED = _plain(b"", b"", b' directed="true"', b" directed='false'") + _other(b' directed="maybe"')
EDGEDEFAULTS = _plain(b"", b' edgedefault="directed"', b' edgedefault="undirected"',
                      b' id=" edgedefault=\'undirected\'"') + _other(b' edgedefault="undirected\t"')
# a change to one element's start tag, or to the document, that XML refuses or the scanner leaves to expat
TAG_EXTRAS = _plain(b" x='a\"b'", b' xmlns:y="u"', b"\t\r\n z = 'q' ") + _other(
    b' id="dup"', b" x=1", b' x="<"', b' x="&amp;"', b' y="1"z="2"', b" 1x='1'", b' x="a\nb"', b' caf\xc3\xa9="1"')
CHILDREN = _plain(b"", b"", b"<desc>about</desc>", b'<port name="p"/>', b"<!-- c -->") + _other(
    b'<node id="x"/>', b"<graph/>", b'<edge source="x" target="y"/>', b'<key id="k0" attr.type="double"/>')
GRAPH_DATA = _plain(b"", b"", b'<data key="k0">g</data>') + _other(b"<data>g</data>", b'<data key="k0"><x/></data>')
DOC_BREAKS = _other(b"\x00", b"\x08", b"\x0b", b"\x7f", b"\xff", b"\xc3", b"\xef\xbf\xbf", b"\r", b"&", b"<",
                    b"]]>", b"</x>", b"<x>", b"<!-- -- -->", b"<![CDATA[x]]>", b"\xc2\x85", b" ", b"\n", b"\t",
                    b"\xc3\xa9", b'"', b"'", b"=", b"/", b">")


def _pick(draw: st.DrawFn, choices: list[tuple[bytes, bool]], parts: list[bytes]) -> bool:
    """Append one piece of `choices` to `parts`: a plain one 6 times in 7 (else most documents would be
    refused for their first piece); returns whether it is plain."""
    plain = [c for c in choices if c[1]]
    other = [c for c in choices if not c[1]]
    pool = plain if not other or (plain and draw(st.integers(0, 6)) > 0) else other
    piece, is_plain = draw(st.sampled_from(pool))
    parts.append(piece)
    return is_plain


@st.composite
def graphml_documents(draw: st.DrawFn) -> Doc:
    """A GraphML document: a prolog, keys, a graph of nodes and edges with <data> values, drawn from valid
    pieces and pieces XML refuses (or that the scanner leaves to expat), sometimes with one start tag
    broken or a byte put anywhere."""
    parts: list[bytes] = []
    plain = all([_pick(draw, BOMS, parts), _pick(draw, DECLARATIONS, parts), _pick(draw, PROLOG_MISC, parts)])
    p = draw(st.sampled_from(PREFIXES)).encode()
    xmlns = b' xmlns:g="http://graphml.graphdrawing.org/xmlns"' if p else b' xmlns="http://graphml.graphdrawing.org/xmlns"'
    parts.append(b"<" + p + b"graphml" + xmlns)
    plain &= _pick(draw, ROOT_ATTRIBUTES, parts)
    parts.append(b">\n")
    key_ids = [b"k0", b"k1", b"k2"]
    for kid in key_ids[:draw(st.integers(0, 3))]:
        domain = draw(st.sampled_from([b"node", b"edge", b"all"]))
        name = draw(st.sampled_from([b"hp", b"near", kid]))
        head = b"<" + p + b'key id="' + kid + b'" for="' + domain + b'" attr.name="' + name + b'" attr.type="'
        parts.append(head)
        plain &= _pick(draw, KEY_TYPES, parts)
        parts.append(b'"')
        body: list[bytes] = []
        plain &= _pick(draw, KEY_DEFAULTS, body)
        parts.append(b">" + body[0] + b"</" + p + b"key>\n" if body[0] else b"/>\n")
    parts.append(b"<" + p + b"graph")
    plain &= _pick(draw, EDGEDEFAULTS, parts)
    parts.append(b">\n")
    plain &= _pick(draw, GRAPH_DATA, parts)
    for _ in range(draw(st.integers(0, 5))):
        is_node = draw(st.booleans())
        tag = b"node" if is_node else b"edge"
        start: list[bytes] = [b"<" + p + tag]
        if is_node:
            start.append(b' id="')
            plain &= _pick(draw, IDS, start)
            start.append(b'"')
        else:
            for end in (b"source", b"target"):
                start.append(b" " + end + b'="')
                plain &= _pick(draw, IDS, start)
                start.append(b'"')
            plain &= _pick(draw, DIRECTED, start)
        if draw(st.integers(0, 7)) == 0:
            plain &= _pick(draw, TAG_EXTRAS, start)
        values: list[bytes] = []
        for _ in range(draw(st.integers(0, 2))):
            values.append(b"<" + p + b'data key="' + draw(st.sampled_from(key_ids)) + b'">')
            plain &= _pick(draw, VALUES, values)
            values.append(b"</" + p + b"data>")
            if draw(st.integers(0, 3)) == 0:
                plain &= _pick(draw, CHILDREN, values)
        if values:
            parts.append(b"".join(start) + b">" + b"".join(values) + b"</" + p + tag + b">\n")
        else:
            parts.append(b"".join(start) + b"/>\n")
    parts.append(b"</" + p + b"graph>\n</" + p + b"graphml>\n")
    plain &= _pick(draw, PROLOG_MISC[:5], parts)  # comments and PIs after the root element
    data = b"".join(parts)
    if draw(st.integers(0, 7)) == 0:  # a byte or a construct anywhere
        at = draw(st.integers(0, len(data)))
        piece, _ = draw(st.sampled_from(DOC_BREAKS))
        data, plain = data[:at] + piece + data[at:], False
    return Doc(data, plain)


# ---------------------------------------------------------------------------------------------------------
# reading a document both ways


def raw_view(raw: RawGraph) -> dict:
    """Everything a reader hands over, as plain values (numbers compared apart)."""
    return {"nodes": raw.nodes, "edges": raw.edges.tolist(), "undirected": raw.graph_undirected,
            "keys": [(k, v.id, v.name, v.domain, v.type, v.default) for k, v in raw.keys.items()],
            "data": raw.data.tolist(), "data_keys": raw.data_keys,
            "texts": [raw.text(i) for i in range(len(raw.data))],
            "places": [raw.place(i) for i in range(len(raw.data))], "booleans": raw.booleans.tolist()}


def graph_view(raw: RawGraph) -> tuple | str:
    """The graph of facts built from a reading, or the error that building it gives."""
    try:
        g: Graph = _to_graph(raw)
    except ProgramCheckError as e:
        return str(e)
    return (g.nodes, g.labels, g.label_arity, g.fact_label.tolist(), g.fact_args.tolist(), g.fact_bounds.tolist(),
            g.edges.tolist())


def assert_readers_agree(path: Path, data: bytes, plain: bool) -> RawGraph | ProgramCheckError:
    """Expat's reading of `data` (written to `path`), after checking the scanner against it. Returns the
    raw graph, or the located error both readings give."""
    path.write_bytes(data)
    try:
        full = read_graphml_expat(str(path))
    except ProgramCheckError as e:
        assert _scan(str(path), data) is None, f"expat refuses ({e}), the scanner reads it"
        with pytest.raises(ProgramCheckError) as fast_error:
            read_raw_graphml(path)
        assert fast_error.value.line > 0 and str(fast_error.value) == str(e)
        return e
    fast = _scan(str(path), data)
    if plain:
        assert fast is not None, "the scanner should read this file itself"
    if fast is not None:
        assert raw_view(fast) == raw_view(full)
        # the scanner leaves numbers it cannot convert exactly as NaN: every reader of numbers falls back
        assert np.array_equal(np.isnan(fast.numbers) | (fast.numbers == full.numbers),
                              np.ones(len(full.numbers), np.bool_))
        assert not (np.isnan(full.numbers) & ~np.isnan(fast.numbers)).any()
        assert graph_view(fast) == graph_view(full)
    return full


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(doc=graphml_documents())
def test_the_scanner_refuses_what_expat_refuses_and_reads_the_rest_alike(doc: Doc) -> None:
    with tempfile.TemporaryDirectory() as d:
        assert_readers_agree(Path(d) / "g.graphml", doc.data, doc.plain)


# ---------------------------------------------------------------------------------------------------------
# explicit cases: one per XML rule, each read both ways

KEYS = ('<key id="k" for="node" attr.name="hp" attr.type="string"/>'
        '<key id="b" for="node" attr.name="ok" attr.type="boolean"/>')


def doc(body: str, before: str = "", keys: str = KEYS) -> bytes:
    """A document whose `body` (nodes and edges) is line 2 (`before` it: a declaration or a DOCTYPE)."""
    return f'{before}<graphml>{keys}<graph edgedefault="directed">\n{body}\n</graph></graphml>'.encode()


def node(nid: str, value: str | None = None) -> str:
    return f'<node id="{nid}"/>' if value is None else f'<node id="{nid}"><data key="k">{value}</data></node>'


REFUSED = [  # (case, document, what expat says, line, column)
    ("duplicate attribute", doc('<node id="a" id="b"/>'), "duplicate attribute", 2, 14),
    ("undefined entity in text", doc(node("a") + "&nbsp;"), "undefined entity", 2, 15),
    ("undefined entity in a value", doc(node("a", "&x;")), "undefined entity", 2, 28),
    ("undefined entity in an attribute", doc(node("a&x;b")), "undefined entity", 2, 1),
    ("reference to NUL", doc(node("&#0;")), "reference to invalid character number", 2, 11),
    ("reference to a control character", doc(node("a", "&#x1;")), "reference to invalid character", 2, 28),
    ("reference to U+FFFE", doc(node("&#xFFFE;")), "reference to invalid character number", 2, 11),
    ("reference to a surrogate", doc(node("a", "&#xD800;")), "reference to invalid character", 2, 28),
    ("control character in text", doc(node("a") + "\x01"), "not well-formed (invalid token)", 2, 15),
    ("control character in a value", doc(node("a", "0.5\x1b")), "not well-formed", 2, 31),
    ("control character in an attribute", doc(node("a\x7fb\x08")), "not well-formed", 2, 14),
    ("control character in a comment", doc("<!-- \x0c -->" + node("a")), "not well-formed", 2, 6),
    ("invalid UTF-8", doc(node("a")).replace(b'"a"', b'"\xff"'), "not well-formed", 2, 11),
    ("U+FFFF as UTF-8", doc(node("\uffff")), "not well-formed", 2, 11),
    ("-- in a comment", doc("<!-- a -- b -->" + node("a")), "not well-formed", 2, 10),
    ("comment ending --->", doc("<!-- a --->" + node("a")), "not well-formed", 2, 10),
    ("]]> in text", doc(node("a") + "]]>"), "not well-formed", 2, 17),
    ("XML declaration not at the start", doc(node("a"), "\n<?xml version='1.0'?>"), "not at start", 2, 1),
    ("PI named XML", doc("<?XML x?>" + node("a")), "not well-formed", 2, 6),
    ("mismatched end tag", doc('<node id="a"></edge>'), "mismatched tag", 2, 16),
    ("unclosed element", doc('<node id="a">'), "mismatched tag", 3, 3),
    ("end tag with an attribute", doc('<node id="a"></node x="1">'), "not well-formed", 2, 21),
    ("attribute without quotes", doc("<node id=a/>"), "not well-formed", 2, 10),
    ("attributes without space between", doc('<edge source="a"target="b"/>'), "not well-formed", 2, 17),
    ("< in an attribute value", doc(node("a<b")), "not well-formed", 2, 12),
    ("name starting with a digit", doc("<1node/>"), "not well-formed", 2, 2),
    ("text after the root element", doc(node("a")) + b"x", "junk after document element", 3, 19),
    ("text before the root element", doc(node("a"), "x"), "not well-formed", 1, 2),
    ("second root element", doc(node("a")) + b"<graphml/>", "junk after document element", 3, 19),
    ("ASCII declared, UTF-8 written", doc(node("é"), '<?xml version="1.0" encoding="us-ascii"?>'),
     "not well-formed", 2, 11),
    ("utf8 (no hyphen) declared, UTF-8 written", doc(node("é"), '<?xml version="1.0" encoding="utf8"?>'),
     "not well-formed", 2, 11),
    ("an encoding Python does not know", doc(node("a"), '<?xml version="1.0" encoding="x-nope"?>'),
     "the encoding it declares cannot be read", 1, 31),
    ("a codec that is not a text encoding", doc(node("a"), '<?xml version="1.0" encoding="rot13"?>'),
     "the encoding it declares cannot be read", 1, 31),
    ("a multi-byte codec", doc(node("a"), '<?xml version="1.0" encoding="shift_jis"?>'),
     "the encoding it declares cannot be read", 1, 31),
    ("entity declaration", doc(node("&e;"), '<!DOCTYPE graphml [<!ENTITY e "a">]>'), "declares the entity 'e'", 1, 31),
    ("parameter entity declaration", doc(node("a"), '<!DOCTYPE graphml [<!ENTITY % p "x"> %p;]>'),
     "declares the entity 'p'", 1, 33),
    ("attribute default in the DTD", doc("<node/>", '<!DOCTYPE graphml [<!ATTLIST node id CDATA "x">]>'),
     "attribute defaults are refused", 1, 44),
    ("entity an external DTD would declare", doc(node("a", "&e;"), '<!DOCTYPE graphml SYSTEM "g.dtd">'),
     "refers to the entity 'e', which it does not declare", 2, 28),
    ("key with an unknown type", doc(node("a"), keys='<key id="k" attr.type="bogus"><default>1</default></key>'),
     "unknown attr.type 'bogus'", 1, 10),
]


@pytest.mark.parametrize("case,data,fragment,line,column", REFUSED, ids=[c[0] for c in REFUSED])
def test_what_xml_refuses_both_readers_refuse_located(tmp_path: Path, case: str, data: bytes, fragment: str,
                                                      line: int, column: int) -> None:
    error = assert_readers_agree(tmp_path / "g.graphml", data, plain=False)
    assert isinstance(error, ProgramCheckError), f"{case}: read as {raw_view(error)['nodes']}"
    assert fragment in error.message and (error.line, error.column) == (line, column), str(error)


READ = [  # (case, document, node ids, values, whether the scanner reads it itself)
    ("attribute values: tab, LF, CR, CRLF are spaces", doc(node("a\tb\nc\rd\r\ne")), ["a b c d e"], [], False),
    ("attribute values: references kept as written", doc(node("a&#9;b&#10;c&#13;&lt;&amp;&gt;&quot;&apos;&#x41;")),
     ["a\tb\nc\r<&>\"'A"], [], False),
    ("values: CRLF and CR are LF", doc(node("a", "[0.2,\r\n0.5\r]")), ["a"], ["[0.2,\n0.5\n]"], False),
    ("values: &#13; is kept", doc(node("a", "0.5&#13;")), ["a"], ["0.5\r"], False),
    ("values: CDATA", doc(node("a", "<![CDATA[<0.5>]]>")), ["a"], ["<0.5>"], False),
    ("values: comments and PIs inside", doc(node("a", "0.<!-- x -->2,<?pi?>0.5")), ["a"], ["0.2,0.5"], False),
    ("values: > and ]] are text", doc(node("a", "]]>".replace(">", "&gt;")) + node("b", "a>b]]")), ["a", "b"],
     ["]]>", "a>b]]"], False),
    ("empty comment, PI, > in an attribute", doc("<!---->" + "<?tool go?>" + node("a>b", "0.5")), ["a>b"], ["0.5"],
     True),
    ("UTF-8 byte order mark", doc(node("a", "0.5"), "\ufeff"), ["a"], ["0.5"], True),
    ("XML declaration, standalone", doc(node("a"), "<?xml version='1.0' encoding='UTF-8' standalone='yes'?>"),
     ["a"], [], True),
    ("ASCII declared, ASCII written", doc(node("a"), '<?xml version="1.0" encoding="US-ASCII"?>'), ["a"], [], True),
    ("Latin-1 declared and written", doc(node("café"), '<?xml version="1.0" encoding="ISO-8859-1"?>').replace(
        "é".encode(), b"\xe9"), ["café"], [], False),
    ("UTF-16 with its byte order mark", ('<?xml version="1.0" encoding="UTF-16"?>' + doc(node("é")).decode()
                                         ).encode("utf-16"), ["é"], [], False),
    ("a DOCTYPE without declarations", doc(node("a"), "<!DOCTYPE graphml>"), ["a"], [], False),
    ("an external DTD (never read)", doc(node("a"), '<!DOCTYPE graphml SYSTEM "http://x/graphml.dtd">'), ["a"],
     [], False),
    ("an external DTD: an undeclared entity in an attribute is empty (expat says nothing)",
     doc(node("a&e;b"), '<!DOCTYPE graphml SYSTEM "g.dtd">'), ["ab"], [], False),
    ("names with prefixes, dots and dashes", doc('<x:node id="a"><x.y-z/></x:node>'), ["a"], [], True),
    ("line breaks in attributes nothing reads", doc('<node id="a"><port name="p\n\tq"/></node>').replace(
        b"<graphml>", b'<graphml xsi:schemaLocation="http://graphml.graphdrawing.org/xmlns\n  graphml.xsd">'),
     ["a"], [], True),
    ("C1 controls, U+FFFD, astral characters", doc(node("\x85\ufffd\U0010ffff", "\x80")), ["\x85\ufffd\U0010ffff"],
     ["\x80"], True),
]


@pytest.mark.parametrize("case,data,nodes,values,scanned", READ, ids=[c[0] for c in READ])
def test_what_xml_reads_both_readers_read_alike(tmp_path: Path, case: str, data: bytes, nodes: list[str],
                                                values: list[str], scanned: bool) -> None:
    raw = assert_readers_agree(tmp_path / "g.graphml", data, plain=scanned)
    assert isinstance(raw, RawGraph), str(raw)
    assert raw.nodes == nodes and [raw.text(i) for i in range(len(raw.data))] == values
    assert (_scan(str(tmp_path / "g.graphml"), data) is not None) == scanned


def test_key_defaults_read_as_expat_reads_them(tmp_path: Path) -> None:
    """The scanner hands <key> elements to expat: comments inside a default, the last of two defaults,
    an empty default (an error when applied), CRLF in a default."""
    for default, expected in [("0.<!-- c -->5", "0.5"), ("0.25</default><default>0.5", "0.5"), ("", ""),
                              ("\r\n0.5\r\n", "\n0.5\n")]:
        keys = f'<key id="k" for="node" attr.name="hp" attr.type="double"><default>{default}</default></key>'
        raw = assert_readers_agree(tmp_path / "g.graphml", doc(node("a"), keys=keys), plain=True)
        assert isinstance(raw, RawGraph) and raw.keys["k"].default == expected


def test_edgedefault_is_an_attribute_not_text_in_another_value(tmp_path: Path) -> None:
    data = b'<graphml><graph id=" edgedefault=\'undirected\'"><edge source="a" target="b"/></graph></graphml>'
    raw = assert_readers_agree(tmp_path / "g.graphml", data, plain=True)
    assert isinstance(raw, RawGraph) and not raw.graph_undirected


def test_booleans_with_unicode_spaces_read_as_python_strips_them(tmp_path: Path) -> None:
    data = doc('<node id="a"><data key="b">\u00a0true\u2003</data></node>')
    raw = assert_readers_agree(tmp_path / "g.graphml", data, plain=True)
    assert isinstance(raw, RawGraph) and raw.booleans.tolist() == [1]


def test_error_columns_count_characters_as_expat_does(tmp_path: Path) -> None:
    """A value's place after non-ASCII text on its line: expat counts characters, not bytes."""
    before = '\ufeff<graphml><key id="k" for="node" attr.name="hp" attr.type="double"/><graph><node id="ééé">'
    data = (before + '<data key="k">7</data></node></graph></graphml>').encode()
    raw = assert_readers_agree(tmp_path / "g.graphml", data, plain=True)
    column = len(before) + 1  # the byte order mark is a character of line 1 too
    assert isinstance(raw, RawGraph) and raw.place(0) == (1, column) and column < len(before.encode()) + 1
    with pytest.raises(ProgramCheckError, match="value 7.0 is not a bound") as e:
        _to_graph(raw)
    assert (e.value.line, e.value.column) == (1, column)


# ---------------------------------------------------------------------------------------------------------
# entity expansion and its cousins, through the command (each in a process with a time limit)

BOMBS = {
    "billion laughs": '<?xml version="1.0"?>\n<!DOCTYPE graphml [\n<!ENTITY a "aaaaaaaaaa">\n'
    + "".join(f'<!ENTITY {c} "{("&" + p + ";") * 10}">\n' for p, c in zip("abcdefgh", "bcdefghi"))
    + ']>\n<graphml><graph><node id="&i;"/></graph></graphml>\n',
    "parameter entities": '<!DOCTYPE graphml [\n<!ENTITY % a "<!ENTITY b \'bbbbbbbbbb\'>">\n%a;\n]>\n'
    '<graphml><graph><node id="&b;"/></graph></graphml>\n',
    "external entity": '<!DOCTYPE graphml [\n<!ENTITY s SYSTEM "file:///etc/passwd">\n]>\n'
    '<graphml><graph><node id="a"><data key="k">&s;</data></node></graph></graphml>\n',
}


def _reason(graph: Path, timeout: float) -> subprocess.CompletedProcess:
    rules = graph.with_suffix(".rules")
    rules.write_text("seen(X) <-1 seen(X)\n")
    return subprocess.run([sys.executable, "-m", "tracelab", "reason", str(rules), "--graph", str(graph),
                           "--steps", "1", "--no-trace"], capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("bomb", sorted(BOMBS))
def test_entity_bombs_are_refused_by_both_readers(tmp_path: Path, bomb: str) -> None:
    path = tmp_path / "bomb.graphml"
    path.write_text(BOMBS[bomb])
    assert _scan(str(path), path.read_bytes()) is None  # the scanner expands nothing: a DTD goes to expat
    with pytest.raises(ProgramCheckError, match="declares the entity") as e:
        load_graphml(path)
    assert e.value.line == (3 if bomb == "billion laughs" else 2)


def test_billion_laughs_is_one_line_from_the_command(tmp_path: Path) -> None:
    path = tmp_path / "bomb.graphml"
    path.write_text(BOMBS["billion laughs"])
    done = _reason(path, timeout=120)
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"tracelab: error: {path}:3:") and "declares the entity 'a'" in done.stderr


def test_attribute_defaults_cannot_multiply_a_small_file(tmp_path: Path) -> None:
    """A 200 KB default copied into a million <node/> elements (a 7 MB file) would be 200 GB of copying:
    refused at the declaration, in well under the time limit."""
    path = tmp_path / "defaults.graphml"
    big = "v" * 200_000
    path.write_text(f'<!DOCTYPE graphml [<!ATTLIST node id CDATA "{big}">]>\n<graphml><graph>'
                    + "<node/>" * 1_000_000 + "</graph></graphml>\n")
    done = _reason(path, timeout=60)
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr[-500:]
    assert f"{path}:1:" in done.stderr and "attribute defaults are refused" in done.stderr
