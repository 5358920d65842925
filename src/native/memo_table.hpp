// What the compiled optimum programmes (pile.cpp, optimal.cpp) share: an open-addressing table of
// doubles by 64-bit code (16-byte slots, linear probing, at most half full), the plan in their terms,
// and the (installed, strategies) pairs interned once.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <stdexcept>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

namespace opportune_memo {

inline uint64_t mix(uint64_t x) {  // the splitmix64 finaliser: a well-spread slot for every code
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ULL;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

// Values by code: linear probing, power-of-two capacity, at most half full.  The slots come zeroed
// from calloc (a large block is mapped lazily by the system: reserving is immediate, a page is paid for
// when first written), so a code is kept as code + 1 and 0 marks an empty slot.
class Table {
public:
    struct Slot {
        uint64_t key;
        double val;
    };
    Table() { rehash(1024); }
    ~Table() { std::free(slots_); }
    Table(const Table&) = delete;
    Table& operator=(const Table&) = delete;
    const double* find(uint64_t code) const {
        uint64_t key = code + 1;
        for (size_t i = mix(key) & mask_;; i = (i + 1) & mask_) {
            if (slots_[i].key == key) return &slots_[i].val;
            if (slots_[i].key == 0) return nullptr;
        }
    }
    void put(uint64_t code, double v) {
        if (2 * (size_ + 1) > cap_) rehash(cap_ * 2);
        uint64_t key = code + 1;
        for (size_t i = mix(key) & mask_;; i = (i + 1) & mask_) {
            if (slots_[i].key == key || slots_[i].key == 0) {
                size_ += slots_[i].key == 0;
                slots_[i].key = key;
                slots_[i].val = v;
                return;
            }
        }
    }
    void reserve(size_t n) {
        size_t cap = cap_;
        while (cap < 2 * n) cap *= 2;
        if (cap > cap_) rehash(cap);
    }
    size_t size() const { return size_; }
    void clear() {
        std::fill(slots_, slots_ + cap_, Slot{0, 0.0});
        size_ = 0;
    }
    // the bytes of a table reserved for n values (what reserve(n) allocates on a new table)
    static size_t bytes_for(size_t n) {
        size_t cap = 1024;
        while (cap < 2 * n) cap *= 2;
        return cap * sizeof(Slot);
    }
    size_t bytes() const { return cap_ * sizeof(Slot); }

private:
    void rehash(size_t cap) {
        Slot* slots = static_cast<Slot*>(std::calloc(cap, sizeof(Slot)));
        if (!slots) throw std::bad_alloc();
        size_t m = cap - 1;
        for (size_t j = 0; j < cap_; ++j) {
            if (slots_[j].key == 0) continue;
            size_t i = mix(slots_[j].key) & m;
            while (slots[i].key != 0) i = (i + 1) & m;
            slots[i] = slots_[j];
        }
        std::free(slots_);
        slots_ = slots;
        cap_ = cap;
        mask_ = m;
    }
    Slot* slots_ = nullptr;
    size_t cap_ = 0, mask_ = 0, size_ = 0;
};

struct PairHash {
    size_t operator()(const std::pair<uint64_t, uint64_t>& k) const { return mix(k.first ^ mix(k.second)); }
};

// A plan written as ways (opportune.planning.ways.WaysTable): each part (one unit) goes in by one of its
// ways, (blockers, needs) masks: none of the blockers in yet, a part of each need in.  A set is live when
// it has a completion, decided exactly as WaysEngine.alive decides it: a part shut out (every way
// blocked) or the parts left locking each other: dead; else, with no needs anywhere, live; else live when
// a set one part larger is, every set decided kept (a value of 1 or 0 in a Table) up to `limit` sets, then
// forgotten whole (a cache: what is forgotten is decided again), so its bytes are known before the work.
class WaysLiveness {
public:
    using Way = std::pair<uint64_t, std::vector<uint64_t>>;
    WaysLiveness(int n, std::vector<std::vector<Way>> ways) : n_(n), ways_(std::move(ways)) {
        if ((int)ways_.size() != n_) throw std::invalid_argument("the ways need one list per part");
        full_ = n_ == 64 ? ~uint64_t(0) : (uint64_t(1) << n_) - 1;
        for (int i = 0; i < n_; ++i) {
            if (ways_[i].empty()) ways_[i].emplace_back(0, std::vector<uint64_t>{});  // none listed: one free way
            for (auto& [blockers, needs] : ways_[i]) {
                if ((blockers | (uint64_t(1) << i)) & ~full_) throw std::invalid_argument("a blocker is out of range");
                for (uint64_t x : needs) {
                    if (x & ~full_) throw std::invalid_argument("a need is out of range");
                    has_needs_ = true;
                }
                if (!blockers && needs.empty()) free_ |= uint64_t(1) << i;
            }
        }
    }

    bool can_go(uint64_t mask, int i) const {
        if (free_ >> i & 1) return true;
        for (auto& [blockers, needs] : ways_[i]) {
            if (blockers & mask) continue;
            bool ok = true;
            for (uint64_t x : needs) ok = ok && (x & mask);
            if (ok) return true;
        }
        return false;
    }

    uint64_t goes(uint64_t mask) const {
        uint64_t out = 0;
        for (uint64_t rest = full_ & ~mask; rest; rest &= rest - 1) {
            int i = __builtin_ctzll(rest);
            if (can_go(mask, i)) out |= uint64_t(1) << i;
        }
        return out;
    }

    bool live(uint64_t mask) {
        if (mask == full_) return true;
        if (const double* known = memo_.find(mask)) return *known != 0.0;
        bool found;
        if (shut_out(mask) || locked(mask)) found = false;
        else if (!has_needs_) found = true;
        else {
            found = false;
            for (uint64_t todo = goes(mask); todo && !found; todo &= todo - 1)
                found = live(mask | (todo & -todo));
        }
        if (memo_.size() >= limit_) memo_.clear();
        memo_.put(mask, found ? 1.0 : 0.0);
        return found;
    }

    // at most n sets kept (at least 512: a table's least, 1,024 slots, holds them), their table reserved at
    // once: Table::bytes_for(n) bytes
    void reserve(size_t n) {
        limit_ = std::max<size_t>(n, 512);
        memo_.reserve(limit_);
    }
    size_t bytes() const { return memo_.bytes(); }

private:
    // WaysTable.shut_out: a part not in whose every way has a blocker in
    bool shut_out(uint64_t mask) const {
        for (uint64_t rest = full_ & ~mask & ~free_; rest; rest &= rest - 1) {
            bool blocked = true;
            for (auto& w : ways_[__builtin_ctzll(rest)]) blocked = blocked && (w.first & mask);
            if (blocked) return true;
        }
        return false;
    }

    // WaysTable.locked: the parts left taken out last first while one can be (a way with no blocker in
    // the set nor among the others left); some remain
    bool locked(uint64_t mask) const {
        uint64_t rest = full_ & ~mask;
        while (rest) {
            uint64_t out = 0;
            for (uint64_t r = rest; r; r &= r - 1) {
                int i = __builtin_ctzll(r);
                for (auto& w : ways_[i])
                    if (!(w.first & mask) && !(w.first & rest & ~(uint64_t(1) << i))) {
                        out |= uint64_t(1) << i;
                        break;
                    }
            }
            if (!out) return true;
            rest &= ~out;
        }
        return false;
    }

    int n_;
    std::vector<std::vector<Way>> ways_;
    uint64_t full_ = 0, free_ = 0;
    bool has_needs_ = false;
    size_t limit_ = std::numeric_limits<size_t>::max();
    Table memo_;
};

// The plan as the programmes see it.  `first[i]`, `quantity[i]`: part i's units first ..
// first+quantity-1; `below[s][u]`: the units below unit u in strategy s; `move[i]`: the cost of moving
// a unit of part i; `capacity` < 0: none.  A buffer is a count per part, coded in the radix of the
// quantities (`radix_`; `buffers_` codes in all, as a long double for the callers' overflow checks).
struct PlanUnits {
    PlanUnits(int n_units, std::vector<int> first, std::vector<int> quantity, std::vector<std::vector<uint64_t>> below,
              std::vector<double> move, double look, double shake, int visible, int capacity)
        : n_units_(n_units), first_(std::move(first)), quantity_(std::move(quantity)), below_(std::move(below)),
          move_(std::move(move)), look_(look), shake_(shake), visible_(visible), capacity_(capacity) {
        parts_ = (int)first_.size();
        if (n_units_ < 1 || n_units_ > 64) throw std::invalid_argument("the compiled optimum takes 1 to 64 units");
        if (below_.empty() || below_.size() > 64) throw std::invalid_argument("between 1 and 64 strategies");
        if ((int)quantity_.size() != parts_ || (int)move_.size() != parts_ || parts_ == 0)
            throw std::invalid_argument("first, quantity and move need one entry per part");
        if (visible_ < 1) throw std::invalid_argument("at least one unit must be visible");
        for (auto& b : below_)
            if ((int)b.size() != n_units_) throw std::invalid_argument("below needs one mask per unit");
        full_ = n_units_ == 64 ? ~uint64_t(0) : (uint64_t(1) << n_units_) - 1;
        part_units_.resize(parts_);
        radix_.resize(parts_);
        for (int i = 0; i < parts_; ++i) {
            if (quantity_[i] < 1 || first_[i] < 0 || first_[i] + quantity_[i] > n_units_)
                throw std::invalid_argument("a part's units are out of range");
            radix_[i] = (uint64_t)buffers_;
            buffers_ *= quantity_[i] + 1;
            uint64_t units = quantity_[i] == 64 ? ~uint64_t(0) : ((uint64_t(1) << quantity_[i]) - 1);
            part_units_[i] = units << first_[i];
        }
    }

    int next_unit(uint64_t mask, int part) const {
        for (int u = first_[part]; u < first_[part] + quantity_[part]; ++u)
            if (!(mask >> u & 1)) return u;
        return -1;
    }

    // A plan written as ways: its table in place of the strategies' orders (every part one unit, one
    // "strategy" that stays open while the set is live).
    void set_ways(std::vector<std::vector<WaysLiveness::Way>> ways) {
        if (n_units_ != parts_) throw std::invalid_argument("a plan written as ways has parts of one unit");
        ways_ = std::make_unique<WaysLiveness>(n_units_, std::move(ways));
    }
    size_t ways_bytes() const { return ways_ ? ways_->bytes() : 0; }
    void reserve_ways(size_t n) {
        if (ways_) ways_->reserve(n);
    }

    uint64_t consistent_after(uint64_t mask, uint64_t cons, int unit) const {
        if (ways_)  // the set after must have a completion: a dead one is never entered
            return (cons & 1) && ways_->can_go(mask, unit) && ways_->live(mask | uint64_t(1) << unit) ? 1 : 0;
        uint64_t out = 0;
        for (size_t s = 0; s < below_.size(); ++s)
            if ((cons >> s & 1) && (below_[s][unit] & ~mask) == 0) out |= uint64_t(1) << s;
        return out;
    }

    uint64_t buffer_code(const std::vector<int>& buf) const {
        uint64_t b = 0;
        for (int i = 0; i < parts_; ++i) b += (uint64_t)buf[i] * radix_[i];
        return b;
    }

    // units of part i in the bin: neither installed nor buffered
    int in_bin(uint64_t mask, const std::vector<int>& buf, int i) const {
        return quantity_[i] - __builtin_popcountll(mask & part_units_[i]) - buf[i];
    }

    int n_units_, parts_ = 0;
    std::vector<int> first_, quantity_;
    std::vector<std::vector<uint64_t>> below_;
    std::vector<double> move_;
    double look_, shake_;
    int visible_, capacity_;
    uint64_t full_ = 0;
    long double buffers_ = 1;
    std::vector<uint64_t> part_units_, radix_;
    std::unique_ptr<WaysLiveness> ways_;  // a plan written as ways; null: the strategies' orders (below_)
};

// The (installed, strategies) pairs, numbered in the order first seen.
class PairIds {
public:
    // the pair's number, or ~0 where it would be the `most`-th or later
    uint64_t id(uint64_t mask, uint64_t cons, uint64_t most) {
        auto it = ids_.find({mask, cons});
        if (it != ids_.end()) return it->second;
        uint64_t id = pairs_.size();
        if (id >= most) return ~uint64_t(0);
        ids_.emplace(std::make_pair(mask, cons), id);
        pairs_.emplace_back(mask, cons);
        return id;
    }
    size_t size() const { return pairs_.size(); }
    // bytes a pair takes: the vector's entry and the hash map's node
    static constexpr size_t PAIR_BYTES = sizeof(std::pair<uint64_t, uint64_t>) + 48;
    size_t bytes() const { return pairs_.size() * PAIR_BYTES; }

private:
    std::unordered_map<std::pair<uint64_t, uint64_t>, uint64_t, PairHash> ids_;
    std::vector<std::pair<uint64_t, uint64_t>> pairs_;
};

}  // namespace opportune_memo

// What the uniform bin's programmes share at a state (window.cpp; optimal.cpp computes the same inline):
// the bin's parts ranked by their best move, the buffer's best installation, and the shake loop over them.
namespace opportune_memo {

// The least over prefixes A of the looks in increasing best move m:
// (c_look + sum_A p m + (1 - P_A) c_shake) / P_A, fed one (m, p) at a time.
struct ShakeLoop {
    double look, shake;
    double acc_pm = 0.0, acc_p = 0.0, value = std::numeric_limits<double>::infinity();
    // false once m is infinite (no later look allows a move either)
    bool step(double m, double p) {
        if (m == std::numeric_limits<double>::infinity()) return false;
        acc_pm += p * m;
        acc_p += p;
        value = std::min(value, (look + acc_pm + (1.0 - acc_p) * shake) / acc_p);
        return true;
    }
};

// Each part with units in the bin, in declaration order, with its best move: installing its next unit
// (`value` of the state after, plus its move) or, with a free location, buffering one; `ranked` gets
// (best move, part, units in the bin) and the bin's units are returned.  `value(mask, cons, buf)` is the
// programme's value of a state (the buffer counts changed in place and restored).
template <class Value>
int rank_parts(const PlanUnits& plan, uint64_t mask, uint64_t cons, std::vector<int>& buf, bool free, Value&& value,
               std::vector<std::tuple<double, int, int>>& ranked) {
    int n = 0;
    for (int i = 0; i < plan.parts_; ++i) {
        int units = plan.in_bin(mask, buf, i);
        if (units <= 0) continue;
        n += units;
        double best = std::numeric_limits<double>::infinity();
        int u = plan.next_unit(mask, i);
        uint64_t after = plan.consistent_after(mask, cons, u);
        if (after) best = plan.move_[i] + value(mask | uint64_t(1) << u, after, buf);
        if (free) {
            buf[i] += 1;
            double v = plan.move_[i] + value(mask, cons, buf);
            buf[i] -= 1;
            best = std::min(best, v);
        }
        ranked.emplace_back(best, i, units);
    }
    return n;
}

// The buffer's best installation (the same on every look): inf where none keeps a strategy.
template <class Value>
double best_from_buffer(const PlanUnits& plan, uint64_t mask, uint64_t cons, std::vector<int>& buf, Value&& value) {
    double best = std::numeric_limits<double>::infinity();
    for (int i = 0; i < plan.parts_; ++i) {
        if (!buf[i]) continue;
        int u = plan.next_unit(mask, i);
        uint64_t after = plan.consistent_after(mask, cons, u);
        if (!after) continue;
        buf[i] -= 1;
        double v = plan.move_[i] + value(mask | uint64_t(1) << u, after, buf);
        buf[i] += 1;
        best = std::min(best, v);
    }
    return best;
}

// A state given by a caller, checked: buffer counts within each part's units left, installed units in range.
inline void check_state(const PlanUnits& plan, uint64_t mask, const std::vector<int>& buf) {
    if ((int)buf.size() != plan.parts_) throw std::invalid_argument("the buffer needs one count per part");
    for (int i = 0; i < plan.parts_; ++i) {
        if (buf[i] < 0 || buf[i] + __builtin_popcountll(mask & plan.part_units_[i]) > plan.quantity_[i])
            throw std::invalid_argument("a buffer count is out of range");
    }
    if (mask & ~plan.full_) throw std::invalid_argument("an installed unit is out of range");
}

}  // namespace opportune_memo
