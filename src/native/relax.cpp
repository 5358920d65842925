// opportune._native: adaptive relaxation Monte Carlo (opportune.engine.relaxmc), compiled.
//
// The method of Talvitie, Kangas, Niinimäki & Koivisto ("Counting linear extensions in practice:
// MCMC versus exponential Monte Carlo", AAAI 2018).  Cut the order's elements into pieces of at most
// 64 elements and drop every constraint between two pieces: the relaxed order R has
//     e(R) = n! * prod_i e(P_i) / n_i!
// linear extensions, each piece counted exactly here.  A uniform linear extension of R is one of the
// order with probability p = e(P) / e(R); the driver estimates p from draws.
//
// Three parts:
//  * partition(): pieces of k elements, a random start improved by the best swap of two elements
//    between two pieces while a swap keeps more comparable pairs inside the pieces; best of `tries`.
//  * Piece: the exact count of a piece by the memoised recursion (split a set into its lowest
//    element's component and the rest, times a binomial; a connected set: sum over its minimal
//    elements), doubles (a piece of 64 elements has at most 64! < 1.3e89 linear extensions), in an
//    open-addressing table keyed by the set's bits.  Every stored set keeps what a sampler needs: its
//    minimal elements, or its two parts.
//  * Relaxation::sample(): a uniform linear extension of R built one element at a time from the
//    memos (a piece's next element: a part chosen with probability size / elements left, then a
//    minimal element x of a connected part with probability e(S \ x) / e(S)), rejected at the first
//    element whose predecessors in other pieces are not placed yet: most draws stop after a few
//    elements.
//
// Every loop whose length depends on the input reads the clock (a few microseconds apart at most),
// the memo stops before it would exceed its entry cap, and nothing throws into Python on a budget:
// the result carries a status.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <map>
#include <mutex>
#include <new>
#include <numeric>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "splitmix.hpp"

namespace py = pybind11;

namespace {

using u64 = std::uint64_t;
using Clock = std::chrono::steady_clock;

constexpr int MAX_PIECE = 64;      // a piece's sets are one machine word
constexpr int MAX_ORDER = 4096;    // what the partition and the draws take (sets of 64 words)

struct Rng {  // the project's stream (splitmix.hpp)
    u64 state;
    u64 next() { return opportune::splitmix64(state); }
    double uniform() { return opportune::uniform53(state); }  // [0, 1)
    // [0, m): the high word of a 64x64-bit product (bias below m / 2^64, immaterial here)
    u64 below(u64 m) { return u64((unsigned __int128)next() * m >> 64); }
};

Clock::time_point after(double seconds) {
    return Clock::now() + std::chrono::duration_cast<Clock::duration>(
                              std::chrono::duration<double>(std::min(std::max(0.0, seconds), 1e9)));
}

// Pascal's triangle up to 64 in doubles (exact up to C(64, 32) < 2^61 within rounding)
struct Binomials {
    double c[MAX_PIECE + 1][MAX_PIECE + 1];
    Binomials() {
        for (int n = 0; n <= MAX_PIECE; ++n) {
            c[n][0] = c[n][n] = 1.0;
            for (int k = 1; k < n; ++k) c[n][k] = c[n - 1][k - 1] + c[n - 1][k];
        }
    }
};
const Binomials BINOM;

// The order: strict predecessors (transitive) of every element as rows of `words` 64-bit words.
struct Order {
    int n = 0, words = 0;
    std::vector<u64> below, near;        // near: comparable (below or above)
    std::vector<std::vector<int>> covers;  // immediate predecessors

