"""A compiled scanner for the plain GraphML that graph tools write: one pass over the bytes finds nodes,
edges and their <data> values, interns node ids and key ids in hash tables and parses numbers and
booleans, so that a million-edge file costs well under a second, not a Python call per element.

It reads a subset of XML 1.0, and within it reads exactly what expat reads (the expat reader,
graphml_expat.py, is the definition; tests/test_graphml_differential.py compares the two). Whatever leaves
the subset makes it stop with status SCAN_UNSUPPORTED, and the caller reads the file with expat, which
resolves what the scanner does not and gives the located error for what XML refuses. Left to expat:
- anything expat would refuse: a character XML does not allow (a control character, invalid UTF-8,
  U+FFFE / U+FFFF), a duplicate attribute, a name that is not an XML name (non-ASCII names included),
  an attribute without quotes or without white space before it, `<` in an attribute value, `--` inside
  a comment, `]]>` in text, text outside the root element, end tags that do not match, an end tag with
  attributes;
- anything expat would turn into other characters: a reference (`&`), a tab or line break in an
  attribute value of a node, edge, data or graph element (XML makes each a space; in other elements,
  such as the root's multi-line xsi:schemaLocation, nothing reads it), a carriage return in a <data>
  value (XML makes line ends LF);
- a DOCTYPE or CDATA section, a processing instruction named xml... (the XML declaration is checked by
  the caller, graph.py), elements inside <data>, a <node> without an id, an <edge> without source or
  target, elements inside a <key> that the graph reads (nodes, edges, data, keys, graphs).
Within the subset there is nothing to expand, so nothing hostile to do.
"""
from __future__ import annotations

import numpy as np
from numba import njit

SCAN_OK, SCAN_UNSUPPORTED, SCAN_GROW = 0, 1, 2  # SCAN_GROW: the node table is half full, scan again larger
# elements the scanner knows
_OTHER, _NODE, _EDGE, _DATA, _KEY, _GRAPH = 0, 1, 2, 3, 4, 5
# per data value: (kind 0 node / 1 edge, element index, key index, text start, text end, tag offset)
D_KIND, D_ELEM, D_KEY, D_START, D_END, D_POS = 0, 1, 2, 3, 4, 5
N_DCOLS = 6
# per edge: (source, target, directed: -1 graph default / 0 undirected / 1 directed)
E_SRC, E_DST, E_DIRECTED = 0, 1, 2
# counts written by scan: nodes, edges, data values, key ids, key elements
C_NODES, C_EDGES, C_DATA, C_KEYS, C_KEY_ELEMS = 0, 1, 2, 3, 4
MAX_DEPTH = 256
MAX_ATTRS = 64  # attributes of one tag the duplicate check holds; a tag with more is left to expat
# graph_tag: offset of the <graph> tag (-1 none), then its edgedefault value (start, end; -1 none)
G_TAG, G_EDGEDEFAULT_S, G_EDGEDEFAULT_E = 0, 1, 2
BOOLEAN_UNKNOWN = -2  # a value with non-ASCII bytes: its boolean is decided in Python (str.strip's spaces)

# no reference counting (`_nrt=False`): each array passed to a helper would cost atomic operations per
# call, a real cost per tag (figures: docs/benchmarks.md, "Figures behind the code");
# every buffer is allocated by the caller (`scan_graphml`)
scan_jit = njit(cache=True, _nrt=False)
# small helpers called per tag or per byte, inlined in numba's IR: LLVM left some as calls, and the checks
# XML needs made `scan` slower until they were inlined; docs/benchmarks.md, "Figures behind the code")
scan_inline = njit(cache=True, _nrt=False, inline="always")
_POW10 = np.array([float(f"1e{k}") for k in range(23)])  # exact doubles


def _packed(word: bytes) -> int:
    """Up to 8 bytes as one integer, the way _pack reads a name."""
    v = 0
    for c in word:
        v = (v << 8) | c
    return v


