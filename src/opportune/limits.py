"""The limits on everything the program reads: one table for the command line and the service.

Every bound on input lives here, once.  The readers (:mod:`opportune.formats`), the plan's own
check (:mod:`opportune.planning.plan`) and the service (:mod:`opportune.service`) import their
bounds from this module, so that a plan, a looks file or a request is refused alike by
``opportune check`` and by ``POST /plans``, with the same number in the message.  The service's
options may lower a bound (``opportune serve --max-body``), never raise it past what the readers
read: :func:`check_option` says so at start.

:data:`LIMITS` is the table (docs/service.md prints it, and a test checks that the page says what
this module says).  The module imports nothing, so any layer may use it.

>>> LIMITS["plan_bytes"].value == MAX_FILE_BYTES
True
>>> check_option("--max-body", 64 << 20, MAX_BODY)
Traceback (most recent call last):
...
ValueError: --max-body 67,108,864 is over its maximum of 33,554,432 bytes (32 MiB): the readers read no larger plan file, so a larger body could only be refused later; give at most 33554432
"""

from __future__ import annotations

# ---------------------------------------------------------------- plans (every format)
#: The engine's tables grow with the square of the number of units: 10,000 units take about 0.5 GB.
MAX_PARTS = 10_000           # parts declared
MAX_QUANTITY = 10_000        # identical units of one part
MAX_UNITS = 10_000           # install operations in all (the sum of the quantities)
MAX_STRATEGIES = 64          # alternative strategies (checking compares every pair of them)
MAX_CONSTRAINTS = 1_000_000  # declared constraints, over all strategies
MAX_WEIGHT = 1_000_000       # a constraint's weight (the price of dropping it; > 0, default 1)
MAX_WAYS = 256               # ways in of one part, in a plan written as ways (derive's minimal ways: directions × supports)
MAX_PRODUCTS = 16            # products built at once on as many fixtures (one bin)

# ---------------------------------------------------------------- plan files (YAML, JSON)
MAX_FILE_BYTES = 32 << 20    # a plan file (32 MiB), and a plan uploaded to the service
MAX_DEPTH = 64               # nesting of values (a plan needs 6)
MAX_ALIASES = 1_000          # YAML aliases (*name) in one file
MAX_VALUES = 150_000         # values of a document (keys included), aliases expanded: 10,000 parts, ~130,000 constraints
MAX_ALIAS_VALUES = 50_000    # values that aliases add to a YAML document by repeating what they name
MAX_TEXT = 100_000           # characters of one string (a name, a description)
MAX_ID = 200                 # characters of a part id (a look names parts by id: a short text)

# ---------------------------------------------------------------- graph files (.IN2, .alb, DOT, GraphML)
MAX_TASKS = 2 * MAX_UNITS    # tasks (nodes): past MAX_UNITS the plan's own check says what to do
MAX_PAIRS = 120_000          # precedence lines (edges), repeats included
MAX_LINES = 4 * (MAX_TASKS + MAX_PAIRS)  # lines of a line-based graph file, blank ones and comments included
MAX_LINE_CHARS = 10_000      # characters of one line of an .IN2 or .alb file (a value or a pair is short)

# ---------------------------------------------------------------- looks and sequences files
MAX_LOOKS_BYTES = 32 << 20       # a looks file (32 MiB)
MAX_LOOKS = 1_000_000            # looks in one file (a cell's week at one look a second)
MAX_LOOK_PARTS = 2_000_000       # part ids in all the looks of one file
MAX_SEQUENCE_BYTES = 32 << 20    # one sequences file (32 MiB)
MAX_SEQUENCES = 100_000          # sequences in one file
MAX_SEQUENCE_ITEMS = 2_000_000   # installations in all the sequences of one file (about 2 s to read)
MAX_ESTIMATE_RUNS = 100_000      # seeded runs of one estimate (`evaluate --runs`; 1,000 give a standard error near 0.05%)

