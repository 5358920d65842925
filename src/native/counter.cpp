// opportune._native: the counter's memoised recursion (Counter._f in engine/count.py) in C++.
//
// Same three rules as the pure-Python counter, same results (exact integers):
//   1. cut elements (comparable to every other element of the set) split it into blocks counted
//      separately and multiplied;
//   2. components (of the comparability graph) multiply, times the multinomial coefficient;
//   3. otherwise e(S) = sum over the minimal (direction 0) or maximal (direction 1) elements x of
//      e(S \ {x}).
// Sets are W-word bitsets (W = 1, 2, 4, 8, 16: up to 1024 elements); counts are unsigned big
// integers of 64-bit limbs; the memo is an open-addressing hash table whose slots hold the key and
// the count up to 4 words of key (counts past 127 bits in an arena), and past that the hash and
// where key and count lie in the arena (see Slot).  A set's children found missing are counted
// without a second look-up (see fresh).  A call
// stops with a status (no exception crosses into Python) when it would add more than `max_new`
// entries or outlive its time limit; what it stored stays, like the Python counter's memo.
// The clock is read by work done, not by entries: every loop whose length depends on the input
// (scans, components, big-integer products and sums, table and arena growth) adds its word
// operations to a tally, and the clock is read each CHECK_WORK of them (a few microseconds).
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <thread>
#include <type_traits>
#include <unordered_map>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <sys/mman.h>

namespace py = pybind11;

namespace {

using u64 = std::uint64_t;
using u128 = unsigned __int128;
using Clock = std::chrono::steady_clock;

struct Stop {
    int reason;  // 1: new-entry limit, 2: time limit
};

template <int W>
struct Bits {
    u64 w[W];

    static Bits zero() {
        Bits b;
        for (int i = 0; i < W; ++i) b.w[i] = 0;
        return b;
    }
    bool none() const {
        u64 x = 0;
        for (int i = 0; i < W; ++i) x |= w[i];
        return x == 0;
    }
    int count() const {
        int c = 0;
        for (int i = 0; i < W; ++i) c += __builtin_popcountll(w[i]);
        return c;
    }
    bool at_most_one() const {  // popcount <= 1
        int c = 0;
        for (int i = 0; i < W; ++i) {
            if (w[i] & (w[i] - 1)) return false;
            c += w[i] != 0;
        }
        return c <= 1;
    }
    Bits operator&(const Bits& o) const {
        Bits r;
        for (int i = 0; i < W; ++i) r.w[i] = w[i] & o.w[i];
        return r;
    }
    Bits operator|(const Bits& o) const {
        Bits r;
        for (int i = 0; i < W; ++i) r.w[i] = w[i] | o.w[i];
        return r;
    }
    Bits without(const Bits& o) const {
        Bits r;
        for (int i = 0; i < W; ++i) r.w[i] = w[i] & ~o.w[i];
        return r;
    }
    // Whether the two sets meet, looking at word `first` first: where they meet there (an element's
    // predecessors in the set tend to lie in the element's own word) the other W - 1 words are not read.
    bool meets(const Bits& o, int first) const {
        if (w[first] & o.w[first]) return true;
        u64 x = 0;
        for (int i = 0; i < W; ++i) x |= w[i] & o.w[i];
        return x != 0;
    }
    bool operator==(const Bits& o) const {
        for (int i = 0; i < W; ++i)
            if (w[i] != o.w[i]) return false;
        return true;
    }
    void set(int i) { w[i >> 6] |= u64(1) << (i & 63); }
    void flip(int i) { w[i >> 6] ^= u64(1) << (i & 63); }
    bool is_single(int i) const {  // == {i}
        for (int k = 0; k < W; ++k)
            if (w[k] != (k == (i >> 6) ? u64(1) << (i & 63) : 0)) return false;
        return true;
    }
    int lowest() const {
        for (int i = 0; i < W; ++i)
            if (w[i]) return i * 64 + __builtin_ctzll(w[i]);
        return -1;
    }
    u64 hash() const {  // splitmix64's finaliser over the words
        u64 h = 0;
        for (int i = 0; i < W; ++i) {
            h ^= w[i] + 0x9E3779B97F4A7C15ull * (i + 1);
            h ^= h >> 30;
            h *= 0xBF58476D1CE4E5B9ull;
            h ^= h >> 27;
            h *= 0x94D049BB133111EBull;
            h ^= h >> 31;
        }
        return h;
    }
    template <class F>
    void each(F f) const {
        for (int k = 0; k < W; ++k) {
            u64 x = w[k];
            while (x) {
                f(k * 64 + __builtin_ctzll(x));
                x &= x - 1;
            }
        }
    }
};

// A zero-filled buffer of T from mmap, in 2 MiB pages where the kernel allows: the memo is read at
// random, and with 4 KiB pages most look-ups in a memo of hundreds of megabytes also miss the TLB.
template <class T>
class Buffer {
   public:
    Buffer() = default;
    explicit Buffer(size_t n) { allocate(n); }
    Buffer(const Buffer&) = delete;
    Buffer& operator=(const Buffer&) = delete;
    Buffer(Buffer&& o) noexcept { swap(o); }
    Buffer& operator=(Buffer&& o) noexcept {
        swap(o);
        return *this;
    }
    ~Buffer() { release(); }
    void swap(Buffer& o) noexcept {
        std::swap(base_, o.base_);
        std::swap(bytes_, o.bytes_);
        std::swap(data_, o.data_);
        std::swap(n_, o.n_);
    }
    T* data() const { return data_; }
    size_t size() const { return n_; }
    size_t bytes() const { return bytes_; }
    T& operator[](size_t i) { return data_[i]; }
    const T& operator[](size_t i) const { return data_[i]; }

   private:
    void* base_ = nullptr;
    size_t bytes_ = 0;
    T* data_ = nullptr;
    size_t n_ = 0;

