"""A compiled scanner for the plain GraphML that graph tools write: one pass over the bytes finds nodes,
edges and their <data> values, interns node ids and key ids in hash tables and parses numbers and
booleans, so that a million-edge file costs well under a second, not a Python call per element.

It reads a subset of XML and says when a file leaves it (status SCAN_UNSUPPORTED and the byte offset):
a DOCTYPE or CDATA section, an entity or character reference (`&`) inside a tag or a value, elements
inside <data>, a <node> without an id, an <edge> without source or target, mismatched tags. The caller
then reads the file with the complete (slower) expat reader, which also gives the located errors and
refuses entity declarations. Within the subset there is nothing to expand, so nothing hostile to do.
"""
from __future__ import annotations

import numpy as np
from numba import njit

SCAN_OK, SCAN_UNSUPPORTED = 0, 1
# elements the scanner knows
_OTHER, _NODE, _EDGE, _DATA, _KEY, _GRAPH = 0, 1, 2, 3, 4, 5
# per data value: (kind 0 node / 1 edge, element index, key index, text start, text end, tag offset)
D_KIND, D_ELEM, D_KEY, D_START, D_END, D_POS = 0, 1, 2, 3, 4, 5
N_DCOLS = 6
# per edge: (source, target, directed: -1 graph default / 0 undirected / 1 directed)
E_SRC, E_DST, E_DIRECTED = 0, 1, 2

scan_jit = njit(cache=True)
_POW10 = np.array([float(f"1e{k}") for k in range(23)])  # exact doubles


@scan_jit
def _hash(b, s, e):
    h = np.uint64(14695981039346656037)
    for i in range(s, e):
        h = (h ^ np.uint64(b[i])) * np.uint64(1099511628211)
    return h


@scan_jit
def _same(b, s1, e1, s2, e2):
    if e1 - s1 != e2 - s2:
        return False
    for k in range(e1 - s1):
        if b[s1 + k] != b[s2 + k]:
            return False
    return True


@scan_jit
def _rehash(b, spans, n, size):
    table = np.full(size, -1, np.int64)
    mask = np.uint64(size - 1)
    for i in range(n):
        j = _hash(b, spans[i, 0], spans[i, 1]) & mask
        while table[j] >= 0:
            j = (j + np.uint64(1)) & mask
        table[j] = i
    return table


@scan_jit
def _intern(b, s, e, table, spans, n):
    """Index of the byte string b[s:e] among spans[:n] (added when new). Returns (index, table, spans,
    n): the arrays are replaced when they grow."""
    size = table.shape[0]
    if 2 * (n + 1) > size:
        table = _rehash(b, spans, n, 2 * size)
        size = 2 * size
    mask = np.uint64(size - 1)
    j = _hash(b, s, e) & mask
    while True:
        k = table[j]
        if k < 0:
            break
        if _same(b, spans[k, 0], spans[k, 1], s, e):
            return k, table, spans, n
        j = (j + np.uint64(1)) & mask
    if n == spans.shape[0]:
        grown = np.empty((2 * n, 2), np.int64)
        grown[:n] = spans[:n]
        spans = grown
    spans[n, 0] = s
    spans[n, 1] = e
    table[j] = n
    return n, table, spans, n + 1


@scan_jit
def _is_space(c):
    return c == 32 or c == 9 or c == 10 or c == 13


@scan_jit
def _find(b, i, pat):
    """Offset of pattern bytes `pat` at or after i, or -1."""
    n, m = b.shape[0], pat.shape[0]
    while i + m <= n:
        ok = True
        for k in range(m):
            if b[i + k] != pat[k]:
                ok = False
                break
        if ok:
            return i
        i += 1
    return -1


@scan_jit
def _name_is(b, s, e, word):
    """Is b[s:e], without a namespace prefix, equal to `word`?"""
    for k in range(e - 1, s - 1, -1):
        if b[k] == 58:  # ':'
            s = k + 1
            break
    return _same_bytes(b, s, e, word)


@scan_jit
def _same_bytes(b, s, e, word):
    if e - s != word.shape[0]:
        return False
    for k in range(e - s):
        if b[s + k] != word[k]:
            return False
    return True


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