    Order(int n_, const std::vector<std::vector<int>>& preds) : n(n_) {
        if (n < 1 || n > MAX_ORDER) throw std::invalid_argument("an order of 1 to 4096 elements");
        if (int(preds.size()) != n) throw std::invalid_argument("one list of predecessors per element");
        words = (n + 63) / 64;
        below.assign(std::size_t(n) * words, 0);
        near.assign(std::size_t(n) * words, 0);
        for (int v = 0; v < n; ++v)
            for (int u : preds[v]) {
                if (u < 0 || u >= n || u == v) throw std::invalid_argument("a predecessor out of range");
                below[std::size_t(v) * words + u / 64] |= u64(1) << (u % 64);
                near[std::size_t(v) * words + u / 64] |= u64(1) << (u % 64);
                near[std::size_t(u) * words + v / 64] |= u64(1) << (v % 64);
            }
        // u covers-precedes v when u < v and no w has u < w < v: u not below any predecessor of v
        covers.resize(n);
        std::vector<u64> under(words);
        for (int v = 0; v < n; ++v) {
            std::fill(under.begin(), under.end(), 0);
            for (int u : preds[v])
                for (int w = 0; w < words; ++w) under[w] |= below[std::size_t(u) * words + w];
            for (int u : preds[v])
                if (!(under[u / 64] >> (u % 64) & 1)) covers[v].push_back(u);
            std::sort(covers[v].begin(), covers[v].end());
            covers[v].erase(std::unique(covers[v].begin(), covers[v].end()), covers[v].end());
        }
        // a predecessor list that is not transitively closed would make the pieces wrong
        for (int v = 0; v < n; ++v)
            for (int u : preds[v])
                for (int w = 0; w < words; ++w)
                    if (below[std::size_t(u) * words + w] & ~below[std::size_t(v) * words + w])
                        throw std::invalid_argument("the predecessor lists must be transitively closed");
    }
    bool comparable(int a, int b) const { return near[std::size_t(a) * words + b / 64] >> (b % 64) & 1; }
    bool less(int a, int b) const { return below[std::size_t(b) * words + a / 64] >> (a % 64) & 1; }
};

// ------------------------------------------------------------------------------------ partition

struct Partitioner {
    const Order& o;
    int k, m;
    std::vector<int> piece_of;
    std::vector<std::vector<int>> members;
    std::vector<int> cnt;                  // cnt[v * m + p]: elements comparable to v in piece p
    std::vector<std::vector<int>> nbr;     // comparable elements of each element
    struct Best { int gain, a, b; };
    std::vector<Best> best;                // best swap of each pair of pieces i < j (index i * m + j)

    Partitioner(const Order& order, int k_) : o(order), k(k_) {
        m = (o.n + k - 1) / k;
        nbr.resize(o.n);
        for (int v = 0; v < o.n; ++v)
            for (int u = 0; u < o.n; ++u)
                if (o.comparable(u, v)) nbr[v].push_back(u);
    }

    // the best swap of an element of piece i with one of piece j: the gain in comparable pairs inside
    // the pieces.  Moving v from i to j gains cnt[v][j] - cnt[v][i]; two comparable elements swapped
    // lose their own pair twice, so the few best of each side are paired and checked.
    Best compute(int i, int j) {
        constexpr int TOP = 6;
        std::pair<int, int> ti[TOP], tj[TOP];
        int ni = 0, nj = 0;
        auto push = [](std::pair<int, int>* t, int& nt, std::pair<int, int> x) {
            if (nt < TOP) t[nt++] = x;
            else if (x.first > t[TOP - 1].first) t[TOP - 1] = x;
            else return;
            for (int q = nt - 1; q > 0 && t[q].first > t[q - 1].first; --q) std::swap(t[q], t[q - 1]);
        };
        for (int v : members[i]) push(ti, ni, {cnt[std::size_t(v) * m + j] - cnt[std::size_t(v) * m + i], v});
        for (int v : members[j]) push(tj, nj, {cnt[std::size_t(v) * m + i] - cnt[std::size_t(v) * m + j], v});
        Best b{0, -1, -1};
        for (int x = 0; x < ni; ++x)
            for (int y = 0; y < nj; ++y) {
                int g = ti[x].first + tj[y].first - (o.comparable(ti[x].second, tj[y].second) ? 2 : 0);
                if (g > b.gain) b = {g, ti[x].second, tj[y].second};
            }
        return b;
    }

