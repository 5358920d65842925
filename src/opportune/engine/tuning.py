"""Every numeric tuning constant of the order engine, in one place, each with why it has its value
and what measured it (``benchmarks/bench_count.py`` on the SALBP graphs and the random sparse orders,
``benchmarks/bench_decisions.py`` on KILBRID, TONGE70 and ARC111, unless a line says otherwise).

The modules of the engine read them from here: a budget change is one edit in this file.  The
schedule's counting entry and its memory upkeep read ``tuning.NAME`` when they use it, so a test may
patch those here (``monkeypatch.setattr(tuning, "SHRINK_SECONDS", 0.0)``); the other modules import
theirs by name when they load (under the names they had there, which callers still import).

>>> from opportune.engine import tuning
>>> 0 < tuning.GRACE < tuning.COUNT_MARGIN
True
"""

from __future__ import annotations

# ------------------------------------------------------------------ the schedule's counting entry and its memory

#: Most strategies counted by inclusion–exclusion (2^k terms); more: the union's certain bounds.
MAX_STRATEGIES_EXACT = 12
#: Entries per per-state cache before it is cleared (a long simulation of a large plan visits millions
#: of states that never recur; bench_decisions' long runs).
STATE_CACHE_LIMIT = 300_000
#: Between two measurements of an engine's bytes in :meth:`OrderEngine.maintain`, seconds (a measurement
#: samples every memo: a few milliseconds; a decision adds a bounded number of entries meanwhile).
MEASURE_EVERY = 0.5
#: Memos over ``memory_limit`` are shrunk to this share of it (room for hours before the next shrink).
SHRINK_TO = 0.5
#: Share of an engine's ``memory_limit`` that programmes kept beside it (a policy's exact optimum,
#: :meth:`OrderEngine.reserve_programme`) may hold in all; the memos keep the rest.
PROGRAMME_SHARE = 0.5
#: Most seconds one :meth:`OrderEngine.maintain` spends shrinking (the rest waits for the next one).
SHRINK_SECONDS = 0.02
#: New memo entries a plain count may add before counting through a hub is tried (ARC111 in
#: bench_count: its plain count never finishes, its hub count does).
HUB_PROBE = 100_000
#: Seconds Schedule.count_result may take past its deadline: the deadline checks' granularity and
#: assembling the answer (measured at most 0.1 s past it on orders of up to 10,000 elements).
COUNT_MARGIN = 0.25
#: Seconds per element an estimate needs for its bounds and first path (~0.25 s for 10,000 elements).
ESTIMATE_RESERVE = 3e-5
#: Seconds the exact count and the estimate each get in count_result when its deadline has passed:
#: a small plan is still exact.
GRACE = 0.05
#: Seconds of the first turn of the plain count and of the engine's count in count_result's exact phase
#: (each later round twice as long; see :mod:`opportune.engine.phases`): small orders are exact within the
#: first, and an order that its hub counts in a tenth of a second is not held up by the plain count.
FIRST_TURN = 0.05
#: The plain count's turn, as a share of the engine's, once the engine found a hub: ARC111's plain
#: count never finishes, its hub count takes about 4 s (a quarter more: 5 s, within the default limit).
PLAIN_SHARE = 0.25
#: Most seconds relaxation Monte Carlo takes in count_result's exact phase, after the second round of
#: turns (one strategy; :func:`~opportune.engine.estimate.relaxation_estimate`): it stops as soon as
#: its interval is within EARLY_ERROR (a tenth of a second to two seconds on sparse orders of 64-100
#: elements), and gives the time back at once where it cannot hit; the exact count has the rest.  A
#: fixed time, not a share of the limit: a longer limit must not make an exact count later.
EARLY_SECONDS = 2.0
#: Share of that first estimate's time for counting its relaxations (their own time): where its draws
#: never hit (ARC111), it is found hopeless after this, so that the exact count (through a hub there)
#: loses little (ARC111 exact in about 6 s of the default 10); a quarter left sparse orders of 100
#: elements with pieces of 40 elements, ±9% within 3 s where pieces of 45 give ±4%.
EARLY_COUNT_SHARE = 0.5
#: The relative error at which that first relaxation estimate stops (the error asked, if looser):
#: ±5% takes a few thousand hits; where the exact count then fails too, the estimate phase runs it
#: again towards the error asked.
EARLY_ERROR = 0.05
#: Share of the estimate phase the first relaxation estimate's draws go on for, when it stated an error
#: wider than asked (one strategy): its draws are the best use of the time (the estimate's own split
#: gave them a third, then sequential Monte Carlo runs that are far wider on such orders); the rest is
#: for the estimate's certain bounds and its own go at the draws.
EARLY_RESUME = 0.85


