"""Precedence graphs as GraphML and Graphviz DOT files, in and out, and as NetworkX graphs.

A graph is a plan: each node a part (its id; ``label`` or ``name`` data its name; ``quantity``,
``install`` and ``acquire`` data as in a plan file), each edge ``a -> b`` "a before b".  Several
``<graph>`` elements of a GraphML file (or several ``digraph`` blocks... not in DOT: one per file)
are several strategies over the same parts.  What is read goes through the same checks as a plan
file (:func:`~opportune.formats.validate.check_document`), with every problem placed on the line of
the file that caused it.

Bounds, each checked while the file is read (streamed: tokens and XML events, nothing built ahead),
each refusal with its line: the file size of :func:`~opportune.formats.loader.read_plan`; at most
:data:`~opportune.formats.graphs.MAX_TASKS` nodes and :data:`~opportune.formats.graphs.MAX_PAIRS`
edges; :data:`MAX_TOKENS` DOT tokens; :data:`MAX_ELEMENTS` GraphML elements nested at most
:data:`~opportune.formats.loader.MAX_DEPTH` deep, :data:`~opportune.planning.plan.MAX_STRATEGIES` graphs, and
data of at most :data:`~opportune.formats.validate.MAX_TEXT` characters; no DTD or entity in GraphML
(refused: they are how XML bombs work); then the plan limits of :mod:`opportune.planning.plan`.

>>> from opportune import make_plan
>>> plan = make_plan(["a", "b", "c"], {"c": ["a", "b"]})
>>> check_dot_bytes(to_dot_precedence(plan).encode()).plan.strategies[0].requires["c"]
('a', 'b')
>>> check_graphml_bytes(to_graphml(plan).encode()).plan.part_ids
('a', 'b', 'c')
"""

from __future__ import annotations

import re
from collections import deque
from xml.parsers import expat
from xml.sax.saxutils import escape, quoteattr

from opportune.formats.graphs import MAX_PAIRS, MAX_TASKS, file_stem
from opportune.formats.documents import MAX_DEPTH, CheckResult, Document
from opportune.formats.problems import Problem
from opportune.formats.validate import MAX_TEXT
from opportune.planning.plan import MAX_STRATEGIES

__all__ = ["check_dot_bytes", "check_graphml_bytes", "plan_from_networkx", "plan_to_networkx",
           "to_dot_precedence", "to_graphml"]

_NUMERIC = ("quantity", "install", "acquire")
# Bounds besides the nodes (MAX_TASKS) and edges (MAX_PAIRS) of opportune.formats.graphs, each
# keeping the largest file accepted read within a few seconds and a few times its size in memory.
MAX_TOKENS = 16 * MAX_TASKS + 4 * MAX_PAIRS   # DOT tokens: a node with its attributes, an edge statement
# GraphML elements: 64 strategies that each list all 10,000 parts, and 120,000 edges, are 760,000.
# (It was 1,000,000: a file of a million elements took 4 to 5 s of CPU time to read and check on a
# busy machine, with Python's calls per element the most of it; 800,000 take about 3.5 s.)
MAX_ELEMENTS = 800_000


class _Bad(Exception):
    def __init__(self, message: str, hint: str, line: int | None, code: str = "syntax"):
        super().__init__(message)
        self.problem = (message, hint, line)
        self.code = code


def _build(name: str, source: str, nodes: dict[str, dict], node_lines: dict[str, int],
           graphs: list[tuple[str, list[tuple[str, str, int]]]], file: str | None) -> CheckResult:
    """The plan document of parsed nodes and edges, checked like a plan file, problems on file lines."""
    from opportune.formats.validate import check_document

    lines: dict[tuple, int] = {}
    parts = []
    for i, (pid, attrs) in enumerate(nodes.items()):
        entry: dict = {"id": pid}
        for key in ("name", *_NUMERIC):
            if key in attrs:
                entry[key] = attrs[key]
        parts.append(entry if len(entry) > 1 else pid)
        lines[("parts", i)] = node_lines.get(pid, 1)
    data: dict = {"name": name, "source": source, "parts": parts}

    def requires_of(edges, prefix):
        req: dict[str, list[str]] = {}
        for a, b, line in edges:
            req.setdefault(b, []).append(a)
            lines[(*prefix, b, len(req[b]) - 1)] = line
            lines.setdefault((*prefix, b), line)
        return req

    if len(graphs) == 1:
        data["requires"] = requires_of(graphs[0][1], ("requires",))
    else:
        data["strategies"] = [{"name": gname, "requires": requires_of(edges, ("strategies", k, "requires"))}
                              for k, (gname, edges) in enumerate(graphs)]
    return check_document(Document(data, lines, file))