    void allocate(size_t n) {
        const size_t page = size_t(1) << 21;
        size_t want = n * sizeof(T);
        size_t bytes = want >= page ? want + page : want;
        void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (p == MAP_FAILED) throw std::bad_alloc();
        uintptr_t at = reinterpret_cast<uintptr_t>(p);
        if (want >= page) {
            at = (at + page - 1) & ~(page - 1);
#ifdef MADV_HUGEPAGE
            madvise(reinterpret_cast<void*>(at), want & ~(page - 1), MADV_HUGEPAGE);
#endif
        }
        base_ = p;
        bytes_ = bytes;
        data_ = reinterpret_cast<T*>(at);
        n_ = n;
    }
    void release() {
        if (base_) munmap(base_, bytes_);
        base_ = nullptr;
        data_ = nullptr;
        bytes_ = n_ = 0;
    }
};

// ---------------------------------------------------------------- unsigned big integers (limbs)
using Limbs = std::vector<u64>;

void trim(Limbs& a) {
    while (a.size() > 1 && a.back() == 0) a.pop_back();
}

void add_into(Limbs& acc, const u64* b, size_t nb) {
    if (acc.size() < nb) acc.resize(nb, 0);
    u64 carry = 0;
    size_t i = 0;
    for (; i < nb; ++i) {
        u128 t = (u128)acc[i] + b[i] + carry;
        acc[i] = (u64)t;
        carry = (u64)(t >> 64);
    }
    for (; carry && i < acc.size(); ++i) {
        u128 t = (u128)acc[i] + carry;
        acc[i] = (u64)t;
        carry = (u64)(t >> 64);
    }
    if (carry) acc.push_back(carry);
}

void mul_into(const Limbs& a, const u64* b, size_t nb, Limbs& out) {
    out.assign(a.size() + nb, 0);
    for (size_t i = 0; i < a.size(); ++i) {
        u64 carry = 0;
        u64 ai = a[i];
        if (!ai) continue;
        for (size_t j = 0; j < nb; ++j) {
            u128 t = (u128)ai * b[j] + out[i + j] + carry;
            out[i + j] = (u64)t;
            carry = (u64)(t >> 64);
        }
        size_t k = i + nb;
        while (carry) {
            u128 t = (u128)out[k] + carry;
            out[k] = (u64)t;
            carry = (u64)(t >> 64);
            ++k;
        }
    }
    trim(out);
}

void mul_small(Limbs& a, u64 m) {  // a *= m
    u64 carry = 0;
    for (auto& x : a) {
        u128 t = (u128)x * m + carry;
        x = (u64)t;
        carry = (u64)(t >> 64);
    }
    if (carry) a.push_back(carry);
}

void div_small(Limbs& a, std::uint32_t d) {  // exact division by d < 2^32, in 32-bit halves (no 128-bit division)
    u64 rem = 0;
    for (size_t i = a.size(); i-- > 0;) {
        u64 hi = (rem << 32) | (a[i] >> 32);
        u64 qh = hi / d;
        rem = hi % d;
        u64 lo = (rem << 32) | (a[i] & 0xFFFFFFFFull);
        u64 ql = lo / d;
        rem = lo % d;
        a[i] = (qh << 32) | ql;
    }
    trim(a);
}

// ---------------------------------------------------------------- the counter
template <int W>
class Counter {
   public:
    using B = Bits<W>;

    Counter(int n, const std::vector<std::string>& below, const std::vector<std::string>& above)
        : n_(n) {
        if (n < 0 || n > 64 * W) throw std::invalid_argument("poset too large for this width");
        if ((int)below.size() != n || (int)above.size() != n)
            throw std::invalid_argument("below and above need one mask per element");
        below_.resize(n);
        above_.resize(n);
        nbr_.resize(n);
        for (int i = 0; i < n; ++i) {
            below_[i] = unpack(below[i]);
            above_[i] = unpack(above[i]);
            nbr_[i] = below_[i] | above_[i];
        }
        acc_.resize(n + 2);
        tmp_.resize(n + 2);
        comps_.resize(n + 2);
        hs_.resize(n + 2);
        reset();
    }

    // Returns (status, value bytes or None, new entries): status 0 done, 1 entry limit, 2 time limit.
    // (The caller resets the memo when it is over its cap, between top-level counts: never here,
    // within one, where the recursions above the core rely on what it has stored.)
    py::tuple count(const std::string& mask, int direction, long long max_new, double seconds) {
        B s = unpack(mask);
        start_budget(max_new, seconds, direction);
        convex_ = direction != 2 && convex(s);
        if (convex_) make_covers();
        int status = 0;
        Val v = one();
        {
            py::gil_scoped_release release;
            try {
                v = rec(s, 0);
            } catch (const Stop& stop) {
                status = stop.reason;
            }
        }
        if (status) return py::make_tuple(status, py::none(), added_);
        return py::make_tuple(0, to_bytes(v), added_);
    }

    // Word operations done by the last call (a test measures how often the clock is read with it).
    long long work() const { return work_; }

    py::object lookup(const std::string& mask) const {
        B s = unpack(mask);
        if (s.at_most_one()) return to_bytes(one());
        const Slot* slot = find(s);
        if (!full(*slot)) return py::none();
        return to_bytes(val(*slot));
    }

    // Store the exact count of a set found by another method (the hub split, the down-set programme).
    void put(const std::string& mask, const std::string& value) {
        B s = unpack(mask);
        if (s.at_most_one() || value.empty() || value.size() % 8) return;
        if (full(*find(s))) return;
        Limbs v(value.size() / 8);
        std::memcpy(v.data(), value.data(), value.size());
        trim(v);
        timed_ = false;     // not the last call's deadline: a Stop must never leave put()
        store(s, v);
    }

    // Between decisions: grow the table now if `more` new entries would make it grow, so that a
    // decision never pays for the copy (a table of millions of slots takes tens of milliseconds).
    void reserve(long long more) {
        timed_ = false;
        while (crowded(size_ + size_t(std::max(0LL, more)))) grow();
    }