W_NODE, W_EDGE, W_DATA, W_KEY, W_GRAPH = (_packed(w) for w in (b"node", b"edge", b"data", b"key", b"graph"))
W_ID, W_SOURCE, W_TARGET, W_DIRECTED = (_packed(w) for w in (b"id", b"source", b"target", b"directed"))
W_TRUE, W_FALSE, W_ONE, W_ZERO = (_packed(w) for w in (b"true", b"false", b"1", b"0"))
_EDGEDEFAULT = np.frombuffer(b"edgedefault", np.uint8).copy()


def _byte_table(classes: dict[int, bytes]) -> np.ndarray:
    """A 256-entry table of byte classes: the bytes listed under a class have it, all others 0."""
    table = np.zeros(256, np.uint8)
    for cls, members in classes.items():
        table[np.frombuffer(members, np.uint8)] = cls
    return table


_LETTERS = bytes(range(65, 91)) + bytes(range(97, 123))
# XML names in ASCII: 1 may start a name, 2 may continue one; any other byte (non-ASCII too) ends it
_NAME_CLASS = _byte_table({1: _LETTERS + b"_:", 2: b"0123456789.-"})
# in an attribute value: 1 a quote (the closing one, or the other kind), 2 leave it to expat ('<' is an
# error, '&' a reference), 3 tab / LF / CR (XML makes each a space: left to expat where the graph reads it)
_VALUE_CLASS = _byte_table({1: b"\"'", 2: b"<&", 3: b"\t\n\r"})
# in text: 1 '<' ends it, 2 leave it to expat ('&' a reference, CR a line end made LF), 3 ']' (']]>')
_TEXT_CLASS = _byte_table({1: b"<", 2: b"&\r", 3: b"]"})
# bytes that need a closer look in the character check: control characters but tab / LF / CR, non-ASCII
_CHAR_CHECK = _byte_table({1: bytes(range(0, 9)) + b"\x0b\x0c" + bytes(range(14, 32)) + bytes(range(128, 256))})


@scan_inline
def _pack(b, s, e, lower):
    """b[s:e] as one integer (-1 if longer than 8 bytes), lower-cased if `lower`."""
    if e - s > 8 or e < s:
        return -1
    v = 0
    for k in range(s, e):
        c = b[k]
        if lower and 65 <= c <= 90:
            c += 32
        v = (v << 8) | c
    return v


@scan_inline
def _local_name(b, s, e):
    """The packed name b[s:e] without a namespace prefix."""
    for k in range(e - 1, s - 1, -1):
        if b[k] == 58:  # ':'
            return _pack(b, k + 1, e, False)
    return _pack(b, s, e, False)


@scan_jit
def _hash(b, s, e):
    h = np.uint64(14695981039346656037)
    for i in range(s, e):
        h = (h ^ np.uint64(b[i])) * np.uint64(1099511628211)
    return h


@scan_inline
def _same(b, s1, e1, s2, e2):
    if e1 - s1 != e2 - s2:
        return False
    for k in range(e1 - s1):
        if b[s1 + k] != b[s2 + k]:
            return False
    return True


@scan_jit
def _intern(b, s, e, table, spans, n):
    """Index of the byte string b[s:e] among spans[:n]; a new one is added as n (the caller counts).
    The table (open addressing, -1 empty) is sized by the caller for every string there can be."""
    mask = np.uint64(table.shape[0] - 1)
    j = _hash(b, s, e) & mask
    while True:
        k = table[j]
        if k < 0:
            break
        if _same(b, spans[k, 0], spans[k, 1], s, e):
            return k
        j = (j + np.uint64(1)) & mask
    spans[n, 0] = s
    spans[n, 1] = e
    table[j] = n
    return n