def _number(text: str, what: str, line: int):
    try:
        value = float(text)
    except ValueError:
        raise _Bad(f"{what} is {text[:40]!r}, not a number", "write a number", line) from None
    return int(value) if value.is_integer() and what.endswith("quantity") else value


def _node_data(part) -> list[tuple[str, str]]:
    """A part's data as a file writes it: its name (if it has one besides its id), a quantity other
    than 1, costs other than the defaults."""
    out = []
    if part.name and part.name != part.id:
        out.append(("name", part.name))
    if part.quantity != 1:
        out.append(("quantity", str(part.quantity)))
    for key in ("install", "acquire"):
        value = _given(part, key)
        if value is not None:
            out.append((key, f"{value:g}"))
    return out


def _covers(plan, k: int) -> list[tuple[str, str]]:
    """The cover relations of strategy ``k`` as part-id pairs: the fewest edges that give its order.
    O(constraints) (:func:`~opportune.planning.orders.strategy_summaries`, computed once per plan)."""
    from opportune.planning.orders import strategy_summaries

    ids = plan.part_ids
    return [(ids[a], ids[b]) for a, b in strategy_summaries(plan)[k][0]]


def _given(part, key: str):
    """A part's cost as the plan gives it (None when it is the default, so files stay short)."""
    value = getattr(part, key)
    default = type(part).__dataclass_fields__[key].default
    return None if value is None or value == default else value


# ---------------------------------------------------------------- GraphML

#: The encodings a GraphML file may declare: those expat reads itself (any other name would be handed to
#: Python's codecs, which include rot13, base64 and zlib).
_XML_ENCODINGS = frozenset({"utf-8", "utf8", "us-ascii", "ascii", "iso-8859-1", "latin-1", "latin1", "utf-16"})
_XML_ENCODING = re.compile(rb'^(?:\xef\xbb\xbf)?<\?xml[^>]*?\bencoding\s*=\s*["\']([A-Za-z0-9._-]{1,64})["\']')