    // one random start improved to a local optimum; returns the comparable pairs inside the pieces
    // (-1: out of time)
    long long run(Rng& rng, Clock::time_point until, bool timed) {
        std::vector<int> perm(o.n);
        std::iota(perm.begin(), perm.end(), 0);
        for (int i = o.n - 1; i > 0; --i) std::swap(perm[i], perm[rng.below(u64(i) + 1)]);
        piece_of.assign(o.n, 0);
        members.assign(m, {});
        for (int i = 0; i < o.n; ++i) {
            piece_of[perm[i]] = i / k;
            members[i / k].push_back(perm[i]);
        }
        cnt.assign(std::size_t(o.n) * m, 0);
        for (int v = 0; v < o.n; ++v)
            for (int u : nbr[v]) ++cnt[std::size_t(v) * m + piece_of[u]];
        best.assign(std::size_t(m) * m, Best{0, -1, -1});
        for (int i = 0; i < m; ++i)
            for (int j = i + 1; j < m; ++j) best[std::size_t(i) * m + j] = compute(i, j);
        unsigned steps = 0;
        while (true) {
            if (timed && !(++steps & 15) && Clock::now() > until) return -1;
            int bi = -1, bj = -1, bg = 0;
            for (int i = 0; i < m; ++i)
                for (int j = i + 1; j < m; ++j)
                    if (best[std::size_t(i) * m + j].gain > bg) bg = best[std::size_t(i) * m + j].gain, bi = i, bj = j;
            if (bg <= 0) break;
            int a = best[std::size_t(bi) * m + bj].a, b = best[std::size_t(bi) * m + bj].b;
            *std::find(members[bi].begin(), members[bi].end(), a) = b;
            *std::find(members[bj].begin(), members[bj].end(), b) = a;
            piece_of[a] = bj;
            piece_of[b] = bi;
            for (int u : nbr[a]) --cnt[std::size_t(u) * m + bi], ++cnt[std::size_t(u) * m + bj];
            for (int u : nbr[b]) --cnt[std::size_t(u) * m + bj], ++cnt[std::size_t(u) * m + bi];
            // only the gains towards or from pieces bi and bj changed
            for (int c = 0; c < m; ++c) {
                if (c != bi) best[std::size_t(std::min(c, bi)) * m + std::max(c, bi)] = compute(std::min(c, bi), std::max(c, bi));
                if (c != bj && c != bi) best[std::size_t(std::min(c, bj)) * m + std::max(c, bj)] = compute(std::min(c, bj), std::max(c, bj));
            }
        }
        long long inside = 0;
        for (int v = 0; v < o.n; ++v) inside += cnt[std::size_t(v) * m + piece_of[v]];
        return inside / 2;
    }
};

// (pieces, comparable pairs inside them, tries run): the best of `tries` random starts, each improved
// by swaps; fewer tries when `seconds` (negative: no limit) pass, at least one finished if it can.
std::tuple<std::vector<std::vector<int>>, long long, int> partition(
        int n, const std::vector<std::vector<int>>& preds, int k, int tries, u64 seed, double seconds) {
    if (k < 1 || k > MAX_PIECE) throw std::invalid_argument("pieces of 1 to 64 elements");
    Order o(n, preds);
    py::gil_scoped_release release;
    Rng rng{seed};
    Partitioner part(o, std::min(k, n));
    auto until = after(seconds);
    std::vector<std::vector<int>> best;
    long long best_inside = -1;
    int done = 0;
    for (; done < std::max(1, tries); ++done) {
        long long inside = part.run(rng, until, seconds >= 0);
        if (inside < 0) break;
        if (inside > best_inside) best_inside = inside, best = part.members;
    }
    for (auto& p : best) std::sort(p.begin(), p.end());
    return {best, best_inside, done};
}

// ------------------------------------------------------------------------------------ one piece

struct Halt { int status; };  // 1: the entry cap, 2: the clock, 3: no memory

// What the threads counting the pieces share: the memos' bytes over all pieces, and the first
// halt (0: none), which stops the others at their next check.
struct Shared {
    std::atomic<std::size_t> bytes{0};
    std::atomic<int> halt{0};
};

// One thread's budget: the clock, the cap on the bytes of every piece's memos (one count, shared).
struct Budget {
    Clock::time_point until;
    bool timed;
    std::size_t max_bytes;        // the memos' allocations over all pieces
    Shared* shared;
    unsigned tick = 0;
    void entry() {  // one more entry: the clock and the other threads' halts, now and then
        if (!(++tick & 255)) {
            if (int h = shared->halt.load(std::memory_order_relaxed)) throw Halt{h};
            if (timed && Clock::now() > until) throw Halt{2};
        }
    }
    // `add` more bytes, if the cap allows (then counted; else nothing)
    bool take(std::size_t add) {
        std::size_t before = shared->bytes.fetch_add(add);
        if (before + add <= max_bytes) return true;
        shared->bytes.fetch_sub(add);
        return false;
    }
    void give(std::size_t bytes) { shared->bytes.fetch_sub(bytes); }
    // a vector of `size` items of `item` bytes about to take one more: grow it (doubled) if the cap
    // allows, before anything is allocated
    template <class V>
    void room(V& v, std::size_t more = 1) {
        if (v.size() + more <= v.capacity()) return;
        std::size_t cap = std::max<std::size_t>(64, std::max(2 * v.capacity(), v.size() + more));
        if (!take((cap - v.capacity()) * sizeof(typename V::value_type))) throw Halt{1};
        v.reserve(cap);
    }
};

// A reference to a set of a piece: >= 0, the index of its memo entry; < 0, the single element -ref-1.
using Ref = std::int32_t;

class Piece {
public:
    // A child of a connected set S (S minus one of its minimal elements) and, rounded to a float,
    // the share of e(S) of the children up to it: a draw picks a child from one cache line instead
    // of reading every child's count (which cost half the time of a draw), and reads the counts
    // only when its number falls within rounding of a boundary, so the choice is the exact one.
    struct Kid {
        Ref ref;
        float cum;
    };
    struct Node {
        u64 key;
        double value;
        u64 mins;          // connected: its minimal elements (0: not connected)
        Ref a, b;          // not connected: its lowest element's component and the rest;
                           // connected: a is where its children (S minus each minimal) start in kids_
    };