@scan_jit
def _intern_node(b, s, e, table, off, pool, n):
    """Index of node id b[s:e] among the n interned so far; a new one is added as n (its bytes copied into
    the pool). A table slot is (tag, index), 0 empty. An id of up to 7 bytes is its own tag (the bytes
    and the length packed), so a lookup reads one slot and nothing else: on random edge ends, each extra
    read of the pool was a cache miss. A longer id's tag is its hash, confirmed against the pool."""
    m = e - s
    if m <= 7:
        tag = np.int64(m + 1) << 56
        for x in range(s, e):
            tag |= np.int64(b[x]) << (8 * (e - 1 - x))
        h = np.uint64(tag) * np.uint64(0x9E3779B97F4A7C15)
        h ^= h >> np.uint64(29)
    else:
        h = _hash(b, s, e)
        tag = (np.int64(64) << 56) | np.int64(h >> np.uint64(8))
    mask = np.uint64(table.shape[0] - 1)
    j = h & mask
    while True:
        v = table[j, 0]
        if v == 0:
            break
        if v == tag:
            k = table[j, 1]
            if m <= 7:
                return k
            ps = off[k]
            if off[k + 1] - ps == m:
                same = True
                for x in range(m):
                    if pool[ps + x] != b[s + x]:
                        same = False
                        break
                if same:
                    return k
        j = (j + np.uint64(1)) & mask
    ps = off[n]
    for x in range(m):
        pool[ps + x] = b[s + x]
    off[n + 1] = ps + m
    table[j, 0] = tag
    table[j, 1] = n
    return n


@scan_inline
def _is_space(c):
    return c == 32 or c == 9 or c == 10 or c == 13


@scan_jit
def _skip_past(b, i, c0, c1, c2):
    """Offset just past the first c0 c1 c2 (c2 < 0: c0 c1) at or after i, or -1."""
    n = b.shape[0]
    while i + 1 < n:
        if b[i] == c0 and b[i + 1] == c1:
            if c2 < 0:
                return i + 2
            if i + 2 < n and b[i + 2] == c2:
                return i + 3
        i += 1
    return -1


@scan_jit
def _utf8_char_length(b, i, n):
    """Length of the UTF-8 sequence starting at b[i] (a byte >= 0x80) when it encodes a character XML 1.0
    allows, else 0 (a stray or overlong byte, a surrogate, past U+10FFFF, U+FFFE, U+FFFF)."""
    c = b[i]
    if c < 0xC2 or c > 0xF4:
        return 0
    if c < 0xE0:
        return 2 if i + 1 < n and 0x80 <= b[i + 1] <= 0xBF else 0
    if c < 0xF0:
        if i + 2 >= n:
            return 0
        c1, c2 = b[i + 1], b[i + 2]
        lo = 0xA0 if c == 0xE0 else 0x80
        hi = 0x9F if c == 0xED else 0xBF
        if not (lo <= c1 <= hi and 0x80 <= c2 <= 0xBF):
            return 0
        if c == 0xEF and c1 == 0xBF and c2 >= 0xBE:
            return 0
        return 3
    if i + 3 >= n:
        return 0
    lo = 0x90 if c == 0xF0 else 0x80
    hi = 0x8F if c == 0xF4 else 0xBF
    if not (lo <= b[i + 1] <= hi and 0x80 <= b[i + 2] <= 0xBF and 0x80 <= b[i + 3] <= 0xBF):
        return 0
    return 4


@scan_jit
def _check_chars(b, i, end):
    """The characters from b[i] up to `end` (the last may run past it): (the offset after them, -1), or
    (i, the offset of the first one XML does not allow)."""
    n = b.shape[0]
    while i < end:
        c = b[i]
        if _CHAR_CHECK[c] == 0:
            i += 1
        elif c < 128:
            return i, i
        else:
            m = _utf8_char_length(b, i, n)
            if m == 0:
                return i, i
            i += m
    return i, -1


@scan_jit
def first_bad_char(b):
    """Offset of the first byte that does not start a character XML 1.0 allows in UTF-8, or -1. A block
    of 256 bytes is passed over in one vectorised test when it holds only ASCII and tab / LF / CR (blocks
    aligned to the start and the test as comparisons: several times faster than a table lookup per byte,
    or blocks at any offset; docs/benchmarks.md, "Figures behind the code")."""
    n = b.shape[0]
    whole = n - n % 256
    i = 0  # checked up to here (a multi-byte character may end past a block)
    for start in range(0, whole, 256):
        odd = False
        for k in range(start, start + 256):
            c = b[k]
            odd |= (c >= 128) | ((c < 32) & (c != 9) & (c != 10) & (c != 13))
        if odd:
            i, bad = _check_chars(b, max(i, start), start + 256)
            if bad >= 0:
                return bad
    return _check_chars(b, max(i, whole), n)[1]