def check_graphml_bytes(raw: bytes, *, file: str | None = None) -> CheckResult:
    """Read a GraphML file as a plan (one strategy per ``<graph>``), checked like any plan.

    Parameters
    ----------
    raw : bytes
        The file's bytes (UTF-8, US-ASCII, ISO-8859-1 or UTF-16, as its XML declaration says).
    file : str, optional
        The name problems are reported under.

    Returns
    -------
    CheckResult
        The plan (``None`` if unusable) and every problem found, with its line.

    Examples
    --------
    >>> from opportune import make_plan
    >>> result = check_graphml_bytes(to_graphml(make_plan(["a", "b"], {"b": ["a"]}, name="two")).encode())
    >>> result.plan.name, result.plan.strategies[0].pairs()
    ('two', [('a', 'b')])
    """
    declared = _XML_ENCODING.match(raw[:200])
    if declared and declared.group(1).decode("ascii").lower().replace("_", "-") not in _XML_ENCODINGS:
        name = declared.group(1).decode("ascii")[:40]
        return CheckResult(None, [Problem(f"the XML declaration names the encoding {name!r}; GraphML files are read "
                                          "in UTF-8 (or US-ASCII, ISO-8859-1, UTF-16)",
                                          'write the file as UTF-8 (encoding="UTF-8")', file=file, line=1,
                                          code="syntax")])
    parser = expat.ParserCreate()
    found = _GraphMLFound()
    characters = _graphml_characters(parser, found)
    parser.StartElementHandler = _graphml_start(parser, found, characters)
    parser.EndElementHandler = _graphml_end(parser, found)
    parser.buffer_text = True  # one call per run of text, not one per line of it
    parser.StartDoctypeDeclHandler = parser.EntityDeclHandler = _refuse_dtd(parser)
    try:
        parser.Parse(raw, True)
    except _Bad as exc:
        return CheckResult(None, [Problem(*exc.problem[:2], file=file, line=exc.problem[2], code=exc.code)])
    except (LookupError, ValueError, UnicodeError) as exc:    # an encoding the codecs refuse midway
        return CheckResult(None, [Problem(f"the file cannot be decoded: {ascii(str(exc))[1:-1][:200]}",
                                          'write the file as UTF-8 (encoding="UTF-8")', file=file,
                                          line=parser.CurrentLineNumber, code="syntax")])
    except expat.ExpatError as exc:
        return CheckResult(None, [Problem(f"XML syntax error: {expat.ErrorString(exc.code)}",
                                          "fix the XML at this line", file=file, line=exc.lineno, code="syntax")])
    graphs, nodes, node_lines = found.graphs, found.nodes, found.node_lines
    if not graphs:
        return CheckResult(None, [Problem("no <graph> element", "a GraphML file holds its nodes and edges in a "
                                          "<graph edgedefault=\"directed\">", file=file, line=1, code="syntax")])
    for _, edges in graphs:
        for a, b, line in edges:     # an edge may name a node declared nowhere: it is a part too
            for pid in (a, b):
                if pid not in nodes:
                    nodes[pid] = {}
                    node_lines[pid] = line
    name = found.plan_name[0] or (file_stem(file) if file else "graphml")
    return _build(name, "GraphML precedence graph", nodes, node_lines, graphs, file)


# The handlers run once per element (a million at most; Python's calls alone cost 1 µs per
# element): closures over the reader's containers, not methods (an attribute read per use made them
# 5 to 25% slower); the common elements (node, edge) are tested first, the stack holds tags only, the line
# is asked for only where it is kept, and text is collected only inside a node's <data> (the
# handler is set there and removed after: whitespace between elements would cost a call each).

class _GraphMLFound:
    """What :func:`check_graphml_bytes`' handlers gather and share as they read."""

    def __init__(self):
        self.keys: dict[str, str] = {}          # key id -> attribute name
        self.nodes: dict[str, dict] = {}
        self.node_lines: dict[str, int] = {}
        self.graphs: list[tuple[str, list[tuple[str, str, int]]]] = []
        self.stack: list[str] = []              # the tags of the open elements
        self.text: list[str] = []
        self.node_ids: list = []     # the ids of the open <node> elements (a node may hold a graph of nodes)
        self.data_key: list = [None]   # the key of the node's <data> being read
        self.plan_name: list = [""]    # a <data> of the <graphml> element keyed "name": the plan's name
        self.collecting: list = []     # inside a <data> of a node: its text is kept (and only there)


def _refuse_dtd(parser):
    def refuse_dtd(*_args):
        raise _Bad("the file declares a DTD or entities", "remove the <!DOCTYPE ...> and <!ENTITY ...> "
                   "declarations: GraphML needs none", parser.CurrentLineNumber)

    return refuse_dtd