    // ------------------------------------------------------------ tail distributions (hub.py)
    // A new memo of tail distributions for the marked elements `marks`; returns its handle.
    int tails_new(const std::string& marks) {
        if (binom_.empty()) make_binomials();
        tails_.push_back(std::make_unique<Tails>());
        tails_.back()->marks = unpack(marks);
        fresh_memo(*tails_.back());
        return int(tails_.size()) - 1;
    }
    void tails_drop(int handle) {
        if (handle >= 0 && handle < (int)tails_.size()) tails_[handle].reset();
    }
    // (status, list of little-endian bytes or None, new count entries): the tail distribution of
    // `mask` (see TailCounter in engine/hub.py); status 0 done, 1 entry limit, 2 time limit.
    py::tuple tail(int handle, const std::string& mask, long long max_new, double seconds) {
        if (handle < 0 || handle >= (int)tails_.size() || !tails_[handle])
            throw std::invalid_argument("no such tail memo");
        B s = unpack(mask);
        Tails& tm = *tails_[handle];
        if ((s & tm.marks).none()) throw std::invalid_argument("the set holds no marked element");
        if (tm.bytes > TAIL_MAX_BYTES || tm.memo.size() > TAIL_BUCKETS) fresh_memo(tm);
        start_budget(max_new, seconds, 0);
        convex_ = false;    // (tail sets are any sets: scanned)
        int status = 0;
        const Vec* r = nullptr;
        {
            py::gil_scoped_release release;
            try {
                r = &tail_rec(tm, s);
            } catch (const Stop& stop) {
                status = stop.reason;
            }
        }
        if (status) return py::make_tuple(status, py::none(), added_);
        py::list out;
        for (const Limbs& v : *r)
            out.append(py::bytes(reinterpret_cast<const char*>(v.data()), 8 * v.size()));
        return py::make_tuple(0, out, added_);
    }

    size_t size() const { return size_; }
    // Bytes held: the count memo, its arenas, and every tail memo (distributions and buckets).
    size_t memory() const {
        size_t total = table_.bytes() + arena_cap_ * sizeof(u64) + next_.bytes() + arena_next_.bytes();
        for (const auto& tm : tails_)
            if (tm) total += tm->bytes + tm->memo.bucket_count() * sizeof(void*) + tm->memo.size() * (sizeof(B) + 32);
        return total;
    }
    // Forget every entry, the tail memos' too (their handles stay valid).
    void reset() {
        for (auto& tm : tails_)
            if (tm) fresh_memo(*tm);
        next_ = Buffer<Slot>();
        next_at_ = 0;
        arena_next_ = Buffer<u64>();
        arena_next_at_ = 0;
        table_ = Buffer<Slot>(1024);
        size_ = 0;
        arena_ = Buffer<u64>(1 << 16);
        arena_cap_ = 1 << 16;
        arena_size_ = 0;
    }

   private:
    // Word operations between two readings of the clock: a few microseconds of work.
    static constexpr long long CHECK_WORK = 1024;

    // Count `units` word operations of work; past the deadline, stop (status 2).  Callers only call
    // it where a stop leaves the memo whole (before storing, or between stored entries).
    void tick(long long units) {
        work_ += units;
        if (work_ >= next_check_) {
            next_check_ = work_ + CHECK_WORK;
            if (timed_ && Clock::now() > deadline_) throw Stop{2};
        }
    }

    void start_budget(long long max_new, double seconds, int direction) {
        added_ = 0;
        calls_ = 0;
        work_ = 0;
        next_check_ = CHECK_WORK;
        max_new_ = max_new < 0 ? std::numeric_limits<long long>::max() : max_new;
        timed_ = seconds >= 0 && seconds < 1e9;
        if (timed_) {
            deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(seconds));
        }
        dir_ = direction;
    }

    using Vec = std::vector<Limbs>;
    struct Hash {
        size_t operator()(const B& b) const { return b.hash(); }
    };
    struct Tails {
        B marks;
        std::unordered_map<B, Vec, Hash> memo;
        size_t bytes = 0;   // limbs held, roughly (the distributions dominate)
    };
    // A tail memo holds at most this many bytes of distributions (a simulation of ARC111 adds about
    // 2 KB an entry, 1.4 GB over ten trials unbounded).  Its buckets are reserved once it grows, so that
    // it never rehashes a large table inside a decision (rehashing 700,000 entries took 140 ms, past a 15 ms deadline);
    // a full memo is replaced, at the start of a call, by an empty one, and the old one is freed on a
    // thread of its own, for the same reason.
    static constexpr size_t TAIL_MAX_BYTES = size_t(512) << 20;
    static constexpr size_t TAIL_BUCKETS = size_t(1) << 20;

    static void fresh_memo(Tails& tm) {
        if (!tm.memo.empty()) {
            auto old = std::make_shared<std::unordered_map<B, Vec, Hash>>(std::move(tm.memo));
            std::thread([old]() mutable { old.reset(); }).detach();
        }
        tm.memo = std::unordered_map<B, Vec, Hash>();
        tm.bytes = 0;
    }

    const Vec& remember(Tails& tm, const B& s, Vec&& r) {
        size_t b = 64;
        for (const Limbs& v : r) b += 8 * v.size() + sizeof(Limbs);
        tm.bytes += b;
        // most tail memos stay small (hub searches make and drop many): reserve only for one that grows
        if (tm.memo.size() == 4096) tm.memo.reserve(TAIL_BUCKETS);
        return tm.memo.emplace(s, std::move(r)).first->second;
    }
    std::vector<std::unique_ptr<Tails>> tails_;
    std::vector<std::vector<Limbs>> binom_;  // Pascal's triangle up to n + 1
    long long calls_ = 0;