@scan_jit
def _count_name(w, counts):
    if w == W_NODE:
        counts[0] += 1
    elif w == W_EDGE:
        counts[1] += 1
    elif w == W_DATA:
        counts[2] += 1
    elif (w >> 8) == W_KEY:
        counts[3] += 1


@scan_jit
def _count_starts(b, counts):
    n = b.shape[0]
    for i in range(n - 4):
        if b[i] != 60:
            continue
        c = b[i + 1]
        if c == 47 or c == 33 or c == 63:  # '</', '<!', '<?': no element starts here
            continue
        w = _pack(b, i + 1, i + 5, False)
        if w == W_NODE or w == W_EDGE or w == W_DATA or (w >> 8) == W_KEY:
            _count_name(w, counts)
            continue
        # a prefix: '<' name ':' (the bytes after ':' as above)
        k = i + 1
        while k < n and k < i + 65 and b[k] != 58 and b[k] != 62 and not _is_space(b[k]) and b[k] != 60:
            k += 1
        if k + 4 < n and b[k] == 58:
            _count_name(_pack(b, k + 1, k + 5, False), counts)


def count_starts(b: np.ndarray) -> tuple[int, int, int, int]:
    """How many '<node', '<edge', '<data', '<key' (any prefix) there are: the buffer sizes of scan.
    Closing tags, comments and declarations are passed over at their second byte."""
    counts = np.zeros(4, np.int64)
    _count_starts(b, counts)
    c_node, c_edge, c_data, c_key = (int(x) for x in counts)
    return c_node, c_edge, c_data, c_key


@scan_jit
def parse_number(b, s, e):
    """A decimal number in b[s:e] ([+-]digits[.digits][e[+-]digits], spaces around) as float() reads it,
    or NaN when it is not one or is beyond exact conversion (more than 15 digits or a large exponent:
    the caller converts those in Python)."""
    while s < e and _is_space(b[s]):
        s += 1
    while e > s and _is_space(b[e - 1]):
        e -= 1
    if s == e:
        return np.nan
    sign = 1.0
    if b[s] == 45 or b[s] == 43:
        sign = -1.0 if b[s] == 45 else 1.0
        s += 1
    mant = 0
    digits = 0
    frac = 0
    i = s
    while i < e and 48 <= b[i] <= 57:
        mant = mant * 10 + (b[i] - 48)
        i += 1
        digits += 1
    if i < e and b[i] == 46:
        i += 1
        while i < e and 48 <= b[i] <= 57:
            mant = mant * 10 + (b[i] - 48)
            i += 1
            digits += 1
            frac += 1
    if digits == 0 or digits > 15:
        return np.nan
    ex = 0
    if i < e and (b[i] == 101 or b[i] == 69):
        i += 1
        esign = 1
        if i < e and (b[i] == 45 or b[i] == 43):
            esign = -1 if b[i] == 45 else 1
            i += 1
        ed = 0
        while i < e and 48 <= b[i] <= 57 and ed < 4:
            ex = ex * 10 + (b[i] - 48)
            i += 1
            ed += 1
        if ed == 0:
            return np.nan
        ex *= esign
    if i != e:
        return np.nan
    p = ex - frac
    if p > 22 or p < -22:
        return np.nan
    # an integer below 2^53 times or over an exact power of ten: one correctly rounded operation
    if p >= 0:
        return sign * (float(mant) * _POW10[p])
    return sign * (float(mant) / _POW10[-p])


@scan_inline
def _name_end(b, s, n):
    """End of the XML name starting at b[s] (ASCII letters, digits, '_', ':', '.', '-'; not starting with a
    digit, '.' or '-'), or s when none starts there. A name holding any other byte ends before it, and the
    caller then finds a byte it does not expect there."""
    if s >= n or _NAME_CLASS[b[s]] != 1:
        return s
    e = s + 1
    while e < n and _NAME_CLASS[b[e]] != 0:
        e += 1
    return e