def _graphml_start(parser, found: _GraphMLFound, characters):
    """The handler of an element's start: bounds checked, nodes, edges, keys and graphs gathered into
    ``found``; inside a node's ``<data>``, ``characters`` collects the text."""
    keys, nodes, node_lines, graphs = found.keys, found.nodes, found.node_lines, found.graphs
    stack, text, node_ids, data_key, collecting = found.stack, found.text, found.node_ids, found.data_key, \
        found.collecting
    ids: set[str] = set()  # every node id met, declared or named by an edge
    elements = 0
    edge_count = 0

    def named(pid, line):
        if pid not in ids:
            if len(ids) >= MAX_TASKS:
                raise _Bad(f"more than {MAX_TASKS:,} nodes; graph files of at most {MAX_TASKS:,} are read "
                           "(a plan holds at most 10,000 parts)", "split the graph into smaller ones", line, "limit")
            ids.add(pid)

    def start(tag, attrs):
        nonlocal elements, edge_count
        elements += 1
        if elements > MAX_ELEMENTS:
            raise _Bad(f"more than {MAX_ELEMENTS:,} elements; GraphML files of at most {MAX_ELEMENTS:,} are read",
                       "split the graph into smaller ones", parser.CurrentLineNumber, "limit")
        if len(stack) >= MAX_DEPTH:
            raise _Bad(f"elements nested more than {MAX_DEPTH} levels deep", "GraphML nests 4 levels: "
                       "graphml, graph, node, data", parser.CurrentLineNumber, "limit")
        if ":" in tag:
            tag = tag.rpartition(":")[2]
        stack.append(tag)
        if tag == "node":
            pid = attrs.get("id")
            if not pid:
                raise _Bad("a node has no id", "give every <node> an id attribute", parser.CurrentLineNumber)
            node_ids.append(pid)
            if pid not in nodes:
                line = parser.CurrentLineNumber
                named(pid, line)
                nodes[pid] = {}
                node_lines[pid] = line
        elif tag == "edge":
            line = parser.CurrentLineNumber
            a, b = attrs.get("source"), attrs.get("target")
            if not a or not b:
                raise _Bad("an edge lacks its source or target", "write <edge source=\"a\" target=\"b\"/>", line)
            if not graphs:
                raise _Bad("an edge outside any <graph>", "put edges inside a <graph> element", line)
            edge_count += 1
            if edge_count > MAX_PAIRS:
                raise _Bad(f"more than {MAX_PAIRS:,} <edge> elements; GraphML files of at most {MAX_PAIRS:,} are "
                           "read", "split the graph into smaller ones, or list only the covering edges (opportune "
                           "convert writes those)", line, "limit")
            for pid in (a, b):  # an edge may name a node declared nowhere: it is a node too (added at the end)
                if pid not in ids:
                    named(pid, line)
            graphs[-1][1].append((a, b, line))
        elif tag == "key":
            keys[attrs.get("id", "")] = attrs.get("attr.name", attrs.get("id", ""))
        elif tag == "graph":
            _graph_element(attrs, graphs, stack, parser.CurrentLineNumber)
        elif tag == "data":
            text.clear()
            collecting[:] = [len(stack) > 1 and stack[-2] in ("node", "graphml")]
            if collecting[0]:
                data_key[0] = attrs.get("key", "")
                parser.CharacterDataHandler = characters

    return start


def _graph_element(attrs, graphs: list, stack: list[str], line: int) -> None:
    """A ``<graph>``: a strategy (refused if undirected at the top, or past the strategies a plan holds)."""
    if attrs.get("edgedefault", "directed") != "directed" and "graph" not in stack[:-1]:
        raise _Bad("the graph is undirected", "a precedence graph is directed: edgedefault=\"directed\"", line)
    if len(graphs) >= MAX_STRATEGIES:
        raise _Bad(f"more than {MAX_STRATEGIES} <graph> elements; a plan holds at most {MAX_STRATEGIES} "
                   "strategies", "keep the strategies that add sequences", line, "limit")
    graphs.append((attrs.get("id") or f"strategy {len(graphs) + 1}", []))


def _graphml_end(parser, found: _GraphMLFound):
    """The handler of an element's end: a node's ``<data>`` becomes its name or a number; the
    ``<graphml>`` element's ``name`` data, the plan's name."""
    keys, nodes, stack, text = found.keys, found.nodes, found.stack, found.text
    node_ids, data_key, plan_name, collecting = found.node_ids, found.data_key, found.plan_name, found.collecting

    def end(_tag):
        tag = stack.pop()
        if tag != "data":
            if tag == "node":
                node_ids.pop()
            return
        collecting[:] = []
        parser.CharacterDataHandler = None
        if stack and stack[-1] == "node":
            key = keys.get(data_key[0], data_key[0])
            pid = node_ids[-1]
            value = "".join(text).strip()
            line = parser.CurrentLineNumber
            if key in ("label", "name"):
                nodes[pid]["name"] = value
            elif key in _NUMERIC:
                nodes[pid][key] = _number(value, f"node {pid}'s {key}", line)
        elif stack and stack[-1] == "graphml" and keys.get(data_key[0], data_key[0]) == "name":
            plan_name[0] = "".join(text).strip()    # the plan's name (as convert writes it)

    return end