@scan_jit
def scan(b, w_node, w_edge, w_data, w_key, w_graph, w_id, w_source, w_target, w_directed, w_false, w_true,
         w_comment_end, w_pi_end):
    """Scan GraphML bytes `b`. Returns (status, offset, node spans [N,2], edges [E,3], data [D,6],
    key-id spans [K,2], key element spans [k,2], graph start tag span [2])."""
    n = b.shape[0]
    node_tab = np.full(1024, -1, np.int64)
    node_spans = np.empty((512, 2), np.int64)
    n_nodes = 0
    key_tab = np.full(64, -1, np.int64)
    key_spans = np.empty((32, 2), np.int64)
    n_keys = 0
    edges = np.empty((1024, 3), np.int64)
    n_edges = 0
    data = np.empty((1024, N_DCOLS), np.int64)
    n_data = 0
    key_elems = np.empty((16, 2), np.int64)
    n_key_elems = 0
    graph_tag = np.full(2, -1, np.int64)
    cur_kind = -1  # the open node (0) or edge (1), -1 none
    cur_elem = -1
    in_key = -1  # start offset of an open <key> element
    stack = np.empty((64, 2), np.int64)  # name spans of the open elements: every end tag must match
    depth = 0
    roots = 0
    i = 0
    while i < n:
        if b[i] != 60:  # '<'
            i += 1
            continue
        if i + 1 >= n:
            return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
        c = b[i + 1]
        if c == 63:  # '<?' processing instruction / XML declaration
            j = _find(b, i + 2, w_pi_end)
            if j < 0:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            i = j + 2
            continue
        if c == 33:  # '<!'
            if i + 3 < n and b[i + 2] == 45 and b[i + 3] == 45:  # comment
                j = _find(b, i + 4, w_comment_end)
                if j < 0:
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                i = j + 3
                continue
            return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
        closing = c == 47  # '</'
        s = i + 2 if closing else i + 1
        e = s
        while e < n and not _is_space(b[e]) and b[e] != 62 and b[e] != 47:
            e += 1
        if _name_is(b, s, e, w_node):
            kind = _NODE
        elif _name_is(b, s, e, w_edge):
            kind = _EDGE
        elif _name_is(b, s, e, w_data):
            kind = _DATA
        elif _name_is(b, s, e, w_key):
            kind = _KEY
        elif _name_is(b, s, e, w_graph):
            kind = _GRAPH
        else:
            kind = _OTHER
        # attributes up to '>' (values may not hold '<', '>' or '&' in the subset)
        j = e
        a_id_s = -1
        a_id_e = -1
        a_src_s = -1
        a_src_e = -1
        a_dst_s = -1
        a_dst_e = -1
        a_dir_s = -1
        a_dir_e = -1
        while True:
            while j < n and _is_space(b[j]):
                j += 1
            if j >= n:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            if b[j] == 62 or b[j] == 47:
                break
            ns = j
            while j < n and b[j] != 61 and not _is_space(b[j]) and b[j] != 62:  # '='
                j += 1
            ne = j
            while j < n and _is_space(b[j]):
                j += 1
            if j >= n or b[j] != 61:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            j += 1
            while j < n and _is_space(b[j]):
                j += 1
            if j >= n or (b[j] != 34 and b[j] != 39):
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            q = b[j]
            vs = j + 1
            j = vs
            while j < n and b[j] != q:
                if b[j] == 60 or b[j] == 38 or b[j] == 62:  # '<', '&', '>'
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                j += 1
            if j >= n:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            ve = j
            j += 1
            if kind == _NODE or kind == _DATA:
                if _same_bytes(b, ns, ne, w_id if kind == _NODE else w_key):
                    a_id_s = vs
                    a_id_e = ve
            elif kind == _EDGE:
                if _same_bytes(b, ns, ne, w_source):
                    a_src_s = vs
                    a_src_e = ve
                elif _same_bytes(b, ns, ne, w_target):
                    a_dst_s = vs
                    a_dst_e = ve
                elif _same_bytes(b, ns, ne, w_directed):
                    a_dir_s = vs
                    a_dir_e = ve
        empty = b[j] == 47
        if empty:
            j += 1
            if j >= n or b[j] != 62 or closing:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
        tag_end = j + 1
        if closing:
            if depth == 0 or not _same(b, stack[depth - 1, 0], stack[depth - 1, 1], s, e):
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            depth -= 1
        else:
            if depth == 0:
                roots += 1
                if roots > 1:
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            if not empty and kind != _DATA:  # <data> reads its own end tag below
                if depth == stack.shape[0]:
                    grown = np.empty((2 * depth, 2), np.int64)
                    grown[:depth] = stack[:depth]
                    stack = grown
                stack[depth, 0] = s
                stack[depth, 1] = e
                depth += 1
        if closing:
            if kind == _NODE or kind == _EDGE:
                if cur_kind != kind - 1:
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                cur_kind = -1
            elif kind == _KEY:
                if in_key < 0:
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                if n_key_elems == key_elems.shape[0]:
                    grown = np.empty((2 * n_key_elems, 2), np.int64)
                    grown[:n_key_elems] = key_elems[:n_key_elems]
                    key_elems = grown
                key_elems[n_key_elems, 0] = in_key
                key_elems[n_key_elems, 1] = tag_end
                n_key_elems += 1
                in_key = -1
            elif kind == _DATA:  # a </data> not closing the text we took: elements inside <data>
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            i = tag_end
            continue
        if in_key >= 0:  # <default> and friends inside a <key>: the key element is read in Python
            i = tag_end
            continue
        if kind == _NODE:
            if a_id_s < 0 or cur_kind >= 0:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            idx, node_tab, node_spans, n_nodes = _intern(b, a_id_s, a_id_e, node_tab, node_spans, n_nodes)
            if not empty:
                cur_kind = 0
                cur_elem = idx
        elif kind == _EDGE:
            if a_src_s < 0 or a_dst_s < 0 or cur_kind >= 0:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            if n_edges == edges.shape[0]:
                grown = np.empty((2 * n_edges, 3), np.int64)
                grown[:n_edges] = edges[:n_edges]
                edges = grown
            src, node_tab, node_spans, n_nodes = _intern(b, a_src_s, a_src_e, node_tab, node_spans, n_nodes)
            dst, node_tab, node_spans, n_nodes = _intern(b, a_dst_s, a_dst_e, node_tab, node_spans, n_nodes)
            edges[n_edges, E_SRC] = src
            edges[n_edges, E_DST] = dst
            directed = -1
            if a_dir_s >= 0:
                if _same_bytes(b, a_dir_s, a_dir_e, w_false):
                    directed = 0
                elif _same_bytes(b, a_dir_s, a_dir_e, w_true):
                    directed = 1
                else:
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            edges[n_edges, E_DIRECTED] = directed
            if not empty:
                cur_kind = 1
                cur_elem = n_edges
            n_edges += 1
        elif kind == _DATA:
            if a_id_s < 0:
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            ts = tag_end
            te = tag_end
            if not empty:  # the text up to </data>, which must come next
                te = ts
                while te < n and b[te] != 60:
                    if b[te] == 38:  # '&'
                        return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                    te += 1
                if te + 1 >= n or b[te + 1] != 47:
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                k = te + 2
                e2 = k
                while e2 < n and b[e2] != 62 and not _is_space(b[e2]):
                    e2 += 1
                if not _same(b, k, e2, s, e):  # </data> with the same (prefixed) name
                    return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
                while e2 < n and b[e2] != 62:
                    e2 += 1
                tag_end = e2 + 1
            if cur_kind >= 0:  # data of the graph or the document itself is not a fact
                if n_data == data.shape[0]:
                    grown = np.empty((2 * n_data, N_DCOLS), np.int64)
                    grown[:n_data] = data[:n_data]
                    data = grown
                kid, key_tab, key_spans, n_keys = _intern(b, a_id_s, a_id_e, key_tab, key_spans, n_keys)
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
                    grown = np.empty((2 * n_key_elems, 2), np.int64)
                    grown[:n_key_elems] = key_elems[:n_key_elems]
                    key_elems = grown
                key_elems[n_key_elems, 0] = i
                key_elems[n_key_elems, 1] = tag_end
                n_key_elems += 1
            else:
                in_key = i
        elif kind == _GRAPH:
            if graph_tag[0] >= 0:  # a second (or nested) graph
                return SCAN_UNSUPPORTED, i, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
            graph_tag[0] = i
            graph_tag[1] = tag_end
        i = tag_end
    if cur_kind >= 0 or in_key >= 0 or depth != 0 or roots != 1:
        return SCAN_UNSUPPORTED, n, node_spans[:0], edges[:0], data[:0], key_spans[:0], key_elems[:0], graph_tag
    return (SCAN_OK, 0, node_spans[:n_nodes], edges[:n_edges], data[:n_data], key_spans[:n_keys],
            key_elems[:n_key_elems], graph_tag)