    void make_binomials() {
        binom_.resize(n_ + 2);
        for (int a = 0; a <= n_ + 1; ++a) {
            binom_[a].resize(a + 1);
            binom_[a][0] = binom_[a][a] = Limbs{1};
            for (int b = 1; b < a; ++b) {
                binom_[a][b] = binom_[a - 1][b - 1];
                const Limbs& o = binom_[a - 1][b];
                add_into(binom_[a][b], o.data(), o.size());
            }
        }
    }
    const Limbs& C(int a, int b) const { return binom_[a][b]; }

    // exact count of a set (no tail): the recursion, from depth 0 (no count is in progress)
    Limbs count_of(const B& s) {
        if (s.at_most_one()) return Limbs{1};
        Val v = rec(s, 0);
        return Limbs(v.p, v.p + v.len);
    }

    static void mul_to(Limbs& a, const Limbs& b) {
        Limbs out;
        mul_into(a, b.data(), b.size(), out);
        a.swap(out);
    }

    // out[c] += sum_{i+j=c} a[i] b[j] C(c, i) C(N-1-c, na-1-i), N = na + nb: the merge of two pieces
    // after the binomial scaling of hub.py's _merge/_merge_plain and its exact _unscale (the same
    // numbers: C(na-1,i) C(nb,j) C(N-1,nb) / C(N-1,c) = C(c,i) C(N-1-c, na-1-i)).
    void shuffle_into(Vec& out, const Vec& a, int na, const Vec& b, int nb) {
        int N = na + nb;
        if ((int)out.size() < N) out.resize(N, Limbs{0});
        Limbs term, tmp;
        for (size_t i = 0; i < a.size(); ++i) {
            // |a| x |b| products of big counts: one call can take a tenth of a second, so look at the clock
            // between rows (out is the caller's scratch: a stop leaves nothing half-stored)
            if (timed_ && Clock::now() > deadline_) throw Stop{2};
            if (a[i].size() == 1 && a[i][0] == 0) continue;
            for (size_t j = 0; j < b.size(); ++j) {
                if (b[j].size() == 1 && b[j][0] == 0) continue;
                int c = int(i + j);
                if (c >= N) break;
                mul_into(a[i], b[j].data(), b[j].size(), term);
                mul_into(term, C(c, int(i)).data(), C(c, int(i)).size(), tmp);
                const Limbs& k = C(N - 1 - c, na - 1 - int(i));
                mul_into(tmp, k.data(), k.size(), term);
                add_into(out[c], term.data(), term.size());
                tick((long long)(a[i].size() + C(c, int(i)).size() + k.size()) * (b[j].size() + 4));
            }
        }
    }

    static void pop_zeros(Vec& r) {
        while (!r.empty() && r.back().size() == 1 && r.back()[0] == 0) r.pop_back();
    }

    const Vec& tail_rec(Tails& tm, const B& s) {
        auto it = tm.memo.find(s);
        if (it != tm.memo.end()) return it->second;
        // an entry convolves vectors of big counts (tens of microseconds or more): look at the clock at every entry
        if (timed_ && Clock::now() > deadline_) throw Stop{2};
        const B& marks = tm.marks;
        int n = s.count();
        tick(3LL * n * W);
        B mins = B::zero(), cuts = B::zero();
        int top_cut = -1;
        s.each([&](int x) {
            if ((below_[x] & s).none()) mins.set(x);
            if (s.without(nbr_[x]).is_single(x)) cuts.set(x), top_cut = x;
        });
        Vec r;
        if (cuts.none()) {
            std::vector<B> comps;
            components(s, comps);
            if (comps.size() > 1) {
                // marked pieces merge pairwise; the unmarked ones form one block (multinomial x counts)
                bool have = false;
                int size = 0, plain_n = 0;
                Limbs plain_e{1};
                for (const B& c : comps) {
                    int k = c.count();
                    if (!(c & marks).none()) {
                        const Vec& d = tail_rec(tm, c);  // memo nodes stay put when the map grows
                        if (!have) {
                            r = d;
                            have = true;
                        } else {
                            // the later of the two marks is the last mark of the union
                            Vec out;
                            for (int side = 0; side < 2; ++side) {
                                const Vec& da = side ? d : r;
                                const Vec& db = side ? r : d;
                                int na = side ? k : size, nb = side ? size : k;
                                Vec suffix(db.size());
                                Limbs acc{0};
                                for (size_t j = db.size(); j-- > 0;) {
                                    add_into(acc, db[j].data(), db[j].size());
                                    suffix[j] = acc;
                                }
                                shuffle_into(out, da, na, suffix, nb);
                            }
                            r.swap(out);
                        }
                        size += k;
                    } else {
                        Limbs e = count_of(c);
                        mul_to(e, C(plain_n + k, k));
                        mul_to(plain_e, e);
                        plain_n += k;
                    }
                }
                if (plain_n) {
                    Vec block(plain_n + 1, plain_e);  // every position of the unmarked block, e orders each
                    Vec out;
                    shuffle_into(out, r, size, block, plain_n);
                    r.swap(out);
                }
                pop_zeros(r);
                return remember(tm, s, std::move(r));
            }
        }
        if (!cuts.none() && n > 1) {
            int cut = top_cut;  // any cut element splits s into below and above it
            B lo = s & below_[cut], hi = s & above_[cut];
            int nh = hi.count();
            if (!(hi & marks).none()) {
                Limbs e = count_of(lo);
                r = tail_rec(tm, hi);
                for (Limbs& v : r) mul_to(v, e);
            } else if (!(marks & single(cut)).none()) {
                r.assign(nh + 1, Limbs{0});
                Limbs e = count_of(lo);
                mul_to(e, count_of(hi));
                r[nh] = e;
            } else {
                Limbs e = count_of(hi);
                Vec d = tail_rec(tm, lo);
                r.assign(nh + 1, Limbs{0});
                for (Limbs& v : d) {
                    mul_to(v, e);
                    r.push_back(std::move(v));
                }
            }
        } else {
            Limbs last{0};
            mins.each([&](int x) {
                if (timed_ && Clock::now() > deadline_) throw Stop{2};
                B rest = s;
                rest.flip(x);
                if (!(rest & marks).none()) {
                    const Vec& d = tail_rec(tm, rest);  // memo nodes stay put when the map grows
                    if (r.size() < d.size()) r.resize(d.size(), Limbs{0});
                    for (size_t i = 0; i < d.size(); ++i) add_into(r[i], d[i].data(), d[i].size());
                } else {  // x is the last marked element
                    Limbs e = count_of(rest);
                    add_into(last, e.data(), e.size());
                }
            });
            if (!(last.size() == 1 && last[0] == 0)) {
                if ((int)r.size() < n) r.resize(n, Limbs{0});
                add_into(r[n - 1], last.data(), last.size());
            }
        }
        pop_zeros(r);
        return remember(tm, s, std::move(r));
    }