#: Plans of more units than this find their installable units with tables of four bits, not eight
#: (byte tables hold 32 n sets of up to n bits: 390 MB and 0.6 s to build on a 10,000-unit assembly graph).
WIDE_TABLES = 2048

# ------------------------------------------------------------ the exact counter (count.py)
# Measured with benchmarks/bench_count.py and bench_options.py.

#: Share of each turn's new entries the direction with more extremal elements gets in
#: :meth:`Counter._count_piece` (the other gets the whole turn).  Tunable for experiments.
OTHER_SHARE = 0.0625
#: Memo entries a counter holds between top-level calls, by default (see :meth:`Counter.maintain`).
MAX_TOTAL = 2_000_000
CHECK_EVERY = 256  # new memo entries between clock checks (a power of two), on small posets
#: Posets up to this size may scan with chunk tables of at most 16 bits (three up to 48)
NARROW_UP_TO = 64
#: Posets up to this size scan with byte tables; larger ones element by element.
BYTE_TABLES_UP_TO = 1024
EVICT_CHUNK = 4096  # memo entries dropped between two readings of the clock
#: New entries the plain recursion may spend on a set before its hard pieces get a method each.
PIECE_PROBE = 1 << 13
#: One down-set of the dynamic programme costs about this many memo entries of the recursion.
DP_COST = 0.7
IDEAL_PROBE = 20_000   # sets the bounded down-set count may memoise before it gives up
#: Pieces larger than this never try the down-set DP (nor count their down-sets)
DP_MAX_N = 100

# ------------------------------------------------------------ the down-set programme (downsets.py)
# Measured with benchmarks/bench_count.py.

#: Pieces up to this size get 14-bit chunk tables in upset_counts (32 of them at most)
CHUNK_TABLES_UP_TO = 448

# ------------------------------------------------------------ the estimates (estimate.py)
# Measured with benchmarks/bench_count.py's estimated rows and benchmarks/bench_fallback.py.

#: The stated half-width uses Student's t quantile times ``1 + ERROR_MARGIN * (1 + skew) / sqrt(n)``,
#: where ``skew`` is the skewness of a lognormal with the runs' spread of logs, or that of the runs
#: if larger: a margin calibrated on measured replicate distributions (see :func:`_stated_error`).
ERROR_MARGIN = 0.5
#: Seconds one run of the sequential Monte Carlo takes per particle and squared element (measured
#: here: ARC111, 111 elements, 1,024 particles ~3 s): a run predicted to take longer than the time
#: left is not started, and the time goes to sequential importance sampling instead.
SMC_COST = 2e-7
#: Seconds per element the certain bounds' one pass may take past a spent deadline (measured: 400
#: elements in 3–5 ms), and at most this many in all: kept within the count's stated margin.
SKETCH_FLOOR = 2.5e-5
SKETCH_FLOOR_MOST = 0.05
#: Orders of at most this many elements (and at least :data:`ARMC_MIN_N`) are tried by adaptive
#: relaxation Monte Carlo (:mod:`opportune.engine.relaxmc`, compiled core only) before sequential
#: Monte Carlo: on sparse orders of 64-100 elements it states about ±5 % in 3 seconds.  Larger
#: orders need pieces of far more than 64 elements for a draw to hit.
ARMC_MAX_N = 256
ARMC_MIN_N = 8
#: Share of the time left (after the exact attempts) that it may take; it draws nothing, and leaves
#: the time to the runs, when it predicts fewer than ``ARMC_HOPELESS`` hits in that time (30 hits
#: state about ±40 %).
ARMC_SHARE = 0.6
ARMC_HOPELESS = 30

# ------------------------------------------------------------ counting through a hub (hub.py)
# Measured with ARC111 in benchmarks/bench_count.py.

#: Largest order whose tail distributions the compiled core computes (it keeps Pascal's triangle up
#: to n, about n^2/2 big integers); larger ones run in Python.
NATIVE_TAILS = 256
#: Bytes of one memo entry beside its vector: the key (a set of up to a few hundred elements) and the table's slot.
HUB_ENTRY_OVERHEAD = 120