@scan_jit
def data_numbers(b, data):
    """Each data value parsed as a number (NaN if it is not one)."""
    out = np.empty(data.shape[0], np.float64)
    for k in range(data.shape[0]):
        out[k] = parse_number(b, data[k, D_START], data[k, D_END])
    return out


@scan_jit
def data_booleans(b, data, w_true, w_false, w_one, w_zero):
    """Each data value as a boolean: 1 true, 0 false, -1 neither (case-insensitive, spaces around)."""
    out = np.empty(data.shape[0], np.int8)
    for k in range(data.shape[0]):
        s = data[k, D_START]
        e = data[k, D_END]
        while s < e and _is_space(b[s]):
            s += 1
        while e > s and _is_space(b[e - 1]):
            e -= 1
        v = -1
        if _lower_is(b, s, e, w_true) or _same_bytes(b, s, e, w_one):
            v = 1
        elif _lower_is(b, s, e, w_false) or _same_bytes(b, s, e, w_zero):
            v = 0
        out[k] = v
    return out


@scan_jit
def _lower_is(b, s, e, word):
    if e - s != word.shape[0]:
        return False
    for k in range(e - s):
        c = b[s + k]
        if 65 <= c <= 90:
            c += 32
        if c != word[k]:
            return False
    return True


def words() -> tuple[np.ndarray, ...]:
    """The byte strings `scan` compares against, as uint8 arrays (its last 13 arguments)."""
    return tuple(np.frombuffer(w, np.uint8) for w in (b"node", b"edge", b"data", b"key", b"graph", b"id",
                                                        b"source", b"target", b"directed", b"false",
                                                        b"true", b"-->", b"?>"))