    explicit Piece(std::vector<u64> pred) : k_(int(pred.size())), pred_(std::move(pred)), near_(pred_) {
        for (int x = 0; x < k_; ++x)
            for (int y = 0; y < k_; ++y)
                if (pred_[x] >> y & 1) near_[y] |= u64(1) << x;
        full_ = k_ == 64 ? ~u64(0) : (u64(1) << k_) - 1;
    }
    int size() const { return k_; }
    std::size_t entries() const { return nodes_.size(); }
    std::size_t bytes() const {
        return nodes_.capacity() * sizeof(Node) + slots_.capacity() * sizeof(std::uint32_t) +
               kids_.capacity() * sizeof(Kid);
    }
    Ref root() const { return root_; }
    bool counted() const { return counted_; }

    double count(Budget& b) {
        if (!counted_) {
            root_ = ensure(full_, b);
            counted_ = true;
        }
        return value(root_);
    }

    double value(Ref r) const { return r < 0 ? 1.0 : nodes_[r].value; }
    int ones(Ref r) const { return r < 0 ? 1 : __builtin_popcountll(nodes_[r].key); }
    const Node& node(Ref r) const { return nodes_[r]; }
    const Kid* kids(const Node& nd) const { return kids_.data() + nd.a; }

private:
    int k_;
    std::vector<u64> pred_, near_;
    u64 full_;
    std::vector<Node> nodes_;
    std::vector<std::uint32_t> slots_;   // open addressing, linear probing: entry index + 1, 0 empty
    std::vector<Kid> kids_;              // the children of the connected sets, in the order of their minimals
    Ref root_ = 0;
    bool counted_ = false;