# ------------------------------------------------------------ measuring memory (memory.py)
# Measured with tests/test_memory_limit.py's bounds.

MEMORY_SAMPLE = 8  # entries sampled at each end of a container

# ------------------------------------------------------------ the compiled counter (native.py)
# Measured with benchmarks/bench_count.py with and without OPPORTUNE_PURE_PYTHON.

#: Largest order the counter hands to the compiled core: all it takes (16 machine words).  Growing
#: its table and arena is resumable (a copy stops at the deadline and goes on at the next call), so
#: budgeted decisions on 1,000-task graphs keep their budget with it too.  Larger orders run in
#: Python.
NATIVE_MAX_ELEMENTS = 1024
#: Bytes of memo the compiled counter holds for one order before it starts again (at the start of
#: a top-level count; one count may add its ``max_memo`` entries on top), unless its counter was made
#: for more entries (:attr:`NativeCounter.max_bytes`).  About 60 bytes an entry on orders of 50
#: elements, about 1.5 KB on orders of 1,000 (keys of 128 bytes, counts of ~1 KB): see
#: :func:`entry_bytes`.
NATIVE_MAX_BYTES = 400 * 2**20

# ------------------------------------------------------------ relaxation Monte Carlo (relaxmc.py)
# Measured with benchmarks/bench_armc.py and bench_count.py's sparse orders.

#: Largest order estimated this way: the partition holds an n × n comparability matrix and an
#: n × (n / k) table of counts (a few MB at 1,024 elements).
RELAX_MAX_N = 1024
#: Piece sizes: the first, the step, the last (the compiled pieces hold at most 64 elements).
RELAX_K_START, RELAX_K_STEP, RELAX_K_MAX = 20, 5, 64
#: Random starts of the partition's swap search per ``k`` (as ``armc``).
RELAX_TRIES = 50
#: Bytes the memos of one relaxation may hold (about 100-140 bytes an entry, with the growth slack).
RELAX_MAX_BYTES = 256 * 2**20
#: The next ``k``'s count is predicted to take this many times this one's memo entries (``armc``: 10).
RELAX_COUNT_GROWTH = 10.0
#: The pilot that predicts the draws a relaxation needs: at most this many draws, stopping at
#: :data:`PILOT_HITS` hits (tens of milliseconds).
RELAX_PILOT_DRAWS = 32768
RELAX_PILOT_HITS = 64
#: Seconds per memo entry and per element placed in a draw (x86-64, measured: 0.15-0.65 µs an
#: entry, 0.04-0.15 µs an element): they only weigh counting against drawing when choosing ``k``;
#: the clock stops the work.
RELAX_ENTRY_SECONDS = 0.5e-6
RELAX_STEP_SECONDS = 0.1e-6
#: Share of the time the exact counts of the relaxations may take, over every ``k`` tried.
RELAX_COUNT_SHARE = 0.5

# ------------------------------------------------------------ the completion chains (sampling.py)
# Measured with benchmarks/bench_decisions.py (tests/test_look_latency.py).

#: Populations started alike (the same order, steps left, size and seed) start from the same place: the
#: cover lists (and, without the compiled core, the spread-out starting sequences and the random stream
#: after them) are kept for the last START_KEEP of them and reused, so the runs of one plan in a service
#: (each starts its first
#: population at the plan's first state, with the same seed) build it once.  The chains are the same
#: as if built afresh.  Memory: at most START_KEEP × (chains × steps × 4 bytes + the covers), and only
#: populations of at most START_KEEP_UNITS steps are kept.
START_KEEP = 4
START_KEEP_UNITS = 20_000

# ------------------------------------------------------------ the frontier window (policies/window.py)

#: Open strategies whose frontier windows a decision of the look-ahead's fallback solves (the first ones
#: in the plan's order; windows with the same parts solved once): the window is closed in the strategy
#: it is the frontier of (a window closed in none credits itself with orders its installations break),
#: and the one of least expected cost, its others a look and a move each, decides.  On the policy lab's
#: two-strategy plans both are solved (twice a one-strategy decision's work at most); on plans of many
#: strategies the work grows with this (each window at most ``len(WINDOW_PARTS) × WINDOW_STATES`` states).
WINDOW_STRATEGIES = 4