@scan_jit
def _is_word(b, s, e, word):
    if e - s != word.shape[0]:
        return False
    for k in range(e - s):
        if b[s + k] != word[k]:
            return False
    return True


@scan_jit
def _skip_pi(b, i, n):
    """Offset past the processing instruction at b[i] ('<?'), or -1 when it is one to leave to expat: a
    target that is no name or is named xml... (the XML declaration, which the caller passed over, and
    the names XML reserves)."""
    s = i + 2
    e = _name_end(b, s, n)
    if e == s or (e - s >= 3 and (b[s] | 32) == 120 and (b[s + 1] | 32) == 109 and (b[s + 2] | 32) == 108):
        return -1
    if e + 1 < n and b[e] == 63 and b[e + 1] == 62:  # '?>'
        return e + 2
    if e < n and _is_space(b[e]):
        return _skip_past(b, e, 63, 62, -1)
    return -1


@scan_jit
def _skip_comment(b, i, n):
    """Offset past the comment at b[i] ('<!--'), or -1: a comment ends at its first '--', which must be
    followed by '>'."""
    k = _skip_past(b, i + 4, 45, 45, -1)
    if k < 0 or k >= n or b[k] != 62:
        return -1
    return k + 1


@scan_inline
def _end_tag_end(b, j, n):
    """Offset past the end tag whose name ends at b[j] (white space, then '>'), or -1."""
    while j < n and _is_space(b[j]):
        j += 1
    if j >= n or b[j] != 62:
        return -1
    return j + 1