    static u64 hash(u64 x) {
        x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
        x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
        return x ^ (x >> 31);
    }
    Ref lookup(u64 s) const {
        if (slots_.empty()) return -1;
        std::size_t mask = slots_.size() - 1, i = hash(s) & mask;
        while (std::uint32_t e = slots_[i]) {
            if (nodes_[e - 1].key == s) return Ref(e - 1);
            i = (i + 1) & mask;
        }
        return -1;
    }
    Ref store(const Node& nd, const Kid* kids, int nk, Budget& b) {
        b.entry();
        if (nodes_.size() >= 0x7ffffff0u || kids_.size() + nk >= 0x7ffffff0u) throw Halt{1};
        if (2 * (nodes_.size() + 1) > slots_.size()) {  // load at most 1/2
            std::size_t size = std::max<std::size_t>(64, 2 * slots_.size());
            // before growing: both tables are alive while the entries move
            if (!b.take(size * sizeof(std::uint32_t))) throw Halt{1};
            std::vector<std::uint32_t> grown(size, 0);
            std::size_t mask = grown.size() - 1;
            for (std::size_t e = 0; e < nodes_.size(); ++e) {
                std::size_t i = hash(nodes_[e].key) & mask;
                while (grown[i]) i = (i + 1) & mask;
                grown[i] = std::uint32_t(e + 1);
            }
            b.give(slots_.size() * sizeof(std::uint32_t));
            slots_.swap(grown);
        }
        b.room(nodes_);
        b.room(kids_, std::size_t(nk));
        nodes_.push_back(nd);
        if (nk) {
            nodes_.back().a = Ref(kids_.size());
            kids_.insert(kids_.end(), kids, kids + nk);
        }
        std::size_t mask = slots_.size() - 1, i = hash(nd.key) & mask;
        while (slots_[i]) i = (i + 1) & mask;
        slots_[i] = std::uint32_t(nodes_.size());
        return Ref(nodes_.size() - 1);
    }
    u64 component(u64 s) const {  // the component of s's lowest element (comparability graph)
        u64 comp = s & -s, frontier = comp;
        while (frontier) {
            u64 grow = 0;
            for (u64 f = frontier; f; f &= f - 1) grow |= near_[__builtin_ctzll(f)];
            grow &= s & ~comp;
            comp |= grow;
            frontier = grow;
        }
        return comp;
    }
    Ref ensure(u64 s, Budget& b) {
        if ((s & (s - 1)) == 0) return -1 - __builtin_ctzll(s);
        Ref r = lookup(s);
        if (r >= 0) return r;
        u64 comp = component(s);
        Node nd{s, 0.0, 0, 0, 0};
        Kid kids[MAX_PIECE];
        double vals[MAX_PIECE];
        int nk = 0;
        if (comp != s) {
            Ref a = ensure(comp, b), c = ensure(s & ~comp, b);
            nd.a = a;
            nd.b = c;
            nd.value = value(a) * value(c) *
                       BINOM.c[__builtin_popcountll(s)][__builtin_popcountll(comp)];
        } else {
            for (u64 m = s; m; m &= m - 1) {
                int x = __builtin_ctzll(m);
                if (!(pred_[x] & s)) nd.mins |= u64(1) << x;
            }
            // the children's slots are fetched from memory together, not one miss after another
            // (lookups were most of a count's time)
            if (!slots_.empty()) {
                std::size_t at[MAX_PIECE], mask = slots_.size() - 1;
                int q = 0;
                for (u64 m = nd.mins; m; m &= m - 1, ++q) {
                    at[q] = hash(s & ~(m & -m)) & mask;
                    __builtin_prefetch(&slots_[at[q]]);
                }
                for (int i = 0; i < q; ++i)       // then the entries the slots name (most are there)
                    if (std::uint32_t e = slots_[at[i]]) __builtin_prefetch(&nodes_[e - 1]);
            }
            for (u64 m = nd.mins; m; m &= m - 1) {
                int x = __builtin_ctzll(m);
                kids[nk].ref = ensure(s & ~(u64(1) << x), b);
                vals[nk] = value(kids[nk].ref);
                nd.value += vals[nk++];
            }
            double cum = 0.0;
            for (int i = 0; i < nk; ++i) {
                cum += vals[i];
                kids[i].cum = float(cum / nd.value);
            }
        }
        return store(nd, kids, nk, b);
    }
};

// ------------------------------------------------------------------------------------ the relaxation

class Relaxation {
public:
    // pieces: the global ids of each piece (a partition of 0..n-1, 1 to 64 elements each);
    // preds[v]: v's strict predecessors, transitively closed.
    Relaxation(int n, const std::vector<std::vector<int>>& preds, std::vector<std::vector<int>> pieces)
        : n_(n), ids_(std::move(pieces)) {
        Order o(n, preds);
        piece_of_.assign(n_, -1);
        local_.assign(n_, -1);
        for (std::size_t i = 0; i < ids_.size(); ++i) {
            if (ids_[i].empty() || ids_[i].size() > MAX_PIECE)
                throw std::invalid_argument("a piece has 1 to 64 elements");
            for (std::size_t j = 0; j < ids_[i].size(); ++j) {
                int v = ids_[i][j];
                if (v < 0 || v >= n_ || piece_of_[v] >= 0) throw std::invalid_argument("the pieces must partition the elements");
                piece_of_[v] = int(i);
                local_[v] = int(j);
            }
        }
        for (int v = 0; v < n_; ++v)
            if (piece_of_[v] < 0) throw std::invalid_argument("the pieces must partition the elements");
        for (std::size_t i = 0; i < ids_.size(); ++i) {
            std::vector<u64> pred(ids_[i].size(), 0);
            for (std::size_t x = 0; x < ids_[i].size(); ++x)
                for (std::size_t y = 0; y < ids_[i].size(); ++y)
                    if (o.less(ids_[i][y], ids_[i][x])) pred[x] |= u64(1) << y;
            pieces_.emplace_back(std::move(pred));
        }
        // the constraints a draw checks: cover pairs between pieces (those inside hold by construction;
        // a placed element whose cover predecessors are placed has all its predecessors placed)
        cross_start_.assign(n_ + 1, 0);
        for (int v = 0; v < n_; ++v) {
            for (int u : o.covers[v])
                if (piece_of_[u] != piece_of_[v]) cross_.push_back(u);
            cross_start_[v + 1] = int(cross_.size());
        }
    }