# ---------------------------------------------------------------- geometry (`opportune derive`)
MAX_MESH_BYTES = 64 << 20        # one part's mesh file (64 MiB), checked before it is read
MAX_TRIANGLES = 20_000           # triangles of one part (the blocking test compares bodies' edges pairwise)
MAX_MESH_PARTS = 300             # parts (mesh files) of one assembly
MAX_WORKING = 256                # partial orders kept while the exact plan is built part by part (each pair compared)
MAX_DIRECTIONS = 64              # insertion directions (given, or the axes and the contacts' normals)
MAX_COORDINATE = 10_000          # metres from the origin, any vertex (beyond, squares of lengths lose their digits)
MAX_SCENE_BYTES = 256 << 20      # a glTF/GLB scene file, and its buffers in all (256 MiB: 300 parts of 20,000 triangles)
MAX_SCENE_NODES = 10_000         # entries of each list of a glTF file (nodes, meshes, accessors, buffers, ...)
MAX_SCENE_DEPTH = 64             # nesting of a scene's nodes, and of an MJCF file's elements
MAX_XML_BYTES = 8 << 20          # an MJCF model with its included files, in all (8 MiB)
MAX_XML_ELEMENTS = 100_000       # elements of an MJCF model, its includes' counted
MAX_INCLUDE_DEPTH = 8            # <include> within <include> in an MJCF model
MAX_MJCF_BODIES = 3_000          # <body> elements of an MJCF model (a part may be several unnamed bodies)
MAX_GEOMS = 10_000               # <geom> elements of an MJCF model
MAX_STEP_BYTES = 64 << 20        # a STEP file (64 MiB), checked before Open CASCADE reads it
STEP_SECONDS = 120               # meshing a STEP file (a child process, ended past this)
STEP_MEMORY = 4 << 30            # the address space of the child process that meshes a STEP file (4 GiB)
MAX_MANIFEST_BYTES = 1 << 20     # an assembly's manifest (assembly.yaml, 1 MiB)
MAX_PROCESS = 10_000             # process constraints ("this before that") of a manifest
# a part's real shape in a plan (`geometry: {convex: ...}`, written by derive, heaped by the physical bin)
MAX_SHAPE_BODIES = 64            # convex bodies of one part's shape
MAX_BODY_POINTS = 256            # corners of one body (the physical bin takes its convex hull)
MAX_SHAPE_POINTS = 20_000        # corners of all the shapes of one plan (80,000 values of a document)

# ---------------------------------------------------------------- requests to the service
MAX_BODY = MAX_FILE_BYTES        # a request body: no more than the largest plan file the readers read
DEFAULT_MAX_BODY = 1 << 20       # `serve --max-body` when not given (1 MiB: a plan of thousands of parts fits)
MIN_BODY = 1024                  # `serve --max-body` at least (a look of a few parts fits)
MAX_LOOK = 100_000               # part ids in one look (units repeated)
MAX_NAME = 100                   # characters of a cell's or an operator's name
MAX_LABEL = 200                  # characters of a run's label
MAX_FILENAME = 200               # characters of an upload's file name (the name used in problems)
MAX_KEY = 200                    # characters of an Idempotency-Key
MAX_BUFFER = 1_000_000           # a run's buffer locations
MAX_PAGE = 1_000                 # runs in one page of GET /runs


class Limit:
    """One row of the table: a bound, what it counts, and what reads it."""

    __slots__ = ("key", "value", "unit", "what", "where", "option")

    def __init__(self, key: str, value: int, unit: str, what: str, where: str, option: str = ""):
        self.key, self.value, self.unit, self.what, self.where, self.option = key, value, unit, what, where, option

    def __repr__(self) -> str:
        return f"Limit({self.key!r}, {self.value!r})"


BOTH, SERVICE = "command line and service", "service"