    // the connected components of the comparability graph on s (breadth-first, O(|s| W))
    void components(const B& s, std::vector<B>& comps) {
        comps.clear();
        B rest = s;
        while (!rest.none()) {
            int x = rest.lowest();
            B comp = B::zero();
            comp.set(x);
            B frontier = comp;
            while (!frontier.none()) {
                B grow = B::zero();
                frontier.each([&](int y) { grow = grow | (nbr_[y] & rest); });
                frontier = grow.without(comp);
                comp = comp | grow;
                tick(4 * W);
                // everything left is reached: the last frontier need not be expanded (usually the
                // largest, as comparability reaches most of a set in two rounds)
                if (rest.without(comp).none()) break;
            }
            rest = rest.without(comp);
            comps.push_back(comp);
        }
        tick((long long)s.count() * W);     // every element was in one frontier
    }

    // Whether the current count's set is convex (with a < b < c, a and c in the set, b is too): what
    // remains of an order always is, and removing a minimal or maximal element, components and the
    // blocks between cut elements keep it so.  Then fresh() finds a child's extremal elements from its
    // parent's (see there).  Other sets (a caller's arbitrary mask, tail distributions) are scanned.
    bool convex_ = false;
    std::vector<B> covering_[2];    // [0][x]: the elements covering x; [1][x]: those x covers

    bool convex(const B& s) const {     // O(|s| W)
        B down = B::zero(), up = B::zero();
        s.each([&](int x) {
            down = down | below_[x];
            up = up | above_[x];
        });
        return (down & up).without(s).none();
    }
    // Once, at the first convex count, outside the clock: O(n |below| W) word operations, at most 2^24
    // (about 10 ms) on 1,024 elements.
    void make_covers() {
        if (!covering_[0].empty()) return;
        covering_[0].assign(n_, B::zero());
        covering_[1].assign(n_, B::zero());
        for (int x = 0; x < n_; ++x) {
            B deeper = B::zero();   // elements below something below x: not covered by x
            below_[x].each([&](int y) { deeper = deeper | below_[y]; });
            below_[x].without(deeper).each([&](int y) {
                covering_[1][x].set(y);
                covering_[0][y].set(x);
            });
        }
    }

    static B single(int i) {
        B b = B::zero();
        b.set(i);
        return b;
    }

    // A count: its limbs, little-endian, in a slot or in the arena.  Valid until the next store (which
    // may move both): callers use it at once.
    struct Val {
        const u64* p;
        std::uint32_t len;
    };
    static Val one() {
        static const u64 kOne = 1;   // the count of every set of at most one element
        return Val{&kOne, 1};
    }

    // Two layouts of a table slot (a zero-filled slot is empty in both):
    //  * up to 4 words of key (orders of at most 256 elements): the key and the count inline, W + 2
    //    words, so that a look-up reads one place of memory.  Counts below 2^127 (most sets: those of
    //    mid-lattice sets of 64-element orders are far below it) sit in the slot; a larger one is in the
    //    arena, and the slot holds its offset and (flagged with the top bit) its number of limbs.  The
    //    empty set is never stored, so a zero key marks an empty slot.
    //  * past 4 words: 16 bytes, four to a cache line: the set's hash and where its entry lies in the
    //    arena (the set's W key words, then its count), so that a miss reads one line of the table,
    //    not the two or three lines of a key of 8 or 16 words.
    static constexpr bool INLINE = W <= 4;
    static constexpr u64 BIG = u64(1) << 63;
    struct SlotInline {
        u64 key[W];
        u64 v[2];   // the count (v[1] < 2^63), or: v[0] its offset in the arena, v[1] BIG | its limbs
    };
    struct SlotArena {
        u64 hash = 0;
        u64 off : 40;   // the count's first limb in the arena (its key is the W words before)
        u64 len : 24;   // limbs of the count; 0: empty
        SlotArena() : off(0), len(0) {}
    };
    using Slot = typename std::conditional<INLINE, SlotInline, SlotArena>::type;

    static bool full(const Slot& sl) {
        if constexpr (INLINE) {
            u64 x = 0;
            for (int i = 0; i < W; ++i) x |= sl.key[i];
            return x != 0;
        } else {
            return sl.len != 0;
        }
    }
    bool holds(const Slot& sl, const B& s, u64 h) const {   // a full slot: is its key s (hash h)?
        if constexpr (INLINE) {
            (void)h;
            for (int i = 0; i < W; ++i)
                if (sl.key[i] != s.w[i]) return false;
            return true;
        } else {
            return sl.hash == h && key_at(sl) == s;
        }
    }
    Val val(const Slot& sl) const {
        if constexpr (INLINE) {
            if (sl.v[1] & BIG) return Val{arena_.data() + sl.v[0], std::uint32_t(sl.v[1] & ~BIG)};
            return Val{sl.v, sl.v[1] ? 2u : 1u};
        } else {
            return Val{arena_.data() + sl.off, std::uint32_t(sl.len)};
        }
    }
    u64 slot_hash(const Slot& sl) const {
        if constexpr (INLINE) {
            B b;
            for (int i = 0; i < W; ++i) b.w[i] = sl.key[i];
            return b.hash();
        } else {
            return sl.hash;
        }
    }