def _graphml_characters(parser, found: _GraphMLFound):
    """The handler of text, set only inside a node's ``<data>``: kept, at most :data:`MAX_TEXT` characters."""
    text, collecting = found.text, found.collecting
    kept = [0]  # characters of the <data> being read

    def characters(data):
        if collecting and collecting[0]:
            kept[0] = kept[0] + len(data) if text else len(data)
            if kept[0] > MAX_TEXT:
                raise _Bad(f"a <data> value of more than {MAX_TEXT:,} characters; at most {MAX_TEXT:,} are read",
                           "shorten it: names and numbers are short", parser.CurrentLineNumber, "limit")
            text.append(data)

    return characters

def to_graphml(plan) -> str:
    """The plan as GraphML: one directed ``<graph>`` per strategy, its cover relations as edges.

    Parameters
    ----------
    plan : Plan
        The plan.

    Returns
    -------
    str
        The GraphML document (:func:`check_graphml_bytes` reads it back).

    Examples
    --------
    >>> from opportune import make_plan
    >>> print(to_graphml(make_plan(["a", "b"], {"b": ["a"]})).splitlines()[-3])
        <edge source="a" target="b"/>
    """
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<graphml xmlns="http://graphml.graphdrawing.org/xmlns">',
           '  <key id="name" for="node" attr.name="name" attr.type="string"/>',
           '  <key id="quantity" for="node" attr.name="quantity" attr.type="int"/>',
           '  <key id="install" for="node" attr.name="install" attr.type="double"/>',
           '  <key id="acquire" for="node" attr.name="acquire" attr.type="double"/>',
           '  <key id="plan" for="graphml" attr.name="name" attr.type="string"/>',
           f'  <data key="plan">{escape(plan.name)}</data>']
    for k, strategy in enumerate(plan.strategies):
        out.append(f"  <graph id={quoteattr(strategy.name)} edgedefault=\"directed\">")
        for part in plan.parts:
            data = "".join(f'<data key="{key}">{escape(value)}</data>' for key, value in _node_data(part))
            out.append(f"    <node id={quoteattr(part.id)}>{data}</node>" if data
                       else f"    <node id={quoteattr(part.id)}/>")
        for a, b in _covers(plan, k):
            out.append(f"    <edge source={quoteattr(a)} target={quoteattr(b)}/>")
        out.append("  </graph>")
    out.append("</graphml>")
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------- DOT

# Blanks before a token are matched with it (one match per token, not two).
_TOKEN = re.compile(r'''
    [ \t\r]*(?: (?P<newline>\n) |
    (?P<comment>//[^\n]*|\#[^\n]*|/\*.*?\*/) |
    (?P<string>"(?>[^"\\]++|\\.)*+") |
    (?P<arrow>->) | (?P<undirected>--) |
    (?P<punct>[{}\[\];,=:]) |
    (?P<id>[A-Za-z_\x80-\uffff][A-Za-z_0-9\x80-\uffff]*|-?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)) |
    (?P<other>.) | (?P<space>\Z))''', re.VERBOSE | re.DOTALL)


def _too_many_tokens(line: int) -> "_Bad":
    return _Bad(f"more than {MAX_TOKENS:,} tokens (names, arrows, brackets, separators); DOT files of at most "
                f"{MAX_TOKENS:,} are read ({MAX_TASKS:,} nodes and {MAX_PAIRS:,} edges at most)",
                "split the graph into smaller ones", line, "limit")