#: Every limit, by key, in the order docs/service.md lists them.
LIMITS = {limit.key: limit for limit in (
    Limit("plan_bytes", MAX_FILE_BYTES, "bytes", "a plan file, or a plan's text uploaded (`POST /plans`)", BOTH),
    Limit("parts", MAX_PARTS, "parts", "parts declared in a plan", BOTH),
    Limit("quantity", MAX_QUANTITY, "units", "identical units of one part", BOTH),
    Limit("units", MAX_UNITS, "units", "units of a plan in all (the sum of the quantities)", BOTH),
    Limit("strategies", MAX_STRATEGIES, "strategies", "alternative strategies of a plan", BOTH),
    Limit("constraints", MAX_CONSTRAINTS, "constraints", "declared constraints, over all strategies", BOTH),
    Limit("ways", MAX_WAYS, "ways", "ways in of one part, in a plan written as ways (`ways`)", BOTH),
    Limit("weight", MAX_WEIGHT, "", "a constraint's weight", BOTH),
    Limit("values", MAX_VALUES, "values", "values of a YAML or JSON document (keys included, aliases expanded)",
          BOTH),
    Limit("depth", MAX_DEPTH, "levels", "nesting of a document's values", BOTH),
    Limit("aliases", MAX_ALIASES, "aliases", "YAML aliases in one file", BOTH),
    Limit("alias_values", MAX_ALIAS_VALUES, "values", "values that YAML aliases add by repeating what they name",
          BOTH),
    Limit("text", MAX_TEXT, "characters", "one string of a plan (a name, a description)", BOTH),
    Limit("id", MAX_ID, "characters", "a part id, in a plan and in a look", BOTH),
    Limit("tasks", MAX_TASKS, "tasks", "tasks of a graph file (.IN2, .alb, DOT, GraphML)", BOTH),
    Limit("pairs", MAX_PAIRS, "pairs", "precedence lines or edges of a graph file", BOTH),
    Limit("lines", MAX_LINES, "lines", "lines of an .IN2 or .alb file", BOTH),
    Limit("line_chars", MAX_LINE_CHARS, "characters", "one line of an .IN2 or .alb file", BOTH),
    Limit("products", MAX_PRODUCTS, "products", "products built at once (`products` of a run)", BOTH),
    Limit("looks_bytes", MAX_LOOKS_BYTES, "bytes", "a looks file", "command line"),
    Limit("looks", MAX_LOOKS, "looks", "looks in one file", "command line"),
    Limit("look_parts", MAX_LOOK_PARTS, "part ids", "part ids in all the looks of one file", "command line"),
    Limit("sequence_bytes", MAX_SEQUENCE_BYTES, "bytes", "a sequences file", "command line"),
    Limit("sequences", MAX_SEQUENCES, "sequences", "sequences in one file", "command line"),
    Limit("sequence_items", MAX_SEQUENCE_ITEMS, "installations", "installations in all the sequences of one file",
          "command line"),
    Limit("estimate_runs", MAX_ESTIMATE_RUNS, "runs", "seeded runs of one estimate of a policy's gap (`evaluate --runs`)",
          "command line"),
    Limit("mesh_bytes", MAX_MESH_BYTES, "bytes", "one part's mesh file (`derive`)", "command line"),
    Limit("triangles", MAX_TRIANGLES, "triangles", "triangles of one part's mesh (`derive`)", "command line"),
    Limit("shape_bodies", MAX_SHAPE_BODIES, "bodies", "convex bodies of one part's shape in a plan", BOTH),
    Limit("body_points", MAX_BODY_POINTS, "corners", "corners of one body of a part's shape", BOTH),
    Limit("shape_points", MAX_SHAPE_POINTS, "corners", "corners of all the shapes of one plan", BOTH),
    Limit("mesh_parts", MAX_MESH_PARTS, "parts", "parts (mesh files) of one assembly (`derive`)", "command line"),
    Limit("working_orders", MAX_WORKING, "partial orders",
          "incomparable partial orders kept while a derived plan is built (`derive`)", "command line"),
    Limit("directions", MAX_DIRECTIONS, "directions", "insertion directions of a derivation (`derive`)",
          "command line"),
    Limit("coordinate", MAX_COORDINATE, "m", "a vertex's distance from the origin along each axis (`derive`)",
          "command line"),
    Limit("scene_bytes", MAX_SCENE_BYTES, "bytes", "a glTF/GLB scene with its buffers (`derive`)", "command line"),
    Limit("scene_nodes", MAX_SCENE_NODES, "entries", "each list of a glTF file: nodes, meshes, accessors, ... "
          "(`derive`)", "command line"),
    Limit("scene_depth", MAX_SCENE_DEPTH, "levels", "nesting of a scene's nodes or an MJCF file's elements "
          "(`derive`)", "command line"),
    Limit("xml_bytes", MAX_XML_BYTES, "bytes", "an MJCF model with its includes (`derive`)", "command line"),
    Limit("xml_elements", MAX_XML_ELEMENTS, "elements", "elements of an MJCF model with its includes (`derive`)",
          "command line"),
    Limit("include_depth", MAX_INCLUDE_DEPTH, "levels", "includes within includes of an MJCF model (`derive`)",
          "command line"),
    Limit("mjcf_bodies", MAX_MJCF_BODIES, "bodies", "bodies of an MJCF model (`derive`)", "command line"),
    Limit("geoms", MAX_GEOMS, "geoms", "geoms of an MJCF model (`derive`)", "command line"),
    Limit("step_bytes", MAX_STEP_BYTES, "bytes", "a STEP file (`derive`)", "command line"),
    Limit("step_seconds", STEP_SECONDS, "s", "meshing a STEP file (`derive`)", "command line"),
    Limit("step_memory", STEP_MEMORY, "bytes", "memory of the process that meshes a STEP file (`derive`)",
          "command line"),
    Limit("manifest_bytes", MAX_MANIFEST_BYTES, "bytes", "an assembly's manifest (`derive`)", "command line"),
    Limit("process", MAX_PROCESS, "constraints", "process constraints of a manifest (`derive`)", "command line"),
    Limit("body", MAX_BODY, "bytes", f"a request body (default {DEFAULT_MAX_BODY:,}, at least {MIN_BODY:,})",
          SERVICE, "--max-body"),
    Limit("look", MAX_LOOK, "part ids", "part ids in one look (`POST /runs/{id}/looks`)", SERVICE),
    Limit("name", MAX_NAME, "characters", "a cell's or an operator's name (letters, digits, `.`, `_`, `-`; "
          "`token create`)", BOTH),
    Limit("label", MAX_LABEL, "characters", "a run's label", SERVICE),
    Limit("filename", MAX_FILENAME, "characters", "an upload's file name", SERVICE),
    Limit("key", MAX_KEY, "characters", "an `Idempotency-Key`", SERVICE),
    Limit("buffer", MAX_BUFFER, "locations", "buffer locations (`--buffer-capacity`, a run's `buffer_capacity`)",
          BOTH),
    Limit("page", MAX_PAGE, "runs", "runs in one page of `GET /runs` (`limit`)", SERVICE),
)}