    int n_;
    std::vector<B> below_, above_, nbr_;
    std::vector<Limbs> acc_, tmp_;  // scratch per recursion depth
    std::vector<std::vector<B>> comps_;
    std::vector<std::vector<u64>> hs_;  // the children's hashes, per recursion depth
    Buffer<Slot> table_;
    Buffer<Slot> next_;          // the doubled table while grow() fills it (empty otherwise)
    size_t next_at_ = 0;         // slots of table_ copied into next_ so far
    Buffer<u64> arena_next_;     // the larger arena while it is being filled
    size_t arena_next_at_ = 0;
    size_t size_ = 0;
    Buffer<u64> arena_;
    size_t arena_size_ = 0, arena_cap_ = 0;
    long long added_ = 0, max_new_ = 0;
    long long work_ = 0, next_check_ = 0;
    bool timed_ = false;
    Clock::time_point deadline_;
    int dir_ = 0;

    B unpack(const std::string& bytes) const {
        if (bytes.size() != 8 * W) throw std::invalid_argument("mask has the wrong number of bytes");
        B b;
        std::memcpy(b.w, bytes.data(), 8 * W);
        return b;
    }
    py::bytes to_bytes(Val v) const {
        return py::bytes(reinterpret_cast<const char*>(v.p), 8 * size_t(v.len));
    }

    // Whether `entries` would fill the table past its load: three quarters for inline slots (their
    // probes stay within a line or two), half for the 16-byte slots (whose probes read the arena too).
    bool crowded(size_t entries) const {
        return INLINE ? 4 * entries > 3 * table_.size() : 2 * entries > table_.size();
    }
    const Slot* find(const B& s) const { return find(s, s.hash()); }
    const Slot* find(const B& s, u64 h) const {
        size_t m = table_.size() - 1;
        size_t i = h & m;
        while (full(table_[i]) && !holds(table_[i], s, h)) i = (i + 1) & m;
        return &table_[i];
    }
    Slot* find(const B& s) { return const_cast<Slot*>(static_cast<const Counter*>(this)->find(s)); }
    const B& key_at(const Slot& sl) const { return *reinterpret_cast<const B*>(arena_.data() + sl.off - W); }

    // Double the table.  A table of millions of slots takes tens of milliseconds to copy: the copy
    // reads the clock as it goes and, past the deadline, stops the call with the old table whole
    // and still in use.  The copy made so far is kept and the next call that must grow goes on from
    // there (nothing is stored in between: every store grows first), so short calls in a row still
    // make progress, and growing never takes a timed call past its deadline.
    void grow() {
        if (next_.size() != table_.size() * 2) {
            next_ = Buffer<Slot>(table_.size() * 2);
            next_at_ = 0;
        }
        size_t m = next_.size() - 1;
        for (; next_at_ < table_.size(); ++next_at_) {
            size_t j = next_at_;
            if (!(j & 1023)) tick(1024 * 2);     // before slot j is copied: a stop resumes at j
            const Slot& sl = table_[j];
            if (!full(sl)) continue;
            size_t i = slot_hash(sl) & m;
            while (full(next_[i])) i = (i + 1) & m;
            next_[i] = sl;
        }
        table_.swap(next_);
        next_ = Buffer<Slot>();
        next_at_ = 0;
    }

    // A sum of counts: the counts of up to two limbs added in three words (no allocation, no loop),
    // longer ones into a big integer; the total is both.
    struct Sum {
        u64 w[3] = {0, 0, 0};
        void add(const Val& v, Limbs& big) {
            if (v.len > 2) {
                add_into(big, v.p, v.len);
                return;
            }
            u128 t = (u128)w[0] + v.p[0];
            w[0] = (u64)t;
            t = (u128)w[1] + (v.len > 1 ? v.p[1] : 0) + (u64)(t >> 64);
            w[1] = (u64)t;
            w[2] += (u64)(t >> 64);
        }
    };

    Val store(const B& s, const Limbs& value) { return store(s, value, s.hash()); }
    Val store(const B& s, const Limbs& value, u64 h) { return store(s, value.data(), value.size(), h); }
    // h: s.hash(); `value`: `len` limbs, the last nonzero (or one zero limb)
    Val store(const B& s, const u64* value, size_t len, u64 h) {
        // grow first (either may stop the call, and then nothing of this entry is stored)
        if (crowded(size_ + 1)) grow();
        if constexpr (INLINE) {
            if (len <= 2 && !(len == 2 && (value[1] & BIG))) {
                Slot* slot = const_cast<Slot*>(find(s, h));
                std::memcpy(slot->key, s.w, W * sizeof(u64));
                slot->v[0] = value[0];
                slot->v[1] = len == 2 ? value[1] : 0;
                ++size_;
                return val(*slot);
            }
        }
        // the key (in the arena past 4 words), then the count
        const size_t need = (INLINE ? 0 : W) + len;
        if (arena_size_ + need > arena_cap_) {
            // copied in pieces with the clock read between them, and resumed by the next call
            // after a stop, like grow() (the arena does not change until the copy is done)
            if (arena_next_.size() < arena_size_ + need || arena_next_at_ > arena_size_) {
                arena_next_ = Buffer<u64>(2 * (arena_size_ + need));
                arena_next_at_ = 0;
            }
            const size_t piece = size_t(1) << 15;
            while (arena_next_at_ < arena_size_) {
                tick((long long)piece / 4);
                size_t k = std::min(piece, arena_size_ - arena_next_at_);
                std::memcpy(arena_next_.data() + arena_next_at_, arena_.data() + arena_next_at_, k * sizeof(u64));
                arena_next_at_ += k;
            }
            arena_.swap(arena_next_);
            arena_cap_ = arena_.size();
            arena_next_ = Buffer<u64>();
            arena_next_at_ = 0;
        }
        const size_t off = arena_size_ + (INLINE ? 0 : W);
        if constexpr (!INLINE) std::memcpy(arena_.data() + arena_size_, s.w, W * sizeof(u64));
        std::memcpy(arena_.data() + off, value, len * sizeof(u64));
        arena_size_ += need;
        Slot* slot = const_cast<Slot*>(find(s, h));
        if constexpr (INLINE) {
            std::memcpy(slot->key, s.w, W * sizeof(u64));
            slot->v[0] = off;
            slot->v[1] = BIG | len;
        } else {
            slot->hash = h;
            slot->off = off;
            slot->len = len;
        }
        ++size_;
        return val(*slot);
    }