def _tokens(text: str):
    """The DOT tokens of ``text`` as ``(kind, value, line)``, one at a time, then ``("eof", "", last line)``.

    A generator: the parser holds two tokens at most, so memory stays that of the text.  Raises
    :class:`_Bad` past :data:`MAX_TOKENS` tokens (time is bounded too: a file of a million ``;`` adds
    no node or edge, the bounds of which are checked by the parser).
    """
    line, count, last = 1, 0, 1
    for m in _TOKEN.finditer(text):
        kind = m.lastgroup
        if kind == "id" or kind == "punct" or kind == "arrow":  # most tokens: the checks below do not apply
            count += 1
            if count > MAX_TOKENS:
                raise _too_many_tokens(line)
            last = line
            yield kind, m.group(kind), line
            continue
        if kind == "newline":
            line += 1
            continue
        if kind == "space":  # blanks at the end of the text
            continue
        value = m.group(kind)
        if kind == "comment":
            line += value.count("\n")
            continue
        if kind == "string":
            if len(value) > MAX_TEXT + 2:
                raise _Bad(f"a quoted string of {len(value) - 2:,} characters; at most {MAX_TEXT:,} are read",
                           "shorten it: ids and labels are short", line, "limit")
            value = re.sub(r'\\(.)', lambda s: s.group(1) if s.group(1) in '"\\' else "\\" + s.group(1), value[1:-1])
            kind = "id"
        if kind == "other":
            raise _Bad(f"unexpected character {value!r}", "check the DOT syntax here", line)
        if kind == "undirected":
            raise _Bad("an undirected edge '--'", "a precedence graph is a digraph: write a -> b", line)
        count += 1
        if count > MAX_TOKENS:
            raise _too_many_tokens(line)
        last = line
        yield kind, value, line
    yield "eof", "", last  # placed on the last token's line, where the missing text belongs


def check_dot_bytes(raw: bytes, *, file: str | None = None) -> CheckResult:
    """Read a Graphviz DOT digraph as a plan (edges ``a -> b -> c`` chain), checked like any plan.

    The subset read: ``[strict] digraph [ID] { ... }`` with node statements (attributes ``label``
    or ``name``, ``quantity``, ``install``, ``acquire``), edge chains with attributes, default
    attribute statements and ``ID = ID`` (ignored), and subgraph blocks (their contents read as if
    inline).  An edge to a subgraph is refused with its line.

    Parameters
    ----------
    raw : bytes
        The file's bytes (UTF-8).
    file : str, optional
        The name problems are reported under.

    Returns
    -------
    CheckResult
        The plan (``None`` if unusable) and every problem found, with its line.

    Examples
    --------
    >>> result = check_dot_bytes(b"digraph { a -> b -> c; }", file="chain.dot")
    >>> result.ok, result.plan.strategies[0].pairs()
    (True, [('a', 'b'), ('b', 'c')])
    """
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        from opportune.formats.documents import not_utf8

        return CheckResult(None, [not_utf8(raw, exc, file)])
    nodes: dict[str, dict] = {}
    node_lines: dict[str, int] = {}
    edges: list[tuple[str, str, int]] = []
    try:
        peek, take, ahead = _dot_lookahead(text)
        if peek()[1] == "strict":
            take()
        head = take("id")
        if head[1] == "graph":
            raise _Bad("an undirected graph", "a precedence graph is a digraph: write 'digraph NAME { a -> b; }'",
                       head[2])
        if head[1] != "digraph":
            raise _Bad(f"expected 'digraph' but found {head[1]!r}", "a DOT precedence graph starts with 'digraph'",
                       head[2])
        name = take("id")[1] if peek()[0] == "id" else (file_stem(file) if file else "dot")
        take(value="{")
        _dot_statements(peek, take, ahead, nodes, node_lines, edges)(0)
        take(value="}")
        if peek()[0] != "eof":
            raise _Bad("more after the digraph's closing '}'", "one digraph per file", peek()[2])
    except _Bad as exc:
        return CheckResult(None, [Problem(*exc.problem[:2], file=file, line=exc.problem[2], code=exc.code)])
    return _build(name, "DOT precedence graph", nodes, node_lines, [(name, edges)], file)