    // Count every piece exactly: (status, natural log of e(R)); status 1: the memos would hold more
    // than `max_bytes` over all pieces (checked before each allocation), 2: out of `seconds`
    // (negative: no limit), 3: no memory.  What was counted stays; a later call goes on from there.
    // `threads` count pieces at once (each piece by one thread); the counts, and their sum in the
    // order of the pieces, are the same for any number (a stop on the cap or the clock may differ).
    std::pair<int, double> count(double seconds, long long max_bytes, int threads) {
        if (threads < 1 || threads > MAX_THREADS)
            throw std::invalid_argument("threads must be in 1.." + std::to_string(MAX_THREADS));
        Shared shared;
        shared.bytes = bytes();
        const auto until = after(seconds);
        const std::size_t cap = max_bytes < 0 ? ~std::size_t(0) : std::size_t(max_bytes);
        std::vector<double> counts(pieces_.size(), 0.0);
        std::atomic<std::size_t> next{0};
        auto worker = [&]() {
            Budget b{until, seconds >= 0, cap, &shared};
            int status = 0;
            for (std::size_t i = next++; i < pieces_.size() && !status; i = next++) {
                try {
                    counts[i] = pieces_[i].count(b);
                } catch (Halt& h) {
                    status = h.status;
                } catch (std::bad_alloc&) {
                    status = 3;
                }
                if (shared.halt.load()) return;
            }
            if (status) {
                int none = 0;
                shared.halt.compare_exchange_strong(none, status);
            }
        };
        std::vector<std::thread> pool;
        for (int t = 1; t < std::min<int>(threads, int(pieces_.size())); ++t) pool.emplace_back(worker);
        worker();
        for (std::thread& t : pool) t.join();
        if (int h = shared.halt.load()) return {h, NAN};
        double log_r = std::lgamma(n_ + 1.0);
        for (std::size_t i = 0; i < pieces_.size(); ++i)
            log_r += std::log(counts[i]) - std::lgamma(pieces_[i].size() + 1.0);
        counted_ = true;
        log_r_ = log_r;
        return {0, log_r};
    }

    std::size_t entries() const {
        std::size_t t = 0;
        for (const Piece& p : pieces_) t += p.entries();
        return t;
    }
    std::size_t bytes() const {
        std::size_t t = 0;
        for (const Piece& p : pieces_) t += p.bytes();
        return t;
    }
    int cross_pairs() const { return int(cross_.size()); }

    // Draw uniform linear extensions of R until `target_hits` of them are linear extensions of the
    // order, or `max_draws` are drawn, or `seconds` pass (negative: no limit; the clock read every 64
    // draws): (status 0 hits, 1 draws, 2 clock, -1 not counted; draws; hits; elements placed over
    // all draws, the work done).
    //
    // LANES draws advance in turns, one memory access each, and each prefetches what its next turn
    // reads: a draw chases pointers through memos of tens of megabytes, and one draw at a time waited
    // for every miss in turn.  Draw i has its own random stream (from `seed` and i), and outcomes are
    // taken in the order of i, so the result is the one of drawing 0, 1, 2, ... one after another.
    // `first` numbers the first draw: a call that goes on from an earlier one's draws passes how many
    // it made, and the two together are one run.
    std::tuple<int, long long, long long, long long> sample(long long max_draws, long long target_hits, double seconds, u64 seed,
                                                            long long first, int threads) {
        if (!counted_) return {-1, 0, 0, 0};
        if (first < 0) throw std::invalid_argument("first must be >= 0");
        if (threads < 1 || threads > MAX_THREADS)
            throw std::invalid_argument("threads must be in 1.." + std::to_string(MAX_THREADS));
        if (target_hits <= 0) return {0, 0, 0, 0};
        if (max_draws <= 0) return {1, 0, 0, 0};
        py::gil_scoped_release release;
        // Blocks of BLOCK draws, numbered from `first`: each thread takes the next block not taken,
        // draws it whole, and hands its outcomes over; they are merged in the order of the blocks,
        // so the stops fall on the same draw for any number of threads.  A block cut short by the
        // clock is dropped (its draws are made again by a call that goes on from this one).
        const long long blocks = (max_draws + BLOCK - 1) / BLOCK;
        auto until = after(seconds);
        std::mutex mu;
        std::map<long long, std::pair<std::vector<signed char>, std::vector<int>>> waiting;
        long long merged = 0, drawn = 0, hits = 0, steps = 0;
        int status = -1;
        std::atomic<long long> next_block{0};
        std::atomic<bool> stop{false};
        auto merge = [&](long long b, std::vector<signed char>&& out, std::vector<int>&& placed) {
            std::lock_guard<std::mutex> lock(mu);
            if (status >= 0) return;
            waiting.emplace(b, std::make_pair(std::move(out), std::move(placed)));
            for (auto it = waiting.find(merged); it != waiting.end(); it = waiting.find(merged)) {
                const auto& [o, pl] = it->second;
                for (std::size_t k = 0; k < o.size() && status < 0; ++k) {
                    ++drawn;
                    hits += o[k] == 2;
                    steps += pl[k];
                    if (hits >= target_hits) status = 0;
                    else if (drawn >= max_draws) status = 1;
                }
                waiting.erase(it);
                ++merged;
                if (status >= 0) {
                    stop = true;
                    return;
                }
            }
        };
        auto worker = [&]() {
            std::vector<Walk> lanes(LANES);
            std::vector<std::vector<long long>> stamps(LANES, std::vector<long long>(n_, -1));
            long long finished = 0;
            while (!stop.load(std::memory_order_relaxed)) {
                const long long b = next_block.fetch_add(1);
                if (b >= blocks) return;
                const long long lo = first + b * BLOCK, hi = first + std::min(max_draws, (b + 1) * BLOCK);
                std::vector<signed char> out(std::size_t(hi - lo), 0);
                std::vector<int> placed(std::size_t(hi - lo), 0);
                long long next_id = lo;
                int active = 0;
                for (Walk& w : lanes) {
                    w.live = next_id < hi;
                    if (w.live) {
                        begin(w, next_id++, seed);
                        ++active;
                    }
                }
                while (active > 0) {
                    for (int l = 0; l < LANES; ++l) {
                        Walk& w = lanes[l];
                        if (!w.live) continue;
                        std::vector<long long>& stamp = stamps[l];
                        const long long id = w.id;
                        int r = advance(w, [&](int v) {
                            ++placed[std::size_t(id - lo)];
                            for (int i = cross_start_[v]; i < cross_start_[v + 1]; ++i)
                                if (stamp[cross_[i]] != id) return false;
                            stamp[v] = id;
                            return true;
                        });
                        if (r == 0) continue;
                        out[std::size_t(id - lo)] = r > 0 ? 2 : 1;
                        if (!(++finished & 63)) {
                            if (stop.load(std::memory_order_relaxed)) return;
                            if (seconds >= 0 && Clock::now() > until) {
                                stop = true;
                                return;
                            }
                        }
                        w.live = next_id < hi;
                        if (w.live) begin(w, next_id++, seed);
                        else --active;
                    }
                }
                merge(b, std::move(out), std::move(placed));
            }
        };
        std::vector<std::thread> pool;
        for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
        worker();
        for (std::thread& t : pool) t.join();
        if (status < 0) status = drawn >= max_draws ? 1 : 2;
        return {status, drawn, hits, steps};
    }