    Val rec(const B& s, int depth) { return rec(s, depth, s.hash()); }
    // h: s.hash(), computed once (a parent computed its children's for their look-ups already)
    Val rec(const B& s, int depth, u64 h) {
        if (s.at_most_one()) return one();
        {
            const Slot* slot = find(s, h);
            if (full(*slot)) return val(*slot);
        }
        return fresh(s, depth, h);
    }
    // The count of s (of at least two elements), known not to be in the memo.  A child s \ {x} that
    // the look-ups below found missing is counted here without looking again: nothing its siblings
    // count can store it (all they visit lacks their own removed element, which it holds), and the
    // look-up again, after a sibling's recursion evicted its slot, was a fifth of the time.
    //
    // `parent`, `removed`: s is parent's set less its extremal element `removed`, and `parent` the
    // extremal elements of that set on the recursion's side (or null).  On a convex count (see
    // convex_) the extremal elements of s are then found without scanning s: the parent's less the
    // removed one, plus those of the elements covering it (covered by it) that nothing in s precedes
    // (follows) -- one whose only predecessor in the parent's set was the removed element covers it,
    // as anything between the two would be in the set.
    Val fresh(const B& s, int depth, u64 h, const B* parent = nullptr, int removed = -1) {
        // budget: counted when a set is entered (every entered set is stored once finished)
        if (++added_ > max_new_) throw Stop{1};

        B mins = B::zero(), maxs = B::zero();
        B cuts = B::zero();  // elements comparable to every other element of s
        int k = 0, nmin = 0, nmax = 0;
        // only the side the recursion takes is scanned (both when it chooses per set)
        const bool want_min = dir_ != 1, want_max = dir_ != 0;
        if (parent) {
            B& ext = dir_ == 0 ? mins : maxs;
            const std::vector<B>& rel = dir_ == 0 ? below_ : above_;
            ext = *parent;
            ext.flip(removed);
            int seen = 0;
            (covering_[dir_][removed] & s).each([&](int y) {
                ++seen;
                if (!rel[y].meets(s, y >> 6)) ext.set(y);
            });
            k = s.count();
            (dir_ == 0 ? nmin : nmax) = ext.count();
            tick(4LL + 2LL * seen * W);
        } else {
            s.each([&](int x) {
                ++k;
                if (want_min && !below_[x].meets(s, x >> 6)) mins.set(x), ++nmin;
                if (want_max && !above_[x].meets(s, x >> 6)) maxs.set(x), ++nmax;
            });
        }
        // A cut element is comparable to every minimal element of s: it is the only one, or above all
        // of them (and alike for maximal ones).  So only the elements above every minimal element
        // (below every maximal one) are tested, when there are two or more: on sparse orders few or none.
        B cand = s;
        int tested = k;
        if (want_min && nmin > 1) mins.each([&](int x) { cand = cand & above_[x]; });
        if (want_max && nmax > 1) maxs.each([&](int x) { cand = cand & below_[x]; });
        if (!(cand == s)) tested = cand.count();
        cand.each([&](int x) {
            if (s.without(nbr_[x]).is_single(x)) cuts.set(x);
        });
        tick(4LL + 2LL * (k + tested + nmin + nmax) * W);
        // direction 2: per set, the side with fewer extremal elements
        const B& ext = dir_ == 0 ? mins : dir_ == 1 ? maxs : (nmax < nmin ? maxs : mins);
        Limbs& acc = acc_[depth];
        Limbs& tmp = tmp_[depth];
        if (!cuts.none()) {
            if (cuts == s) return store(s, Limbs{1}, h);
            // the cut elements form a chain: order them by how many elements of s lie below
            std::vector<std::pair<int, int>> chain;
            cuts.each([&](int z) { chain.emplace_back((below_[z] & s).count(), z); });
            std::sort(chain.begin(), chain.end());
            acc.assign(1, 1);
            B rest = s;
            auto times = [&](const B& block) {
                if (block.at_most_one()) return;
                Val v = rec(block, depth + 1);
                mul_into(acc, v.p, v.len, tmp);
                acc.swap(tmp);
                tick((long long)acc.size() * v.len);
            };
            for (auto& [_, z] : chain) {
                B block = rest & below_[z];
                rest = rest & above_[z];
                times(block);
            }
            times(rest);
            return store(s, acc, h);
        }
        // components of the comparability graph on s
        std::vector<B>& comps = comps_[depth];
        components(s, comps);
        if (comps.size() > 1) {
            // |s|! / (|C1|! ... |Cm|!) e(C1) ... e(Cm), with C1 the largest component:
            // (|C1|+1)(|C1|+2)...|s| / (|C2|! ... |Cm|!), so the work grows with the smaller
            // components only (a big component beside a few small ones is the common case, and
            // starting from |s|! cost hundreds of divisions of a long number per set).  Factors are
            // batched into products below 2^32; dividing by 2..|C| one at a time stays exact, and
            // every division comes after the whole product.
            int big = 0;
            for (size_t i = 1; i < comps.size(); ++i)
                if (comps[i].count() > comps[big].count()) big = (int)i;
            acc.assign(1, 1);
            u64 batch = 1;
            for (int f = comps[big].count() + 1; f <= k; ++f) {
                if (batch * (u64)f >> 32) {
                    mul_small(acc, batch);
                    tick(2LL * acc.size());
                    batch = 1;
                }
                batch *= (u64)f;
            }
            if (batch > 1) mul_small(acc, batch);
            batch = 1;
            for (size_t i = 0; i < comps.size(); ++i) {
                if ((int)i == big) continue;
                int ck = comps[i].count();
                for (int d = 2; d <= ck; ++d) {
                    if (batch * (u64)d >> 32) {
                        div_small(acc, (std::uint32_t)batch);
                        tick(2LL * acc.size());
                        batch = 1;
                    }
                    batch *= (u64)d;
                }
            }
            if (batch > 1) div_small(acc, (std::uint32_t)batch);
            for (const B& c : comps) {
                if (c.at_most_one()) continue;
                Val v = rec(c, depth + 1);
                mul_into(acc, v.p, v.len, tmp);
                acc.swap(tmp);
                tick((long long)acc.size() * v.len);
            }
            // Stored only as the count's root (which the caller looks up): below it, a split set is
            // found again from its components' entries for the price of a scan, and on sparse orders
            // most sets the recursion meets split (random sparse orders of 64 elements: a quarter of
            // the entries, and the table's misses fall with its size).  The value stays in this
            // depth's scratch, which the caller reads at once.
            if (depth > 0) {
                --added_;
                return Val{acc.data(), std::uint32_t(acc.size())};
            }
            return store(s, acc, h);
        }
        // Look the children up together, in passes, so that their memory is fetched in parallel: the
        // slots first, then the entries of the children already counted, whose counts are added;
        // only then are the others counted (a recursion goes deep and would evict what was fetched
        // for the siblings after it).
        std::vector<u64>& hs = hs_[depth];
        hs.clear();
        const size_t m = table_.size() - 1;
        ext.each([&](int x) {
            B t = s;
            t.flip(x);
            const u64 ht = t.hash();
            hs.push_back(ht);
            __builtin_prefetch(&table_[ht & m]);
        });
        if constexpr (!INLINE) {    // (inline slots hold the key and most counts: nothing more to fetch)
            for (u64 ht : hs) {
                for (size_t j = ht & m; table_[j].len; j = (j + 1) & m) {
                    if (table_[j].hash == ht) {
                        const u64* at = arena_.data() + table_[j].off;
                        __builtin_prefetch(at - W);
                        __builtin_prefetch(at);
                        break;
                    }
                }
            }
        }
        acc.assign(1, 0);
        Sum sum;
        B todo = B::zero();
        size_t i = 0, missed = 0;   // the hashes of the children still to count move to the front of hs
        ext.each([&](int x) {
            B t = s;
            t.flip(x);
            const u64 ht = hs[i++];
            Val v = one();
            if (!t.at_most_one()) {
                const Slot* slot = find(t, ht);
                if (!full(*slot)) {
                    todo.set(x);
                    hs[missed++] = ht;
                    return;
                }
                v = val(*slot);
            }
            sum.add(v, acc);
            tick(4LL + v.len);
        });
        i = 0;
        const bool hinted = convex_ && dir_ != 2;
        todo.each([&](int x) {      // in the same order as above
            B t = s;
            t.flip(x);
            Val v = fresh(t, depth + 1, hs[i++], hinted ? &ext : nullptr, x);
            sum.add(v, acc);
            tick(4LL + v.len);
        });
        if (acc.size() == 1 && acc[0] == 0 && !sum.w[2]) {     // the common case: no child past 128 bits
            const u64 small[2] = {sum.w[0], sum.w[1]};
            return store(s, small, sum.w[1] ? 2 : 1, h);
        }
        add_into(acc, sum.w, 3);
        trim(acc);
        return store(s, acc, h);
    }
};