def _size(n: int) -> str:
    """``33,554,432 bytes (32 MiB)``: a number of bytes as the messages write it."""
    mib = f" ({n >> 20} MiB)" if n >= 1 << 20 and n % (1 << 20) == 0 else ""
    return f"{n:,} bytes{mib}"


def check_option(option: str, value: int, most: int, least: int = 0) -> int:
    """``value`` of a server option that may lower a limit, checked against the limit ``most``.

    Parameters
    ----------
    option : str
        The option's name, as the user typed it (``--max-body``).
    value : int
        What was asked for.
    most, least : int
        The limit itself (the readers' bound) and the least the option may be.

    Returns
    -------
    int
        ``value``, within the bounds.

    Raises
    ------
    ValueError
        Over the limit or under ``least``, saying which bound and what to give.

    Examples
    --------
    >>> check_option("--max-body", 4096, MAX_BODY, MIN_BODY)
    4096
    """
    if value > most:
        raise ValueError(f"{option} {value:,} is over its maximum of {_size(most)}: the readers read no larger "
                         f"plan file, so a larger body could only be refused later; give at most {most}")
    if value < least:
        raise ValueError(f"{option} {value:,} is under its minimum of {_size(least)}; give at least {least}")
    return value


def markdown_table() -> str:
    """The table as docs/service.md prints it (a test compares the page with it).

    Returns
    -------
    str
        A Markdown table: limit, value, what it bounds, who reads it.

    Examples
    --------
    >>> markdown_table().splitlines()[2].startswith("| `plan_bytes` | 33,554,432 bytes (32 MiB) |")
    True
    """
    rows = ["| limit | at most | what | read by |", "|---|---:|---|---|"]
    for limit in LIMITS.values():
        value = _size(limit.value) if limit.unit == "bytes" else f"{limit.value:,} {limit.unit}".rstrip()
        where = limit.where + (f" (`serve {limit.option}` lowers it)" if limit.option else "")
        rows.append(f"| `{limit.key}` | {value} | {limit.what} | {where} |")
    return "\n".join(rows)