def _dot_lookahead(text: str):
    """``(peek, take, ahead)`` over the DOT tokens of ``text`` (:func:`check_dot_bytes`): ``peek(k)`` the
    token ``k`` ahead (the eof token past the end), ``take(kind, value)`` the next one, refused with its
    line unless of that kind and value; ``ahead``, the tokens read but not taken (two at most)."""
    stream = _tokens(text)
    ahead: deque = deque()  # the next tokens, read as the parser looks ahead (two at most)
    end: list = []          # the eof token, once read

    def peek(k=0):
        if len(ahead) > k:  # the common case: the token is read already
            return ahead[k]
        while len(ahead) <= k and not end:
            tok = next(stream)
            (end if tok[0] == "eof" else ahead).append(tok)
        return ahead[k] if k < len(ahead) else end[0]

    def take(kind=None, value=None):
        tok = peek()
        if (kind and tok[0] != kind) or (value is not None and tok[1] != value):
            want = value or kind
            raise _Bad(f"expected {want!r} but found {tok[1] or 'the end of the file'!r}",
                       "check the DOT syntax here", tok[2])
        if tok[0] != "eof":
            ahead.popleft()
        return tok

    return peek, take, ahead


def _dot_statements(peek, take, ahead: deque, nodes: dict[str, dict], node_lines: dict[str, int],
                    edges: list[tuple[str, str, int]]):
    """The reader of a DOT block's statements (:func:`check_dot_bytes`), ``statements(depth)``: it reads
    up to the block's closing ``}`` through ``peek``, ``take`` and ``ahead`` (:func:`_dot_lookahead`),
    adding the nodes (with their data and first lines) and the edges it meets."""

    def attrs() -> dict[str, str]:
        out: dict[str, str] = {}
        while peek()[1] == "[":
            take(value="[")
            while peek()[1] != "]":
                key = take("id")
                take(value="=")
                out[key[1]] = take("id")[1]
                if peek()[1] in (",", ";"):
                    take()
            take(value="]")
        return out

    def node(pid: str, line: int, given: dict | None = None) -> None:
        entry = nodes.get(pid)
        if entry is None:
            if len(nodes) >= MAX_TASKS:
                raise _Bad(f"more than {MAX_TASKS:,} nodes; graph files of at most {MAX_TASKS:,} are read "
                           "(a plan holds at most 10,000 parts)", "split the graph into smaller ones", line,
                           "limit")
            entry = nodes[pid] = {}
            node_lines[pid] = line
        if not given:
            return
        for key, value in given.items():
            if key in ("label", "name"):
                entry["name"] = value
            elif key in _NUMERIC:
                entry[key] = _number(value, f"node {pid}'s {key}", line)

    def statements(depth: int) -> None:
        if depth > MAX_DEPTH:
            raise _Bad(f"subgraphs nested more than {MAX_DEPTH} levels deep", "flatten the subgraphs", peek()[2],
                       "limit")
        # Each statement peeks at its first token once (800,000 tokens at most: the parser's own
        # steps are most of the time spent on a large file).
        while True:
            tok = peek()
            value = tok[1]
            if value == "}":
                break
            if tok[0] == "eof":
                raise _Bad("the file ends before the closing '}'", "close the digraph with '}'", tok[2])
            if value == "subgraph" or value == "{":
                if value == "subgraph":
                    take()
                    if peek()[0] == "id":
                        take()
                take(value="{")
                statements(depth + 1)
                take(value="}")
            elif tok[0] != "id":
                raise _Bad(f"unexpected {value!r}", "check the DOT syntax here", tok[2])
            elif (after := peek(1)[1]) == "[" and value in ("graph", "node", "edge"):
                take()
                attrs()
            elif after == "=":
                take(), take(), take("id")
            else:
                ahead.popleft()   # tok, an id (peeked above)
                chain = [tok]
                while peek()[0] == "arrow":
                    ahead.popleft()
                    if peek()[1] in ("{", "subgraph"):
                        raise _Bad("an edge to a subgraph", "write one edge per pair: a -> b; a -> c", peek()[2])
                    chain.append(take("id"))
                given = attrs() if peek()[1] == "[" else None
                if len(chain) == 1:
                    node(chain[0][1], chain[0][2], given)
                for (_, a, la), (_, b, _) in zip(chain, chain[1:]):
                    node(a, la)
                    node(b, la)
                    if len(edges) >= MAX_PAIRS:
                        raise _Bad(f"more than {MAX_PAIRS:,} edges; graph files of at most {MAX_PAIRS:,} are read",
                                   "split the graph into smaller ones, or list only the covering edges "
                                   "(opportune convert writes those)", la, "limit")
                    edges.append((a, b, la))
            sep = peek()[1]
            if sep == ";" or sep == ",":
                ahead.popleft()

    return statements