@scan_jit
def scan(b, start, node_tab, node_off, pool, edges, data, key_tab, key_spans, key_elems, stack, attrs,
         graph_tag, counts):
    """Scan GraphML bytes `b` from offset `start` (past a byte order mark and an XML declaration) into the
    caller's buffers (sized by count_starts); counts[C_*] say how much of each was filled. Returns
    (status, byte offset where the file left the subset)."""
    n = b.shape[0]
    n_nodes = 0
    n_keys = 0
    n_edges = 0
    n_data = 0
    n_key_elems = 0
    graph_tag[G_TAG] = -1
    graph_tag[G_EDGEDEFAULT_S] = -1
    graph_tag[G_EDGEDEFAULT_E] = -1
    cur_kind = -1  # the open node (0) or edge (1), -1 none
    cur_elem = -1
    in_key = -1  # start offset of an open <key> element
    depth = 0
    roots = 0
    i = start
    while i < n:
        c = b[i]
        if c != 60:  # text between tags (no graph reads it: <data> values are read below)
            if c == 38 or (depth == 0 and not _is_space(c)):  # a reference; text outside the root element
                return SCAN_UNSUPPORTED, i
            if c == 93 and i + 2 < n and b[i + 1] == 93 and b[i + 2] == 62:  # ']]>'
                return SCAN_UNSUPPORTED, i
            i += 1
            continue
        if i + 1 >= n:
            return SCAN_UNSUPPORTED, i
        c = b[i + 1]
        if c == 63:  # '<?' a processing instruction
            i = _skip_pi(b, i, n)
            if i < 0:
                return SCAN_UNSUPPORTED, n
            continue
        if c == 33:  # '<!': a comment, else (DOCTYPE, CDATA) outside the subset
            if i + 3 < n and b[i + 2] == 45 and b[i + 3] == 45:
                i = _skip_comment(b, i, n)
                if i < 0:
                    return SCAN_UNSUPPORTED, n
                continue
            return SCAN_UNSUPPORTED, i
        closing = c == 47  # '</'
        s = i + 2 if closing else i + 1
        e = _name_end(b, s, n)
        if e == s:
            return SCAN_UNSUPPORTED, i
        name = _local_name(b, s, e)
        kind = _OTHER
        if name == W_NODE:
            kind = _NODE
        elif name == W_EDGE:
            kind = _EDGE
        elif name == W_DATA:
            kind = _DATA
        elif name == W_KEY:
            kind = _KEY
        elif name == W_GRAPH:
            kind = _GRAPH
        if closing:
            tag_end = _end_tag_end(b, e, n)
            if tag_end < 0 or depth == 0 or not _same(b, stack[depth - 1, 0], stack[depth - 1, 1], s, e):
                return SCAN_UNSUPPORTED, i
            depth -= 1
            if kind == _NODE or kind == _EDGE:
                if cur_kind != kind - 1:
                    return SCAN_UNSUPPORTED, i
                cur_kind = -1
            elif kind == _KEY and in_key >= 0 and depth == stack[MAX_DEPTH - 1, 0]:
                if n_key_elems == key_elems.shape[0]:
                    return SCAN_UNSUPPORTED, i
                key_elems[n_key_elems, 0] = in_key
                key_elems[n_key_elems, 1] = tag_end
                n_key_elems += 1
                in_key = -1
            i = tag_end
            continue
        # attributes up to '>' or '/>', each after white space, each name once, values in quotes
        j = e
        n_attrs = 0
        a_val_s = -1  # the value the element is read by: a node's id, a data's key, a graph's edgedefault
        a_val_e = -1
        a_src_s = -1
        a_src_e = -1
        a_dst_s = -1
        a_dst_e = -1
        a_dir_s = -1
        a_dir_e = -1
        while True:
            before = j
            while j < n and _is_space(b[j]):
                j += 1
            if j >= n:
                return SCAN_UNSUPPORTED, i
            if b[j] == 62 or b[j] == 47:  # '>', '/'
                break
            ns = j
            ne = _name_end(b, ns, n)
            if ne == ns or ns == before or n_attrs == MAX_ATTRS:
                return SCAN_UNSUPPORTED, i
            for k in range(n_attrs):
                if _same(b, attrs[k, 0], attrs[k, 1], ns, ne):  # a duplicate attribute
                    return SCAN_UNSUPPORTED, i
            attrs[n_attrs, 0] = ns
            attrs[n_attrs, 1] = ne
            n_attrs += 1
            j = ne
            while j < n and _is_space(b[j]):
                j += 1
            if j >= n or b[j] != 61:  # '='
                return SCAN_UNSUPPORTED, i
            j += 1
            while j < n and _is_space(b[j]):
                j += 1
            if j >= n or (b[j] != 34 and b[j] != 39):
                return SCAN_UNSUPPORTED, i
            q = b[j]
            vs = j + 1
            j = vs
            spaced = False  # a tab or line break: the value XML gives differs from the bytes
            while j < n:
                v = _VALUE_CLASS[b[j]]
                if v != 0:
                    if b[j] == q:
                        break
                    if v == 2:
                        return SCAN_UNSUPPORTED, i
                    spaced |= v == 3
                j += 1
            if j >= n or (spaced and kind != _OTHER and kind != _KEY):  # (keys are read by expat)
                return SCAN_UNSUPPORTED, i
            ve = j
            j += 1
            if kind == _NODE or kind == _DATA or kind == _EDGE:
                an = _pack(b, ns, ne, False)
                if (kind == _NODE and an == W_ID) or (kind == _DATA and an == W_KEY):
                    a_val_s = vs
                    a_val_e = ve
                elif kind == _EDGE:
                    if an == W_SOURCE:
                        a_src_s = vs
                        a_src_e = ve
                    elif an == W_TARGET:
                        a_dst_s = vs
                        a_dst_e = ve
                    elif an == W_DIRECTED:
                        a_dir_s = vs
                        a_dir_e = ve
            elif kind == _GRAPH and _is_word(b, ns, ne, _EDGEDEFAULT):
                a_val_s = vs
                a_val_e = ve
        empty = b[j] == 47
        if empty:
            j += 1
            if j >= n or b[j] != 62:
                return SCAN_UNSUPPORTED, i
        tag_end = j + 1
        if depth == 0:
            roots += 1
            if roots > 1:
                return SCAN_UNSUPPORTED, i
        if not empty and kind != _DATA:  # <data> reads its own end tag below
            if depth == MAX_DEPTH - 1:
                return SCAN_UNSUPPORTED, i
            stack[depth, 0] = s
            stack[depth, 1] = e
            depth += 1
        if in_key >= 0:  # <default> and friends inside a <key>: the key element is read in Python
            if kind != _OTHER:
                return SCAN_UNSUPPORTED, i
            i = tag_end
            continue
        if kind == _NODE:
            if a_val_s < 0 or cur_kind >= 0 or n_nodes + 1 >= node_off.shape[0]:
                return SCAN_UNSUPPORTED, i
            if 2 * (n_nodes + 1) > node_tab.shape[0]:
                return SCAN_GROW, i
            idx = _intern_node(b, a_val_s, a_val_e, node_tab, node_off, pool, n_nodes)
            if idx == n_nodes:
                n_nodes += 1
            if not empty:
                cur_kind = 0
                cur_elem = idx
        elif kind == _EDGE:
            if a_src_s < 0 or a_dst_s < 0 or cur_kind >= 0 or n_edges == edges.shape[0] \
                    or n_nodes + 3 > node_off.shape[0]:
                return SCAN_UNSUPPORTED, i
            if 2 * (n_nodes + 2) > node_tab.shape[0]:
                return SCAN_GROW, i
            src = _intern_node(b, a_src_s, a_src_e, node_tab, node_off, pool, n_nodes)
            if src == n_nodes:
                n_nodes += 1
            dst = _intern_node(b, a_dst_s, a_dst_e, node_tab, node_off, pool, n_nodes)
            if dst == n_nodes:
                n_nodes += 1
            edges[n_edges, E_SRC] = src
            edges[n_edges, E_DST] = dst
            directed = -1
            if a_dir_s >= 0:
                dv = _pack(b, a_dir_s, a_dir_e, False)
                if dv == W_FALSE:
                    directed = 0
                elif dv == W_TRUE:
                    directed = 1
                else:
                    return SCAN_UNSUPPORTED, i
            edges[n_edges, E_DIRECTED] = directed
            if not empty:
                cur_kind = 1
                cur_elem = n_edges
            n_edges += 1
        elif kind == _DATA:
            if a_val_s < 0:
                return SCAN_UNSUPPORTED, i
            ts = tag_end
            te = tag_end
            if not empty:  # the text up to </data>, which must come next
                while te < n:
                    t = _TEXT_CLASS[b[te]]
                    if t != 0:
                        if t == 1:
                            break
                        if t == 2 or (te + 2 < n and b[te + 1] == 93 and b[te + 2] == 62):
                            return SCAN_UNSUPPORTED, i
                    te += 1
                if te + 1 >= n or b[te + 1] != 47:
                    return SCAN_UNSUPPORTED, i
                e2 = _name_end(b, te + 2, n)
                if not _same(b, te + 2, e2, s, e):  # </data> with the same (prefixed) name
                    return SCAN_UNSUPPORTED, i
                tag_end = _end_tag_end(b, e2, n)
                if tag_end < 0:
                    return SCAN_UNSUPPORTED, i
            if cur_kind >= 0:  # data of the graph or the document itself is not a fact
                if n_data == data.shape[0] or n_keys == key_spans.shape[0] or 2 * (n_keys + 1) > key_tab.shape[0]:
                    return SCAN_UNSUPPORTED, i
                kid = _intern(b, a_val_s, a_val_e, key_tab, key_spans, n_keys)
                if kid == n_keys:
                    n_keys += 1
                data[n_data, D_KIND] = cur_kind
                data[n_data, D_ELEM] = cur_elem
                data[n_data, D_KEY] = kid
                data[n_data, D_START] = ts
                data[n_data, D_END] = te
                data[n_data, D_POS] = i
                n_data += 1
        elif kind == _KEY:
            if empty:
                if n_key_elems == key_elems.shape[0]:
                    return SCAN_UNSUPPORTED, i
                key_elems[n_key_elems, 0] = i
                key_elems[n_key_elems, 1] = tag_end
                n_key_elems += 1
            else:
                in_key = i
                stack[MAX_DEPTH - 1, 0] = depth - 1  # the depth its end tag brings back
        elif kind == _GRAPH:
            if graph_tag[G_TAG] >= 0:  # a second (or nested) graph
                return SCAN_UNSUPPORTED, i
            graph_tag[G_TAG] = i
            graph_tag[G_EDGEDEFAULT_S] = a_val_s
            graph_tag[G_EDGEDEFAULT_E] = a_val_e
        i = tag_end
    counts[C_NODES] = n_nodes
    counts[C_EDGES] = n_edges
    counts[C_DATA] = n_data
    counts[C_KEYS] = n_keys
    counts[C_KEY_ELEMS] = n_key_elems
    if cur_kind >= 0 or in_key >= 0 or depth != 0 or roots != 1:
        return SCAN_UNSUPPORTED, n
    return SCAN_OK, 0