template <int W>
void bind(py::module_& m, const char* name) {
    py::class_<Counter<W>>(m, name)
        .def(py::init<int, const std::vector<std::string>&, const std::vector<std::string>&>(),
             py::arg("n"), py::arg("below"), py::arg("above"))
        .def("count", &Counter<W>::count, py::arg("mask"), py::arg("direction"), py::arg("max_new"),
             py::arg("seconds"),
             "(status, little-endian value bytes or None, new entries); status 0 done, 1 entry limit, "
             "2 time limit")
        .def("lookup", &Counter<W>::lookup, py::arg("mask"))
        .def("put", &Counter<W>::put, py::arg("mask"), py::arg("value"))
        .def("tails_new", &Counter<W>::tails_new, py::arg("marks"))
        .def("tails_drop", &Counter<W>::tails_drop, py::arg("handle"))
        .def("tail", &Counter<W>::tail, py::arg("handle"), py::arg("mask"), py::arg("max_new"),
             py::arg("seconds"))
        .def("work", &Counter<W>::work, "word operations done by the last count or tail")
        .def("size", &Counter<W>::size)
        .def("memory", &Counter<W>::memory)
        .def("reset", &Counter<W>::reset)
        .def("reserve", &Counter<W>::reserve, "grow the table now for this many more entries")
        .def_property_readonly_static("words", [](py::object) { return W; });
}

}  // namespace

void bind_chains(py::module_& m);  // chains.cpp
void bind_relax(py::module_& m);   // relax.cpp
void bind_pile(py::module_& m);    // pile.cpp
void bind_optimal(py::module_& m); // optimal.cpp
void bind_window(py::module_& m);  // window.cpp

PYBIND11_MODULE(_native, m) {
    m.doc() = "Compiled core of opportune's order engine (see opportune.engine.native)";
    bind<1>(m, "Counter1");
    bind<2>(m, "Counter2");
    bind<4>(m, "Counter4");
    bind<8>(m, "Counter8");
    bind<16>(m, "Counter16");
    bind_chains(m);
    bind_relax(m);
    bind_pile(m);
    bind_optimal(m);
    bind_window(m);
}