    // One uniform linear extension of R, whole (no rejection): the global ids in order (tests).
    std::vector<int> extension(u64 seed) {
        if (!counted_) throw std::logic_error("count the pieces first");
        std::vector<int> out;
        Walk w;
        begin(w, 0, seed);
        while (!advance(w, [&](int v) { out.push_back(v); return true; })) {}
        return out;
    }

    double log_count() const { return log_r_; }

private:
    int n_;
    std::vector<std::vector<int>> ids_;
    std::vector<int> piece_of_, local_;
    std::vector<Piece> pieces_;
    std::vector<int> cross_, cross_start_;
    double log_r_ = NAN;
    bool counted_ = false;
    static constexpr int LANES = 8;   // draws in progress at once in sample()
    static constexpr long long BLOCK = 1024;   // draws a thread of sample() takes at a time
    static constexpr int MAX_THREADS = 256;

    // A draw in progress: its parts (a set of a piece, by reference, its piece and size), the
    // elements left, and where it stands: 0, choose a part; 1, at the part's set (split it if it is
    // not connected); 2, at the children of a connected set (place one of its minimal elements).
    struct Walk {
        std::vector<Ref> ref;
        std::vector<int> piece, size;
        Rng rng{0};
        long long id = 0;
        int left = 0, stage = 0;
        bool live = false;   // a draw is in progress (sample())
        std::size_t j = 0;   // the part chosen
        u64 r = 0;           // the position chosen within it
    };

    // Draw `id`'s random stream: splitmix64 of the seed and the draw's number.
    void begin(Walk& w, long long id, u64 seed) const {
        u64 st = seed ^ (0x9E3779B97F4A7C15ULL * u64(id + 1));
        w.rng = Rng{opportune::splitmix64(st)};
        w.id = id;
        w.left = n_;
        w.stage = 0;
        w.ref.clear();
        w.piece.clear();
        w.size.clear();
        for (std::size_t i = 0; i < pieces_.size(); ++i) {
            w.ref.push_back(pieces_[i].root());
            w.piece.push_back(int(i));
            w.size.push_back(pieces_[i].size());
        }
    }