@scan_jit
def data_values(b, data, numbers, booleans):
    """Each data value as a number (NaN if not one) and a boolean (1 true, 0 false, -1 neither;
    case-insensitive, "1" / "0" too, spaces around; BOOLEAN_UNKNOWN for a value with non-ASCII bytes,
    where str.strip() finds other spaces than XML's)."""
    for k in range(data.shape[0]):
        s = data[k, D_START]
        e = data[k, D_END]
        numbers[k] = parse_number(b, s, e)
        while s < e and _is_space(b[s]):
            s += 1
        while e > s and _is_space(b[e - 1]):
            e -= 1
        w = _pack(b, s, e, True)
        booleans[k] = 1 if w == W_TRUE or w == W_ONE else 0 if w == W_FALSE or w == W_ZERO else -1
        if booleans[k] < 0:
            for x in range(s, e):
                if b[x] >= 128:
                    booleans[k] = BOOLEAN_UNKNOWN
                    break


def scan_graphml(b: np.ndarray, start: int = 0) -> tuple[int, dict[str, np.ndarray]]:
    """Scan bytes `b` (uint8) from offset `start`: (status, arrays: node_off and pool (node id i is
    pool[off[i]:off[i+1]]), edges, data, key_spans, key_elems, graph_tag, numbers, booleans), buffers sized
    from a counting pass (np.empty pages that are never written cost no memory)."""
    if first_bad_char(b) >= 0:
        return SCAN_UNSUPPORTED, {}
    c_node, c_edge, c_data, c_key = count_starts(b)
    max_nodes = c_node + 2 * c_edge + 1
    node_off = np.empty(max_nodes + 1, np.int64)
    node_off[0] = 0
    pool = np.empty(len(b), np.uint8)
    edges = np.empty((c_edge, 3), np.int64)
    data = np.empty((c_data, N_DCOLS), np.int64)
    key_spans = np.empty((c_data + 1, 2), np.int64)
    key_elems = np.empty((c_key + 1, 2), np.int64)
    stack = np.empty((MAX_DEPTH, 2), np.int64)
    attrs = np.empty((MAX_ATTRS, 2), np.int64)
    graph_tag = np.empty(3, np.int64)
    counts = np.zeros(5, np.int64)
    # a table for 4x the declared nodes; edges to undeclared nodes may need a larger one (scan again)
    size = 1 << int(4 * c_node + 64).bit_length()
    while True:
        node_tab = np.zeros((size, 2), np.int64)
        key_tab = np.full(1 << int(2 * c_key + 64).bit_length(), -1, np.int64)
        status, _ = scan(b, start, node_tab, node_off, pool, edges, data, key_tab, key_spans, key_elems, stack,
                         attrs, graph_tag, counts)
        if status != SCAN_GROW:
            break
        size *= 4
    del node_tab, key_tab
    if status != SCAN_OK:
        return status, {}
    data = data[:counts[C_DATA]]
    numbers = np.empty(len(data), np.float64)
    booleans = np.empty(len(data), np.int8)
    data_values(b, data, numbers, booleans)
    n_nodes = int(counts[C_NODES])
    return status, {"node_off": node_off[:n_nodes + 1], "pool": pool[:node_off[n_nodes]].copy(),
                    "edges": edges[:counts[C_EDGES]], "data": data, "key_spans": key_spans[:counts[C_KEYS]],
                    "key_elems": key_elems[:counts[C_KEY_ELEMS]], "graph_tag": graph_tag, "numbers": numbers,
                    "booleans": booleans}
