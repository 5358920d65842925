"""Every numeric tuning constant of the order engine, in one place, each with why it has its value
and what measured it (``benchmarks/bench_count.py`` on the SALBP graphs and the random sparse orders,
``benchmarks/bench_decisions.py`` on KILBRID, TONGE70 and ARC111, unless a line says otherwise).

The policies' constants live here too (the answering layer's budget, the optimum's and the frontier
window's bounds, how counts are written): the policies sit above the engine and read this module, the
engine never reads theirs.  The answering layer's decision budget is split by one object,
:class:`~opportune.policies.budget.Budget`, whose defaults are the ``DECISION_*`` and ``*_SHARE``
lines below; the engine receives a deadline and nothing else about time.

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


# ------------------------------------------------------------ the answering layer's budget (policies/answers.py)
# Measured with benchmarks/bench_decisions.py (50 ms budgets on KILBRID, TONGE70 and ARC111) and
# tests/test_decision_budget.py; policies/budget.py's Budget takes its defaults from these lines.

#: Share of the decision budget kept for building the answer (the reasons) after the rule's estimate.
DECISION_MARGIN = 0.1
#: Share of the budget the exact attempt gets: after a failure, after a success (a success is tried
#: with more; a failure gives the estimate most of the budget at the next look).
EXACT_SHARE = (0.25, 0.6)
#: Exact attempts come first while their moving average took under this share of the budget.
EXACT_FIRST = 0.2
#: Otherwise a first estimate (a probe) gets this share, and ends the decision if it is sure.
PROBE_SHARE = 0.3
#: Weight of the last exact attempt (or probe) in the moving averages the readings keep.
SLOW_WEIGHT = 0.3
#: That average shrinks by this factor after each sure probe, so exact counts are tried again some day.
SLOW_DECAY = 0.97
#: The averages are kept per band of this many steps remaining (ARC111's early states are slow, its
#: late ones quick: docs/decisions.md).
SIZE_BAND = 5
#: Where exact attempts are slow but not failing, a probe comes first only while at least this share of
#: the probes there settled (else many close candidates: the exact counts decide better while they fit).
PROBES_SETTLING = 0.5
#: An average above this share of the budget: exact attempts have been failing there (the estimate
#: goes on instead of trying them).
FAILING = 0.4
#: With a question after the rule (:meth:`~opportune.policies.answers.CountBasedRule.then`): the share
#: of the budget the rule gets, and the share the question's exact answer may take before it is
#: estimated with what is left.
THEN_SHARES = (0.6, 0.3)

# ------------------------------------------------------------ the estimates' early stop (policies/base.py, answers.py)
# Measured with benchmarks/bench_decisions.py's agreement with the exact rule.

#: An estimated decision stops early, keeping the rest of its budget, once it is this sure of its choice,
#: or this sure that no other candidate is better by more than :data:`INDIFFERENT` (a near tie: the
#: samples would take the whole budget to settle it, for no measurable difference in the outcome).
SURE = 0.999
#: The margin of a near tie: a share of the best candidate's share of completions, or of the steps
#: remaining for an expected position.
INDIFFERENT = 0.01
#: Moves per chain, per step remaining, before an early stop is trusted (a population just started
#: from spread-out sequences is not yet uniform).
MIXED_STEPS = 20

# ------------------------------------------------------------ the exact optimum (policies/optimal.py, pile.py, states.py)
# Measured with benchmarks/bench_optimum.py and tests/test_evaluate_bounds.py's memory bounds.

#: Looks (with their probabilities) the look cache keeps, over all the bin contents it holds: about
#: 150 bytes each, so at most about 30 MB whatever the plan (it used to grow with the states × looks).
LOOK_CACHE_LOOKS = 200_000
#: Bytes of an (installed, strategies) pair the compiled optimum interns: the pair in a vector and a
#: node of the hash map that finds it (what ``OptimalCore.bytes`` counts).
COMPILED_PAIR_BYTES = 64
#: The compiled optimum's cache of a weighted bin's looks (by bin content) holds at most this many
#: bytes, and is cleared whole before it would hold more (a bin's looks are enumerated again when needed).
COMPILED_LOOK_CACHE_BYTES = 4 << 20
#: Visible parts the compiled optimum of a weighted bin takes at most: a look is coded in 6 bits a part.
COMPILED_WEIGHTED_VISIBLE = 10
#: The compiled optimum of a weighted bin enumerates a bin's looks at every state (about 7 ns a look,
#: measured on 12 parts, 3 visible): the look-ahead takes it on plans of at most this many looks at the
#: start times states (the start has the most looks), about ten seconds' work like its uniform bin's
#: cap (:attr:`~opportune.policies.lookahead.Lookahead.COMPILED_STATES`).
COMPILED_WEIGHTED_LOOKS = 1_000_000_000
#: Bytes a look of a weighted bin takes in the compiled cache besides its parts (one byte each): its
#: probability (8), and while the bin's looks are enumerated, its sum and its sorted parts by code (128).
COMPILED_LOOK_BYTES = 136
#: Bytes a bin's entry takes in the compiled look cache (its hash node and vectors; ``ENTRY_BYTES``
#: in ``src/native/optimal.cpp``).
COMPILED_LOOK_ENTRY_BYTES = 96
#: Bytes the compiled pile optimum holds per stored value: a 16-byte slot (the state and window as one
#: 64-bit code, the value) in a table at most half full, so 32-64 bytes when the table is reserved
#: for the count known before (96 for a moment while an unreserved table doubles).  The (installed,
#: strategies) pairs it interns are fewer by the buffers and windows of each, and add a few percent.
#: The Python programme takes 220-260 bytes per value.
PILE_COMPILED_BYTES_PER_STATE = 64
#: Memory a programme uses per state, rounded up: the dict entry, the key and buffer tuples and the
#: value (measured: 574 bytes per state for the optimum of KILBRID, 716 on the gearbox, 220-260 per
#: stored value in the pile).  The memo is the only thing that grows with the states; beside it the
#: look cache holds at most :data:`LOOK_CACHE_LOOKS` looks (~30 MB).
BYTES_PER_STATE = 1_000
#: The state estimate's decomposition packs polynomials that grow as units²; past this many units only
#: a lower bound is given (:func:`~opportune.policies.states.downset_profile`).
PROFILE_MAX_UNITS = 2_000

# ------------------------------------------------------------ the exact evaluation (cli/evaluate.py)
# Measured with benchmarks/bench_evaluate_rates.py: states stored per CPU second (the machine's load beside
# them), each programme run alone in a child process, and its peak resident memory over a child's that
# only built the plan (bytes per state).  ``opportune evaluate`` sizes its work with them before it starts.

#: Seconds of CPU the default state caps of ``opportune evaluate`` are sized for: each programme that runs
#: (the optimum's, and the policy's own evaluation where it does not decide by the optimum) may store the
#: states it does in this time at its rate in :data:`EVALUATE_RATES`, within :data:`EVALUATE_MEMORY`.
EVALUATE_SECONDS = 60
#: Bytes the states of one programme may hold under the default caps (its rate's states times its bytes
#: per state, :data:`EVALUATE_BYTES`): a share a laptop of 8 GB spares; ``--max-states`` asks for more.
EVALUATE_MEMORY = 2 << 30
#: States per CPU second, by programme: the compiled optimum (``OptimalCore``, ``PileCore``) by bin, the
#: Python optimum (no compiled core) by bin, and a policy's own evaluation (Python: every look of every
#: state asks the policy) of a rule (paper, slack, bin-first) or of a policy deciding by a look-ahead of
#: its own (the look-ahead by its frontier window, the rollout), by bin.  Measured in two runs (load 6-12
#: on 2 cores; docs/decisions.md has the table): the compiled uniform optimum 308,000-444,000 on KILBRID
#: (1-2 visible, 1 location), 480,000-742,000 on a 14-part plan (2 visible, unlimited buffer); the compiled
#: weighted optimum 176,000-199,000 on KILBRID, 241,000-263,000 on the 14-part plan (it falls with the
#: looks: about 7 ns a look); the compiled pile optimum 1,090,000-1,600,000 on the 14-part plan; the Python
#: optimum 26,700-32,500 (uniform), 19,800-26,900 (pile), 6,100-10,800 (weighted); the paper's rule
#: 2,550-6,580 (uniform) and 19,000-23,000 (pile); the look-ahead's own evaluation 900-1,210 (uniform) and
#: 1,160-1,590 (pile), the rollout's 600-850; each rounded down below the lower figure.
EVALUATE_RATES = {
    "compiled uniform": 300_000, "compiled weighted": 100_000, "compiled pile": 1_000_000,
    "Python uniform": 25_000, "Python weighted": 5_000, "Python pile": 25_000,
    "rule uniform": 2_500, "rule pile": 10_000, "window uniform": 600, "window pile": 600,
}
#: Bytes per stored state, by programme: the compiled tables (16-byte slots at most half full, the
#: (installed, strategies) pairs beside them: 39-61 bytes a state by their own count, 57-90 of peak resident
#: memory while a table doubles), the Python programmes' :data:`BYTES_PER_STATE` (266-1,053 measured on
#: runs of 10,000-120,000 states; a run of a few thousand shows its look cache's bytes as well, and a
#: policy deciding by a look-ahead of its own its bounded window caches, :data:`WINDOW_CACHE`: 2.6-3.7 kB).
EVALUATE_BYTES = {"compiled": 96, "Python": BYTES_PER_STATE}
#: ``evaluate`` lists the optimum's states for 3 seconds; where that listing stops short and the estimate
#: from the order's down-sets is over the cap by at most this factor, the listing goes on by counted work
#: up to the cap instead of refusing on the estimate (KILBRID with two locations: 27,523,885 states, the
#: estimate 38,064,092, the listing 2.2 CPU seconds idle and past 3 s at load 6); the estimate was 0.85-7.3
#: times the true count on random plans (policies/states.py).
EVALUATE_LIST_ON = 2.0

# ------------------------------------------------------------ the look-ahead and the rollout (policies/lookahead.py, rollout.py)
# Measured with benchmarks/bench_optimum.py, benchmarks/policy_lab.py and tests/test_pile_compiled.py.

#: The compiled optimum decides on plans of up to this many states, work done once per plan and setting
#: and shared by its runs: at most 1.1 GB (a table of 2^26 16-byte slots, at most half full; the engine
#: must grant the bytes), and 60-110 CPU seconds at the most (KILBRID with two buffer locations: 27,523,885
#: states, 89 CPU s at load 2-4, where the frontier window was 4-8% from the optimum); plans of a few
#: million states take seconds.  Without a budget it is solved in the first decision; with one, in the
#: background (:meth:`~opportune.policies.lookahead.Lookahead.prepare`) while the window decides;
#: :attr:`~opportune.policies.lookahead.Lookahead.COMPILED_STATES`.
LOOKAHEAD_COMPILED_STATES = 32_000_000
#: Where the optimum does not fit in a pile or weighted bin, plans of more units than this decide as the
#: base does: the step over the base evaluates the base look by look in Python, hours on a 45-part plan.
LOOKAHEAD_STEP_UNITS = 16
#: With a budget, the share of it the look-ahead's programme takes at each decision (it resumes where it
#: stopped), and the share the frontier window may take where the optimum does not fit; the base decides
#: within a quarter (:data:`LOOKAHEAD_BASE_SHARE`) when they do not finish.
LOOKAHEAD_PROGRAMME_SHARE = 0.7
LOOKAHEAD_WINDOW_SHARE = 0.7
LOOKAHEAD_BASE_SHARE = 0.25
#: With a budget, listing the states before the programme starts gets the budget divided by this (it runs
#: inside the first decision).
LOOKAHEAD_LISTING_PARTS = 3
#: The exact evaluation lists the buffer ties of at most this many (installed, strategies) states; past it
#: any pair's order may decide (:attr:`~opportune.policies.evaluate.BufferOrder.TIES_MAX_KEYS`).
TIES_MAX_KEYS = 100_000
#: The rollout decides plans of at most this many units by the exact look-ahead (an expectation, not a
#: sample: its programme finishes within seconds on them), and with a budget samples rounds of futures
#: until this share of it is spent.
ROLLOUT_EXACT_UNITS = 16
ROLLOUT_SHARE = 0.8

# ------------------------------------------------------------ the frontier window (policies/window.py)
# Measured with benchmarks/policy_lab.py (16-30-part plans, docs/policy-lab.md).

#: The window's sizes (parts, buffered ones and ancestors included) tried at a state in increasing size,
#: the largest that fits :data:`WINDOW_STATES` (and the deadline, where there is one) deciding: 12 was
#: within 0.24% of the optimum on 16-30-part plans (8 within 1.7%, 5 about 4%), and the smaller ones keep a
#: window on wide plans, whose frontier's down-sets are many, and within a budget on a slow machine.
WINDOW_PARTS = (5, 8, 12)
#: Larger sizes tried after them where one strategy is open, each unless its states, predicted from the
#: growth of the two before, pass :data:`WINDOW_GROWTH_SEVERAL` times :data:`WINDOW_STATES` (a window that
#: does not fit stops at the cap, and the largest that did decides, as before).  With one location a window
#: of 16-20 parts fits in a few thousand states.  The policy lab's worst one-strategy rows, exact: r27-25 at
#: 3 visible and 1 location +0.862% -> +0.000%, r21-25 at 2 visible +0.783% -> 0, r9-20 at 2 visible
#: +0.753% -> 0, r3-30 at 3 visible +0.652% -> 0, r19-16 at 2 visible and 2 locations +0.463% -> 0, r3-20
#: at 1 visible and 2 locations +0.122% -> +0.104%; the evaluations took less CPU than without the growth
#: check.  Decision CPU along one run, no budget (benchmarks/bench_fallback.py --decisions, load 2-3): the
#: largest 24.8 ms on TONGE70 and 39.8 ms on ARC111 at 1 visible and 1 location, 19-28 ms at 2-3 visible
#: and 2 locations (before: at most 29 ms); the mean 0.8-4.4 ms.  With a budget the deadline stops the
#: largest window first.
WINDOW_PARTS_MORE = (16, 20)
#: The sizes tried at a state where several strategies are open (each open strategy's frontier window),
#: a larger one skipped where its states, predicted from the two before (their growth), pass
#: :data:`WINDOW_STATES`: a window closed in several strategies keeps the option of choosing among them,
#: which the windows of one strategy each do not value.  On r20-16x2 of the policy lab at 1 visible and 2
#: locations: the earlier windows +1.619%, with the look's option value +0.678%, with these sizes too
#: +0.333%; at 1 location every 16- and 20-part two-strategy plan of the lab within 0.25% (before: 2.133%).
#: The CPU of a decision along runs of two-strategy plans of 20 and 30 parts (1-3 visible, a loaded
#: machine): at most 54 ms (37.5 ms before); with a budget the deadline stops the largest window first.
WINDOW_PARTS_SEVERAL = (5, 8, 12, 16, 20)
#: Where several strategies are open, a size of :data:`WINDOW_PARTS_SEVERAL` is tried unless its states,
#: predicted from the growth of the two before, pass this many times :data:`WINDOW_STATES` (a window
#: that does not fit after all stops at the cap: at most that much work lost).  The prediction runs high
#: (on r14-20x2 of the policy lab at 1 visible and 2 locations, 12 parts predicted at 26,400 states held
#: 17,777, and the windows of 8 parts saw the second strategy 1.7 worse than the first where it is 7.7
#: worse, those of 12 parts 7.1): that plan's fallback +1.518% with 1, +0.429% with 2 (no limit: +0.427%).
WINDOW_GROWTH_SEVERAL = 2
#: How deep the look values keeping several strategies open where each open strategy's window decides:
#: 2, a move that keeps several open at its motion and the value of the state it leads to where each look
#: there takes its best move over the windows (its own option), and the shake at this state's value from
#: those moves; 1, the state's option taken off every such move (a buffering that fills a location was
#: credited with the option of an empty one).  On the policy lab's 20-part two-strategy plans at 1
#: visible and 2 locations the worst +1.298% (r29-20x2) with 1, +0.549% with 2 (r29-20x2 +0.135%; the
#: mean +0.426% and +0.231%); 6-8 ms of CPU a state where two windows differ (docs/decisions.md).
WINDOW_OPTION_LOOKS = 2
#: States the window's programme may hold, per size tried (so at most 3 × this a decision, and in practice
#: the largest window's and a few hundred more): 20,000 take about 20 ms of CPU, so a decision's window
#: keeps within its share of a 50 ms budget (35 ms).  Counted, not timed: the same decision everywhere.
WINDOW_STATES = 20_000
#: Before a run's first installation (nothing installed: states every run passes through, its start again
#: after each shake there), without a deadline, the uniform bin's window programme may hold this many times
#: :data:`WINDOW_STATES` (policies/window.py), as the pile's (:data:`PILE_START_FACTOR`).  With an unlimited
#: buffer a window's states grow with every buffer content, so the usual windows are smallest there: on the
#: policy lab's 8-12-part plans at 1 visible the fallback was +0.526% over the optimum on average and +3.497%
#: at worst (exact), all of it before the first installation, where a window of 8 of 11 parts shook on
#: seeing a lumped part the optimum buffers; now +0.020% and +0.223% (2 visible: +0.188% / +1.722% ->
#: +0.005% / +0.096%; the 27 and 26 plans the earlier version reached; over all of them two plans stay
#: over 1%, docs/decisions.md).  Without a budget the largest decision along a run on KILBRID and TONGE70 with an
#: unlimited buffer took 204-278 ms of CPU (18-20 ms before); within a budget the cap is the usual one.
WINDOW_START_FACTOR = 10
#: The frontier window's parts are taken in the order of their remaining ancestors less this many times their
#: remaining descendants (then declaration order): the parts whose installation unlocks the most come into
#: the window with what they wait for.  Measured on KILBRID at 1 visible (benchmarks/bench_window_gap.py,
#: 40 paired runs, with ready others credited a move and 5 shakes, an other bufferable at the decision alone,
#: the form these sweeps were run with; the final form's gaps are in docs/decisions.md): with 1 location 0 gave +2.76%
#: over the optimum, 0.125 +0.76%, 0.25 +0.30%, 0.5 +0.16%, 1 +0.08%, 2 +0.06%, 4 +0.03%; with 2 locations
#: 0.125 +2.93%, 0.25 +1.26%, 0.5 +0.97%, 1 +0.42%, 2 +0.43%, 4 +0.57%.  Without the ready others the
#: order alone is worse (1 location: +8.4% at 1, +3.3% at 0): the window then holds parts it cannot see
#: unlock anything.
WINDOW_DESCENDANTS = 1.0
#: A unit outside the frontier window whose remaining ancestors are all window parts (a *ready other*)
#: is installed when seen once they are, credited with a move and this many shakes and looks: what it would
#: cost after the window (KILBRID's optimum spends about 3-4 shakes a part at 1 visible).  Measured on
#: KILBRID at 1 visible (40 paired runs, :data:`WINDOW_DESCENDANTS` 1, the same form; credits of a move and 1,
#: 3, 5, 9, 19 shakes): with 1 location +0.10%, +0.09%, +0.08%, +0.12%, +0.34%; with 2 locations +0.51%, +0.40%,
#: +0.42%, +0.97%, +1.47%.
WINDOW_READY_LOOKS = 3.0
#: Windows kept, by state (a decision table is under 1 kB for a window of 12 parts, so at most about
#: 4 MB a policy): a state's looks share it.
WINDOW_CACHE = 4096

# ------------------------------------------------------------ counts written as text (engine/result.py, policies/printable.py)
# Not tuned for speed but set by what people and Python read.

#: Counts of more digits than this are written rounded by :func:`~opportune.engine.result.count_text`:
#: the same bound as Python's own guard on int-to-text conversion, and for the same reason (exact text
#: is quadratic in the digits: 20 ms for the 35,660 digits of 10,000!, more than a look's budget when an
#: answer holds several).
EXACT_DIGITS = 4_300
#: Bits of the largest count :func:`str` writes at once (fewer than 4,215 decimal digits, under
#: Python's guard of 4,300); larger ones are written in halves.
STR_BITS = 14_000
#: Counts of at most this many digits are written in full for people (``40,320``), longer ones as three
#: significant digits and an exponent (``6.13e98``): 15 digits still read at a glance, grouped, and
#: any count fits a dashboard's panel (the exponent of a count of 10,000 free parts has 5 digits).
LABEL_DIGITS = 15

# ------------------------------------------------------------ the compiled core's own bounds (fixed by its code)
# Not tuned: src/native sets them, and these lines must agree with it.

#: What the compiled counter itself can take (``NativeCounter`` directly, e.g. in tests).
CORE_MAX_ELEMENTS = 1024
#: Threads that count and draw in relaxation Monte Carlo, at most (``MAX_THREADS`` in ``src/native/relax.cpp``).
RELAX_MAX_THREADS = 256


# ------------------------------------------------------------------ plans written as ways (engine/ways.py)

#: Sets an exact count enters between two readings of the clock (each is O(ways) mask work: on a random
#: block of 300 parts about half a millisecond, so a count passes its deadline by a few milliseconds at most;
#: read as sets are entered, not finished: the first descent is as deep as the plan).
WAYS_CHECK_EVERY = 4
#: Entries the memo of a :class:`~opportune.engine.ways.WaysCounter` holds at most before its oldest half is
#: dropped (about 150 bytes an entry on 300 parts: 300 MB).
WAYS_MAX_TOTAL = 2_000_000
#: Runs an estimate makes at least before it may stop on its stated error (fewer say little of the spread).
WAYS_MIN_RUNS = 4
#: Steps a draw of :class:`~opportune.engine.ways.WaysChains` counts for, per part left: its draws are
#: independent runs, not a chain that needs mixing, so the policies' test of mixing (steps per part left)
#: passes at once.
WAYS_MIXED = 1_000
#: Walks of the first sequential Monte Carlo run (more walks, a run of smaller variance and longer time):
#: few, so that a run finishes on 300 parts within a second of CPU; later runs take as many as the time
#: allows (``engine.ways._run_size``).
WAYS_PARTICLES = 8
#: Runs the size of the later runs is chosen to fit in the time left: four times :data:`WAYS_MIN_RUNS`, so that
#: a machine slower than the first run said still finishes several.
WAYS_RUNS_IN_TIME = 16
#: Walks of a run at most, where the time allows more than :data:`WAYS_PARTICLES` (see ``engine.ways._run_size``).
WAYS_MAX_PARTICLES = 4096
#: Steps between two checks of a walk for parts that lock each other (``engine.ways._Walk.locked``, O(ways)
#: mask operations a pass): a walk past such a lock has no completion but can go on for many steps (on random
#: blocks of 300 parts, from the 25th part to the 290th); caught, it weighs 0 and the resampling
#: replaces it.  Every 4th step: a quarter of the checks' time, a walk kept at most 3 steps too long.
WAYS_LOCK_EVERY = 4

# ------------------------------------------------------------ the pile's frontier window (policies/pile_window.py)
# Measured with benchmarks/policy_lab.py (--bins pile --policies fallback --without-optimum, 16-20 parts),
# benchmarks/bench_window_gap.py (the gap along seeded runs, where the exact evaluation is too slow) and
# benchmarks/bench_fallback.py (CPU per decision on KILBRID).

#: The pile window's sizes (parts, buffered ones and ancestors included): the smallest is solved at a state,
#: and the largest whose states, predicted from it, fit PILE_WINDOW_STATES (policies/lumped.py).  Every size
#: between: a size smaller than the largest that fits costs the gap (on a 16-part plan at 1 visible and 2
#: locations, sizes 5, 8, 12 were +2.8%, 5-12 by one +0.8%, a cap three times larger +0.25%).  Up to 20: where
#: the states allow (a narrow frontier, or several strategies open with the larger cap of
#: PILE_SEVERAL_FACTOR), a window of 13-16 parts is solved (exact, on a 16-part two-strategy plan at 2
#: locations: sizes up to 12 +1.120% and +1.156% at 1 and 2 visible, up to 20 +0.427% and +0.983%).
PILE_WINDOW_PARTS = tuple(range(4, 21))
#: Values (a state's looks and its value after a shake) the pile window's programme may hold per size
#: tried: counted, not timed, so the decision is the same everywhere.  30,000 take about the CPU 20,000
#: took before the compiled core kept its expectations per successor state (KILBRID at 3 visible, counted
#: in instructions: the mean decision 8% less, the largest 16% more; at 1 visible the largest 40% more;
#: a mean of 6-19 ms a decision, within the window's 35 ms share of a 50 ms budget) and bring the gap on
#: r1-16 under 1% at 1-3 visible; 40,000 cost a quarter more again (docs/decisions.md).
PILE_WINDOW_STATES = 30_000
#: Looks one run of a gap's estimate (policies/regret.py) may take before the policy is said not to finish
#: (it shakes at a state forever): a run of a 111-part plan with one location takes about 1,200.
REGRET_RUN_LOOKS = 1_000_000
#: A regret (policies/regret.py) this small is a tie to rounding, as the optimum's ``best_action`` shakes
#: only where no move is cheaper by more: it counts 0 (and the look as the optimum's action).
REGRET_TIE = 1e-12
#: States whose solved window (every look's action, under 50 kB at 3 visible) the pile window keeps: the
#: exact evaluation asks a state's looks between its successors', so the recursion's path must fit.
PILE_WINDOW_CACHE = 512
#: Where several strategies are open, the pile window values keeping them open by the fresh looks of its
#: windows' parts (the others one group), each taken by its best move over the windows; past this many looks
#: (at 3 visible, windows of about 20 parts) the value is 0 and each look takes the least of the windows'
#: moves alone (policies/pile_window.py).  Each look costs a dictionary look-up a window.
PILE_OPTION_LOOKS = 2_000
#: Where several strategies are open, the pile window values a move that keeps them open a look deeper (by
#: the windows of the state it leads to) with at most this many buffer locations; with more, by the one-look
#: option value (policies/pile_window.py).  Measured: with 1 location, exact, the worst 20-part two-strategy
#: plan +1.951% -> +0.776%; with 2 locations, along 40 seeded runs, it made r2-16x2 and r2-20x2 worse at 1-3
#: visible (+0.67% -> +2.14% at 1 visible on r2-16x2; docs/decisions.md).  Since the look's parts near a
#: frontier are taken first and windows go to 20 parts, it costs at one location too: along 40 seeded runs at
#: 1 visible on the lab's 40 two-strategy plans of 16-30 parts, off (0) took the mean gap at 16 parts +0.29%
#: -> +0.05% (the worst +1.17% -> +0.18%), at 20 +0.51% -> +0.07% (+1.52% -> +0.26%), on seven 25-part
#: plans +2.04% -> +0.99%, and at 30 r14-30x2 +2.89% -> +0.00%, r17-30x2 +3.74% -> +0.78%, r20-30x2 +1.79%
#: -> +0.00% (r8-30x2 +0.23% -> +1.09%); at 2 visible the mean +0.30% -> +0.18% at 16 parts, +0.40% ->
#: +0.37% at 20.  So 0: the one-look option value everywhere (docs/decisions.md).
PILE_LOOK_DEEPER_LOCATIONS = 0
#: Where a move keeping several strategies open is valued a look deeper (see PILE_LOOK_DEEPER_LOCATIONS), the
#: pile window's sizes stop at this many parts: the move is valued by the windows of the state it leads to,
#: the shake by the state's own, and larger windows make the two differ more.  With sizes up to 20 there,
#: exact at 1 visible and 1 location, r20-20x2 +0.525% -> +3.789%, r5-20x2 +0.158% -> +2.252%, r17-20x2
#: +0.151% -> +2.038% (at the start a buffering valued by a window of the whole plan, exact, against a
#: shake valued by windows of 18 of the 20 parts, 8% over the optimum's value).
PILE_DEEPER_PARTS = 12
#: Where several strategies are open and the buffer has at least this many locations, a strategy's pile
#: window takes first only the parts of a look that wait there for at most PILE_NEAR_UNITS remaining units; a
#: part deeper in that strategy's order is one of its window's others (policies/pile_window.py).  Taken first,
#: such a part brings its chain, the strategy's own frontier is lumped and never installed, and a move
#: closing that strategy wins the look.  Measured along 40 seeded runs (bench_window_gap.py, 2 locations) on
#: twelve 16-20-part two-strategy plans: at 2 visible the mean gap +1.68% -> +1.39% (the worst +3.97% ->
#: +2.19%), at 3 visible +1.68% -> +1.25% (+3.57% -> +1.82%); at 1 visible the same decisions on five of
#: them.  With one location see PILE_NEAR_VISIBLE.
PILE_NEAR_LOCATIONS = 2
#: Or with at least this many parts a look (one location): along the same runs at 2 visible and 1 location,
#: r5-20x2 +2.55% -> +0.59%, r20-16x2 +1.69% -> +0.91%, r14-16x2 +0.89% -> +0.31%, r2-20x2 +0.59% -> +0.15%,
#: r2-16x2 +0.83% -> +1.20%, r8-20x2 and r17-16x2 the same decisions; at 3 visible and 1 location the same
#: decisions on three plans.  At 1 visible and 1 location it is off (there the exact
#: lab's rows stand; along runs the same on r29-20x2 and r5-20x2, r20-16x2 +0.35% -> +0.42%).
PILE_NEAR_VISIBLE = 2
#: Remaining units a part of a look may wait for in a strategy and still be taken first by its pile window
#: (see PILE_NEAR_LOCATIONS).  2 and 3 were alike at 2 visible (the mean gap over the eight plans -0.46 and
#: -0.51 points), 2 the better at 3 visible (r5-20x2 +1.81% against +2.32%), 5 nearer the old rule.
PILE_NEAR_UNITS = 2
#: Where several strategies are open and the buffer has at least this many locations, the pile window's
#: programme may hold PILE_SEVERAL_FACTOR times PILE_WINDOW_STATES (policies/pile_window.py): there a window
#: of one strategy's frontier keeps the strategies it is closed in and every buffered combination, so the
#: cap holds 8-10 parts where the gap is made (the moves that close a strategy, at a run's first units).
#: With one location, or one strategy open, the cap and the decisions are as before.
PILE_SEVERAL_LOCATIONS = 2
#: See PILE_SEVERAL_LOCATIONS.  Measured along 40 seeded runs (bench_window_gap.py, 2 locations) on the twelve
#: 16-20-part two-strategy plans: at 2 visible the mean gap +1.39% -> +0.98% (plans over 1%: 9 -> 4, the worst
#: +2.19% -> +1.83%), at 3 visible +1.25% -> +0.96% (7 -> 4, +1.82% -> +1.67%); on r20-16x2 at 2 visible
#: the loss with both strategies open +1.42% -> +0.68% (windows of 8 parts -> 9-12); with 3 locations at 2
#: visible +1.45% -> +1.15% (eleven plans).  It costs the decisions with several open
#: (a run's first few): on r2-30x2 at 2 visible and 2 locations the first decision's windows 24 -> 137 ms
#: of CPU (load 5), the later decisions alike (a mean of 12.1 and 9.9 ms); within a budget the deadline
#: stops a larger window (the last size finished decides) and each open strategy's windows get their share
#: of the time left (policies/lumped.py).
PILE_SEVERAL_FACTOR = 3
#: Where the buffer has at least this many locations, without a deadline, the pile window's programme may
#: hold PILE_LOCATIONS_FACTOR times the states it may hold elsewhere (policies/pile_window.py): each location
#: multiplies the buffered combinations a window keeps, so the same cap holds fewer parts, and the gap is made
#: where a window too small buffers a part the optimum would not (a shake is dearer to it than to the
#: optimum: its lumped others wait unused).  Within a budget the cap is the usual one (the deadline would cut
#: the larger window and leave the smallest deciding).  1: with one location too (2 before, where it was
#: first measured).  Along 40 seeded runs with one location on the lab's two-strategy plans (bench_window_gap.py's
#: estimate, paired; the mean of 10 plans, the worst): at 1 visible, 16 parts +0.05% -> +0.00% (+0.18% ->
#: +0.00%), 20 parts +0.07% -> +0.00% (+0.26% -> +0.02%), 25 parts +0.78% -> +0.31% (+2.63% -> +1.43%;
#: r17-25x2 +2.01% -> +0.80%), 30 parts +0.34% -> +0.34%; at 2 visible 16 parts +0.18% -> +0.03%, 20 parts
#: +0.37% -> +0.07%; at 3 visible 16 parts +0.30% -> +0.11%, 20 parts (7 plans) +0.64% -> +0.17%
#: (docs/decisions.md).  It costs decisions without a budget as with more locations (KILBRID, TONGE70 at 1-3
#: visible: a mean of 12-25 ms -> 19-77 ms of CPU, the largest about 1 s).
PILE_MORE_LOCATIONS = 1
#: See PILE_MORE_LOCATIONS.  Along 200 seeded runs (regrets over the pile's optimum, policies/regret.py) a cap
#: of 100,000 (the other factors on top) put r26-20x2 at 1 visible and 3 locations at +0.107% from +0.903%.
#: Three times the cap, in the policy lab (benchmarks/policy_lab.py, the rows above 150,000 states estimated
#: from 500 runs): r26-20x2 +0.916% -> +0.171%, r2-20x2 there +0.711% -> +0.112%, r23-16x2 at 3 visible and
#: 2 locations +0.729% -> +0.072%, r25-20 at 2 and 3 +0.696% -> +0.266%, r23-16x2 at 2 and 3 +0.688% ->
#: +0.013%, r17-20x2 at 1 and 2 +0.682% -> +0.113%, r12-20 at 2 and 2 +0.559% -> +0.041%.  It costs the
#: decisions without a budget: along a seeded run on KILBRID a mean of 9-13 ms -> 22-81 ms of CPU (TONGE70
#: 27-60 ms), the largest under 1 s; within a 50 ms budget as before (docs/decisions.md).
PILE_LOCATIONS_FACTOR = 3
#: Before a run's first installation (nothing installed: states every run passes through, its start again
#: after each shake there), without a deadline, a pile window's programme may hold PILE_START_FACTOR times
#: the states it may hold elsewhere (policies/pile_window.py).  Exact in the policy lab
#: (benchmarks/fallback_diagnosis.py --bin pile, which sums the lab's value along the fallback's path):
#: r2-16x2 at 2 visible and 2 locations +1.052% -> +0.460%, r23-16x2 there +0.983% -> +0.306%, r11-16x2
#: +0.748% -> +0.342%; r20-16x2 and r26-16x2 at 1 visible and 2 locations +0.840/+0.808% -> +0.358/+0.342%;
#: r27-16 at 2 visible and 3 locations +0.909% -> +0.233%; r0-25 at 1 visible and 3 +1.045% -> +0.403%;
#: r29-20x2 at 1 visible and 1 location the same (+0.772%).  At the start alone (nothing buffered either)
#: r23-16x2 went to +1.125%: its start then buffered as the optimum does, into states the usual windows
#: misjudge.  It costs the decisions before the first installation: without a budget the largest along a
#: seeded run on KILBRID and TONGE70 took 74-158 ms of CPU (21-51 ms before); within a budget the cap is
#: the usual one.
PILE_START_FACTOR = 10
#: With at most PILE_EARLY_LOCATIONS buffer locations the start's larger cap (PILE_START_FACTOR, no deadline)
#: holds until PILE_EARLY_UNITS units are installed (policies/pile_window.py): the states of a run's first
#: installations are few, every run passes through them, and with one location a part buffered there early
#: blocks it for long (a window of 12 of 24 parts, the others lumped and never installed before it is
#: complete, valued buffering a deep part above a shake).  Along 40 seeded runs (the lab's two-strategy plans,
#: one location; docs/decisions.md): 25 parts, 1 visible, a mean of +0.310% -> +0.143% (r11-25x2 +1.43% ->
#: +0.40%, r17-25x2 +0.80% -> +0.17%), none further; 20 parts at 2 visible +0.073% -> +0.014%; 16 parts at
#: 3 visible +0.110% -> +0.030%.
PILE_EARLY_UNITS = 3
#: See PILE_EARLY_UNITS: the buffer locations up to which it applies (measured at one location; with more,
#: the other factors already multiply the cap nine times, and the early states are many more).
PILE_EARLY_LOCATIONS = 1
#: Predictions of a larger window that fits after the smallest, in the pile's and the weighted bin's
#: windows (policies/lumped.py; each solves one window, at most the state cap): trying 5, 8, 12 in turn
#: instead gave +2.8% on a 16-part two-strategy plan.
WINDOW_REFINE = 2
#: Windows predicted to fit that did not (their programme passed the cap) a state's search for its largest
#: window may meet, in the pile's and the weighted bin's windows (policies/lumped.py): after each, the
#: prediction is raised to what the miss proved and the next size is at most halfway from the last window
#: solved.  Before, a miss ended the search with the last window solved, often the smallest: with sizes up to
#: 20, on a 20-part two-strategy plan in the pile at 1 visible and 1 location, +5.81% over the optimum (exact)
#: against +0.13% with the retries (along 60 seeded runs).
WINDOW_MISSES = 3
#: Window plans' engines the pile's and the weighted bin's windows keep (by state and parts, policies/lumped.py):
#: a window's plan is listed to predict its states, then solved, and a state's looks ask for it again.
WINDOW_ENGINES = 64
#: States whose parts' remaining ancestors the frontier windows keep per plan (policies/window.py): a state's
#: windows of every size and strategy ask them, O(parts × strategies) each (on KILBRID at 3 visible about a
#: quarter of a pile window's decision before); a few hundred states are a run's recent ones.
WINDOW_ANCESTORS = 256

# ------------------------------------------------------------ the weighted bin's frontier window (policies/weighted_window.py)

#: The weighted window's sizes: as PILE_WINDOW_PARTS (its looks enumerated, not order statistics, so a
#: state costs more than the uniform window's).
WEIGHTED_WINDOW_PARTS = (4, 5, 6, 7, 8, 9, 10, 11, 12)
#: States the weighted window's programme may hold per size tried: counted, not timed.
WEIGHTED_WINDOW_STATES = 10_000
#: And at most this many looks over its states (a state enumerates its bin's looks, about 7 ns each: on
#: KILBRID at 3 visible the state cap alone let a decision take 121 ms of CPU; bench_fallback --bin weighted).
WEIGHTED_WINDOW_LOOKS = 500_000
#: Where several strategies are open, the weighted window values keeping them open by the state's looks
#: drawn by the parts' weights (window.best_seen_chances: the draws enumerated over the distinct weights),
#: enumerating at most this many draws (parts × distinct weights^visible; more: no option value).  30 parts
#: of 4 weights at 3 visible are 1,920 draws, 0.8 ms of CPU, 62 parts 3,968 draws, 1.7 ms (load 2.6 of 2
#: cores): so a decision's option stays within 2 ms, a twentieth of the window's share.  Measured along 40
#: seeded runs (bench_window_gap.py --bin weighted) on eight 16-20-part two-strategy plans: the mean gap at 2 visible and 1 location +1.14% -> +1.01%, at 3 visible +1.59% ->
#: +1.37% (r11-16x2 at 2 visible and 2 locations +1.34% -> +0.82%); at 1 visible the same on these runs.
#: The looks drawn evenly instead (the uniform bin's option) made the window worse (docs/decisions.md).
WEIGHTED_OPTION_DRAWS = 4_000
#: Where several strategies are open, with at least this many buffer locations or WEIGHTED_NEAR_VISIBLE parts
#: a look, a strategy's weighted window takes first only the parts of a look that wait there for at most
#: WEIGHTED_NEAR_UNITS remaining units (the pile's rule, PILE_NEAR_LOCATIONS; policies/lumped.py).  With the
#: option value, along the same 40 runs on the eight two-strategy plans, the mean gap at 3 visible and 2
#: locations +3.47% -> +2.38% (r5-20x2 +7.53% -> +1.77%), at 3 visible and 1 location +1.37% -> +0.99%, at 2
#: visible and 1 location +1.01% -> +0.79%, at 1 visible and 2 locations +1.95% -> +1.66%, at 2 visible and 2
#: locations +1.48% -> +1.41% (r2-16x2 +1.32% -> +2.48%, r8-20x2 +5.38% -> +3.97%).  At 1 visible and 1
#: location it is off (every part of the look taken first, as before).
WEIGHTED_NEAR_LOCATIONS = 2
#: See WEIGHTED_NEAR_LOCATIONS.
WEIGHTED_NEAR_VISIBLE = 2
#: Remaining units a part of a look may wait for in a strategy and still be taken first by its weighted
#: window (see WEIGHTED_NEAR_LOCATIONS): 3 was better than 2 (the mean gap over seven of the plans at 2
#: locations and 1, 2, 3 visible +1.90%, +1.59%, +2.61% against +2.02%, +1.79%, +2.74%; over the eight at 1
#: location and 2, 3 visible +0.79%, +0.99% against +0.82%, +1.07%).
WEIGHTED_NEAR_UNITS = 3

# ------------------------------------------------------------ the frontier window (policies/window.py)

#: Open strategies whose frontier windows a decision of the look-ahead's fallback solves (the first ones
#: in the plan's order; windows with the same parts solved once): the window is closed in the strategy
#: it is the frontier of (a window closed in none credits itself with orders its installations break),
#: and the one of least expected cost, its others a look and a move each, decides.  On the policy lab's
#: two-strategy plans both are solved (twice a one-strategy decision's work at most); on plans of many
#: strategies the work grows with this (each window at most ``len(WINDOW_PARTS) × WINDOW_STATES`` states).
WINDOW_STRATEGIES = 4