    // One memory access of a draw of a uniform linear extension of R: 0 while it goes on, 1 when it
    // is whole, -1 when `take` refused an element (each placed element is handed to `take`).  The
    // next element lies in a part with probability size / elements left (a uniform interleaving of
    // the parts' own uniform extensions); a part that is not connected splits in two first; a
    // connected part S starts with its minimal x with probability e(S \ x) / e(S).  What the next
    // turn reads is prefetched.
    template <class Take>
    int advance(Walk& w, Take&& take) {
        if (w.stage == 0) {
            w.r = w.rng.below(u64(w.left));
            std::size_t j = 0;
            while (w.r >= u64(w.size[j])) w.r -= w.size[j++];
            w.j = j;
            w.stage = 1;
            Ref ref = w.ref[j];
            if (ref >= 0) {
                __builtin_prefetch(&pieces_[w.piece[j]].node(ref));
                return 0;
            }
        }
        const std::size_t j = w.j;
        const Piece& p = pieces_[w.piece[j]];
        Ref ref = w.ref[j];
        int x;
        if (w.stage == 1) {
            if (ref >= 0 && p.node(ref).mins == 0) {  // not connected: split, follow r
                const Piece::Node& nd = p.node(ref);
                int sa = p.ones(nd.a);
                w.ref.push_back(nd.b);
                w.piece.push_back(w.piece[j]);
                w.size.push_back(w.size[j] - sa);
                w.size[j] = sa;
                if (w.r < u64(sa)) {
                    ref = nd.a;
                } else {
                    w.r -= sa;
                    ref = nd.b;
                    // the part followed is the new last one
                    std::swap(w.ref[j], w.ref.back());
                    std::swap(w.size[j], w.size.back());
                    w.ref.back() = nd.a;
                }
                w.ref[j] = ref;
                if (ref >= 0) {
                    __builtin_prefetch(&p.node(ref));
                    return 0;
                }
            }
            if (ref >= 0) {       // connected: its children next
                __builtin_prefetch(p.kids(p.node(ref)));
                w.stage = 2;
                return 0;
            }
            // a single element: the part is used up
            x = -1 - ref;
            std::size_t last = w.ref.size() - 1;
            w.ref[j] = w.ref[last];
            w.piece[j] = w.piece[last];
            w.size[j] = w.size[last];
            w.ref.pop_back();
            w.piece.pop_back();
            w.size.pop_back();
        } else {
            const Piece::Node& nd = p.node(ref);
            const Piece::Kid* kid = p.kids(nd);
            int last = __builtin_popcountll(nd.mins) - 1, i = 0;
            double u = w.rng.uniform();
            while (i < last && u >= double(kid[i].cum)) ++i;
            // the floats are within 1e-7 of the exact shares: nearer a boundary than 1e-6, the
            // counts decide, as they always would
            if ((i > 0 && u - double(kid[i - 1].cum) < 1e-6) || (i < last && double(kid[i].cum) - u < 1e-6)) {
                double v = u * nd.value;
                for (i = 0; i < last; ++i) {
                    v -= p.value(kid[i].ref);
                    if (v < 0) break;
                }
            }
            u64 m = nd.mins;
            for (int q = 0; q < i; ++q) m &= m - 1;
            x = __builtin_ctzll(m);
            Ref next = kid[i].ref;
            w.ref[j] = next;
            --w.size[j];
            if (next >= 0) __builtin_prefetch(&p.node(next));
        }
        w.stage = 0;
        if (!take(ids_[&p - pieces_.data()][x])) return -1;
        return --w.left > 0 ? 0 : 1;
    }
};

}  // namespace

void bind_relax(py::module_& m) {
    m.def("armc_partition", &partition, py::arg("n"), py::arg("preds"), py::arg("k"), py::arg("tries"),
          py::arg("seed"), py::arg("seconds"),
          "(pieces, comparable pairs inside them, tries run): pieces of at most k elements, the best of "
          "`tries` random starts improved by swaps");
    py::class_<Relaxation>(m, "ArmcRelaxation")
        .def(py::init<int, const std::vector<std::vector<int>>&, std::vector<std::vector<int>>>(),
             py::arg("n"), py::arg("preds"), py::arg("pieces"))
        .def("count", &Relaxation::count, py::arg("seconds"), py::arg("max_bytes"), py::arg("threads") = 1,
             py::call_guard<py::gil_scoped_release>(),
             "count every piece exactly: (status, log e(R)), the same for any number of threads")
        .def("entries", &Relaxation::entries, "memo entries over all pieces")
        .def("bytes", &Relaxation::bytes, "bytes the memos hold (their capacity)")
        .def("cross_pairs", &Relaxation::cross_pairs, "cover pairs between two pieces (0: R is the order)")
        .def("sample", &Relaxation::sample, py::arg("max_draws"), py::arg("target_hits"), py::arg("seconds"),
             py::arg("seed"), py::arg("first") = 0, py::arg("threads") = 1,
             "(status, draws, hits, elements placed): the same for any number of threads, but for a stop on the clock")
        .def("extension", &Relaxation::extension, py::arg("seed"), "one uniform linear extension of R");
}