def _dot_id(s: str) -> str:
    return s if re.fullmatch(r"[A-Za-z_][A-Za-z_0-9]*", s) else '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def to_dot_precedence(plan, strategy: int = 0) -> str:
    """One strategy of the plan as a DOT digraph: its cover relations, names as labels, the rest as
    node attributes — the format :func:`check_dot_bytes` reads (a drawing is ``opportune graph``).

    Parameters
    ----------
    plan : Plan
        The plan.
    strategy : int, default 0
        The strategy's position in ``plan.strategies``.

    Returns
    -------
    str
        The DOT text.

    Examples
    --------
    >>> from opportune import make_plan
    >>> print(to_dot_precedence(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["a", "b"]}, name="tiny")))
    digraph tiny {
      a;
      b;
      c;
      a -> b;
      b -> c;
    }
    <BLANKLINE>
    """
    lines = [f"digraph {_dot_id(plan.name)} {{"]
    for part in plan.parts:
        attrs = [f"{'label' if key == 'name' else key}={_dot_id(value) if key == 'name' else value}"
                 for key, value in _node_data(part)]
        lines.append(f"  {_dot_id(part.id)}" + (f" [{', '.join(attrs)}]" if attrs else "") + ";")
    for a, b in _covers(plan, strategy):
        lines.append(f"  {_dot_id(a)} -> {_dot_id(b)};")
    lines.append("}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- NetworkX (optional)

def plan_to_networkx(plan, strategy: int = 0):
    """One strategy as a ``networkx.DiGraph`` (:meth:`opportune.planning.plan.Plan.to_networkx`).

    Parameters
    ----------
    plan : Plan
        The plan.
    strategy : int, default 0
        The strategy's position in ``plan.strategies``.

    Returns
    -------
    networkx.DiGraph
        A node per part, an edge per cover relation.

    Examples
    --------
    >>> from opportune import make_plan
    >>> sorted(plan_to_networkx(make_plan(["a", "b", "c"], {"b": ["a"], "c": ["a", "b"]})).edges())
    [('a', 'b'), ('b', 'c')]
    """
    return plan.to_networkx(strategy)


def plan_from_networkx(graph, name: str | None = None):
    """A plan from a directed graph.

    Parameters
    ----------
    graph : networkx.DiGraph
        Edges ``a -> b``: a before b; node data ``name`` (or ``label``), ``quantity``, ``install``,
        ``acquire``.
    name : str, optional
        The plan's name (default: the graph's ``name``, else ``"networkx"``).

    Returns
    -------
    Plan
        A one-strategy plan.

    Raises
    ------
    PlanError
        Listing every problem (an undirected graph, a cycle), as ``opportune check`` would.

    Examples
    --------
    >>> import networkx as nx
    >>> plan_from_networkx(nx.DiGraph([("a", "b"), ("b", "c")]), name="chain").strategies[0].pairs()
    [('a', 'b'), ('b', 'c')]
    >>> plan_from_networkx(nx.Graph([("a", "b")]))
    Traceback (most recent call last):
        ...
    opportune.planning.plan.PlanError: error: the graph is undirected — a precedence graph is directed: use a networkx.DiGraph
    """
    from opportune.planning.plan import PlanError

    if not getattr(graph, "is_directed", lambda: False)():
        raise PlanError([Problem("the graph is undirected", "a precedence graph is directed: use a networkx.DiGraph")])
    nodes = {}
    for pid, data in graph.nodes(data=True):
        entry = {}
        if "name" in data or "label" in data:
            entry["name"] = str(data.get("name", data.get("label")))
        for key in _NUMERIC:
            if key in data:
                entry[key] = data[key]
        nodes[str(pid)] = entry
    edges = [(str(a), str(b), 0) for a, b in graph.edges()]
    result = _build(name or str(graph.graph.get("name") or "networkx"), "NetworkX graph", nodes, {},
                    [("main", edges)], None)
    if result.plan is None or result.errors:
        raise PlanError(result.problems)
    return result.plan
