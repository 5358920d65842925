// The exact optimum of the uniform bin (opportune.policies.optimal), compiled.
//
// The same recursion as the pure-Python OptimalSolver in a uniform bin, with the same floating-point
// operations in the same order, so both give the same doubles.  A state is (installed units,
// consistent strategies, buffer counts per part); the bin holds the rest.  A look is `visible` units
// drawn uniformly without replacement, and the robot's best non-shake move on it is the best of
// the visible parts' own best moves (install or buffer) and the buffer's best installation.  So no
// look is enumerated: with the bin's units ranked by their part's best move (ties by declaration
// order), the best visible unit is the j-th of n with probability C(n - j, k - 1) / C(n, k), and a
// part whose c units hold ranks r + 1 .. r + c is the best visible one with probability
// (C(n - r, k) - C(n - r - c, k)) / C(n, k).  The shake loop then runs over the parts in rank order:
//
//   V(s) = min over prefixes A of (c_look + sum_A p m + (1 - P_A) c_shake) / P_A.
//
// In a weighted bin (a unit of part i drawn with chance proportional to weights[i], one after another
// without replacement) the parts are ranked the same way, and a part's chance of being the best
// visible one is the sum, over the looks whose best-ranked part it is, of the look's probability; the
// looks of a bin and their probabilities are those of OptimalSolver._look_distribution (the draws
// enumerated depth first, each sorted look's probability accumulated in the order it is reached,
// the looks in lexicographic order), kept in a cache of at most `look_cache_bytes` bytes (cleared
// whole when full: its bytes are bounded whatever the plan).  The parts are ranked and the looks
// grouped by their best-ranked part in both programmes: the least over the prefixes of the groups is
// the least over the prefixes of the looks, and no look is sorted.
//
// Every value is memoised in one open-addressing table of 16-byte slots (a 64-bit code of the
// state, the value), at most half full: 32-64 bytes per state when reserved for the count known
// before the work, plus the (installed, strategies) pairs interned once.  A value goes into the
// table only once it is known, so a stop (the deadline, the state cap) leaves a table a later call
// goes on from.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include "memo_table.hpp"

namespace py = pybind11;

namespace {

using Clock = std::chrono::steady_clock;
using opportune_memo::PairIds;
using opportune_memo::PlanUnits;
using opportune_memo::Table;

struct OptimalTooLarge : std::runtime_error {
    using std::runtime_error::runtime_error;
};
struct OptimalTimeout : std::runtime_error {
    using std::runtime_error::runtime_error;
};
struct OptimalStuck : std::runtime_error {
    using std::runtime_error::runtime_error;
};

constexpr double INF = std::numeric_limits<double>::infinity();

// OptimalSolver._shake_loop, one (m, p) pair at a time in increasing m: the least over the prefixes
struct Prefixes {
    double look, shake;
    double acc_pm = 0.0, acc_p = 0.0, s = INF;
    bool step(double m, double p) {
        if (m == INF) return false;
        acc_pm += p * m;
        acc_p += p;
        s = std::min(s, (look + acc_pm + (1.0 - acc_p) * shake) / acc_p);
        return true;
    }
};

// The looks of one bin in a weighted bin, as OptimalSolver._look_distribution gives them: k parts per
// look (sorted), in lexicographic order, with their probabilities.
struct Looks {
    int k = 0;
    std::vector<uint8_t> parts;
    std::vector<double> p;
};

// The bins' looks, by bin code; at most `limit` bytes of looks in all (cleared whole before a bin's
// looks would pass it: one bin's looks, the largest those of the start, may be held beyond it).
class LookCache {
public:
    explicit LookCache(size_t limit) : limit_(limit) {}
    // bytes one cached look of k parts takes, and one cached bin (its map node and vectors)
    static constexpr size_t ENTRY_BYTES = 96;
    static size_t look_bytes(int k) { return sizeof(double) + (size_t)k; }

    const Looks& of(uint64_t code, const std::vector<int>& bin, const std::vector<double>& w, int k) {
        auto it = cache_.find(code);
        if (it != cache_.end()) return it->second;
        Looks looks = enumerate(bin, w, k);
        size_t need = looks.p.size() * look_bytes(k) + ENTRY_BYTES;
        if (bytes_ + need > limit_) {
            cache_.clear();
            bytes_ = 0;
        }
        bytes_ += need;
        return cache_.emplace(code, std::move(looks)).first->second;
    }
    size_t bytes() const { return bytes_; }

private:
    // Units drawn one after another without replacement, each with chance proportional to its part's
    // weight: every order of draws depth first (parts in declaration order), a sorted look's
    // probability the sum of its orders' in the order they are reached.  The same operations as
    // OptimalSolver._look_distribution: the mass summed over every part in declaration order, the
    // chance of a draw as prob * c * w / mass from left to right.
    static Looks enumerate(const std::vector<int>& bin, const std::vector<double>& w, int k) {
        std::vector<int> counts(bin);
        std::vector<uint8_t> taken;
        std::unordered_map<uint64_t, double> sums;  // by the sorted look's code (6 bits a part, first most significant)
        std::vector<std::pair<uint64_t, std::vector<uint8_t>>> seen;
        auto draw = [&](auto&& self, int depth, double prob) -> void {
            if (depth == k) {
                std::vector<uint8_t> look(taken);
                std::sort(look.begin(), look.end());
                uint64_t c = 0;
                for (uint8_t x : look) c = c << 6 | x;
                auto [it, fresh] = sums.try_emplace(c, 0.0);
                it->second = it->second + prob;
                if (fresh) seen.emplace_back(c, std::move(look));
                return;
            }
            double mass = 0.0;
            for (size_t i = 0; i < counts.size(); ++i) mass += (double)counts[i] * w[i];
            for (size_t i = 0; i < counts.size(); ++i) {
                int c = counts[i];
                if (!c) continue;
                counts[i] -= 1;
                taken.push_back((uint8_t)i);
                self(self, depth + 1, prob * (double)c * w[i] / mass);
                taken.pop_back();
                counts[i] += 1;
            }
        };
        draw(draw, 0, 1.0);
        std::sort(seen.begin(), seen.end());
        Looks out;
        out.k = k;
        out.parts.reserve(seen.size() * k);
        out.p.reserve(seen.size());
        for (auto& [c, look] : seen) {
            out.parts.insert(out.parts.end(), look.begin(), look.end());
            out.p.push_back(sums[c]);
        }
        return out;
    }

    size_t limit_, bytes_ = 0;
    std::unordered_map<uint64_t, Looks> cache_;
};

class OptimalCore : private PlanUnits {
public:
    OptimalCore(int n_units, std::vector<int> first, std::vector<int> quantity,
                std::vector<std::vector<uint64_t>> below, std::vector<double> move, double look, double shake,
                int visible, int capacity, std::vector<double> weights, size_t look_cache_bytes, int others,
                double other_move, double other_weight)
        : PlanUnits(n_units, std::move(first), std::move(quantity), std::move(below), std::move(move), look, shake,
                    visible, capacity),
          weights_(std::move(weights)), looks_(look_cache_bytes), others_(others), other_move_(other_move) {
        if (!weights_.empty()) {
            if ((int)weights_.size() != parts_) throw std::invalid_argument("weights need one entry per part");
            for (double w : weights_)
                if (!(w > 0.0) || w == INF) throw std::invalid_argument("every weight must be a positive finite number");
            // a look is coded in 6 bits a part (at most 64 parts): at most 10 parts in 64 bits
            if (visible_ > 10) throw std::invalid_argument("a weighted bin takes at most 10 visible parts");
        }
        // the others (a weighted bin's frontier window, opportune.policies.weighted_window): one more group
        // after the parts, its weight `other_weight`, buffered at `other_move`, never installed
        if (others_ < 0 || others_ > (1 << 20)) throw std::invalid_argument("the others' units are out of range");
        if (others_ > 0 && (weights_.empty() || parts_ >= 64))
            throw std::invalid_argument("the others are lumped in a weighted bin of at most 63 parts only");
        if (others_ > 0 && (!(other_weight > 0.0) || other_weight == INF))
            throw std::invalid_argument("the others' weight must be a positive finite number");
        groups_ = parts_ + (others_ > 0);
        if (others_ > 0) weights_.push_back(other_weight);
        most_others_ = capacity_ < 0 ? others_ : std::min(others_, capacity_);
        long double contents = buffers_ * (long double)(others_ + 1);  // a bin's others too: up to all of them
        if (contents > (long double)(uint64_t(1) << 62)) throw std::invalid_argument("too many buffer contents for 64-bit codes");
        contents_ = (uint64_t)contents;
        max_pairs_ = (~uint64_t(0) - 1) / contents_;
        // C(n, k) for n <= 64: at most C(64, 32) < 2^61, exact in 64 bits
        for (int n = 0; n <= 64; ++n) {
            binom_[n][0] = 1;
            for (int k = 1; k <= 64; ++k) binom_[n][k] = n == 0 ? 0 : binom_[n - 1][k - 1] + binom_[n - 1][k];
        }
    }

    double value(uint64_t mask, uint64_t cons, std::vector<int> buf, double seconds, long long max_states) {
        if ((int)buf.size() != groups_) throw std::invalid_argument("the buffer needs one count per part (and the others)");
        for (int i = 0; i < parts_; ++i) {
            if (buf[i] < 0 || buf[i] + __builtin_popcountll(mask & part_units_[i]) > quantity_[i])
                throw std::invalid_argument("a buffer count is out of range");
        }
        if (groups_ > parts_ && (buf[parts_] < 0 || buf[parts_] > most_others_))
            throw std::invalid_argument("the others buffered are out of range");
        if (mask & ~full_) throw std::invalid_argument("an installed unit is out of range");
        timed_ = seconds >= 0;
        if (timed_)
            deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
        max_states_ = max_states < 0 ? std::numeric_limits<size_t>::max() : (size_t)max_states;
        return V(mask, cons, buf);
    }

    void reserve(size_t n) {  // the values' table and, on a plan written as ways, the sets decided live or dead
        table_.reserve(n);
        reserve_ways(n);
    }
    // a plan written as ways: per part, its ways as (blockers, needs) masks (PlanUnits::set_ways)
    void set_ways(std::vector<std::vector<opportune_memo::WaysLiveness::Way>> ways) { PlanUnits::set_ways(std::move(ways)); }
    size_t states() const { return table_.size(); }
    size_t bytes() const { return table_.bytes() + pairs_.bytes() + looks_.bytes() + ways_bytes(); }
    // the bytes a programme of `states` states over `pairs` (installed, strategies) pairs holds once reserved
    static size_t bytes_for(size_t states, size_t pairs) { return Table::bytes_for(states) + pairs * PairIds::PAIR_BYTES; }

private:
    uint64_t code(uint64_t mask, uint64_t cons, const std::vector<int>& buf) {
        uint64_t id = pairs_.id(mask, cons, max_pairs_);
        if (id == ~uint64_t(0)) throw OptimalTooLarge("too many states for 64-bit codes");
        return id * contents_ + group_code(buf);
    }

    // a buffer's (or a bin's) counts, the others' count last where there are others
    uint64_t group_code(const std::vector<int>& counts) const {
        uint64_t c = buffer_code(counts);
        if (groups_ > parts_) c += (uint64_t)counts[parts_] * (uint64_t)buffers_;
        return c;
    }

    // OptimalSolver._value: V(s), the look's cost included
    double V(uint64_t mask, uint64_t cons, std::vector<int>& buf) {
        uint64_t c = code(mask, cons, buf);
        const double* cached = table_.find(c);
        if (cached) return *cached;
        if (mask == full_) {
            table_.put(c, 0.0);
            return 0.0;
        }
        // the clock and the cap at every new state, before its children (a descent stores many)
        if (timed_ && Clock::now() > deadline_) throw OptimalTimeout("the optimum's programme passed its deadline");
        if (table_.size() >= max_states_) throw OptimalTooLarge("over the state limit");
        int used = 0;
        for (int x : buf) used += x;
        bool free = capacity_ < 0 || used < capacity_;
        // each part in the bin: its best move (install from the bin, or buffer), in declaration order
        std::vector<std::tuple<double, int, int>> ranked;  // (best move, part, units in the bin)
        std::vector<int> bin(weights_.empty() ? 0 : groups_, 0);
        int n = 0;
        for (int i = 0; i < parts_; ++i) {
            int units = in_bin(mask, buf, i);
            if (units <= 0) continue;
            n += units;
            double best = INF;
            int u = next_unit(mask, i);
            uint64_t after = consistent_after(mask, cons, u);
            if (after) best = move_[i] + V(mask | uint64_t(1) << u, after, buf);
            if (free) {
                buf[i] += 1;
                double v = move_[i] + V(mask, cons, buf);
                buf[i] -= 1;
                best = std::min(best, v);
            }
            ranked.emplace_back(best, i, units);
            if (!weights_.empty()) bin[i] = units;
        }
        if (groups_ > parts_ && others_ > buf[parts_]) {  // the others in the bin: buffered if a location is free
            int units = others_ - buf[parts_];
            n += units;
            double best = INF;
            if (free && other_move_ < INF) {
                buf[parts_] += 1;
                best = other_move_ + V(mask, cons, buf);
                buf[parts_] -= 1;
            }
            ranked.emplace_back(best, parts_, units);
            bin[parts_] = units;
        }
        // the buffer's best installation (the same on every look)
        double from_buffer = INF;
        for (int i = 0; i < parts_; ++i) {
            if (!buf[i]) continue;
            int u = next_unit(mask, i);
            uint64_t after = consistent_after(mask, cons, u);
            if (!after) continue;
            buf[i] -= 1;
            double v = move_[i] + V(mask | uint64_t(1) << u, after, buf);
            buf[i] += 1;
            from_buffer = std::min(from_buffer, v);
        }
        double s = weights_.empty() ? shake_loop(ranked, n, from_buffer) : weighted_shake_loop(ranked, n, from_buffer, bin);
        if (s == INF) throw OptimalStuck("no look allows any action: the assembly cannot proceed");
        if (table_.size() >= max_states_) throw OptimalTooLarge("over the state limit");
        table_.put(c, s);
        return s;
    }

    // OptimalSolver._order_statistics and _shake_loop: the parts by rank, their chances of being the
    // best visible one, the least over the prefixes
    double shake_loop(std::vector<std::tuple<double, int, int>>& ranked, int n, double from_buffer) const {
        Prefixes run{look_, shake_};
        if (n == 0) {  // every unit left is in the buffer: no part is seen
            run.step(from_buffer, 1.0);
            return run.s;
        }
        std::sort(ranked.begin(), ranked.end());
        int k = std::min(visible_, n);
        double total = (double)(int64_t)binom_[n][k];
        int rank = 0;
        for (auto& [best, part, units] : ranked) {
            (void)part;
            uint64_t hits = binom_[n - rank][k] - binom_[n - rank - units][k];
            rank += units;
            if (!run.step(std::min(best, from_buffer), (double)(int64_t)hits / total)) break;
        }
        return run.s;
    }

    // The same in a weighted bin: a part's chance of being the best visible one summed over the bin's
    // looks in their order (OptimalSolver._order_statistics)
    double weighted_shake_loop(std::vector<std::tuple<double, int, int>>& ranked, int n, double from_buffer,
                               const std::vector<int>& bin) {
        if (n == 0) return shake_loop(ranked, n, from_buffer);
        std::sort(ranked.begin(), ranked.end());
        std::vector<int> rank_of(groups_, 0);
        for (size_t r = 0; r < ranked.size(); ++r) rank_of[std::get<1>(ranked[r])] = (int)r;
        const Looks& looks = looks_.of(group_code(bin), bin, weights_, std::min(visible_, n));
        std::vector<double> chance(ranked.size(), 0.0);
        const int k = looks.k;
        for (size_t j = 0; j < looks.p.size(); ++j) {
            const uint8_t* look = &looks.parts[j * k];
            int best = rank_of[look[0]];
            for (int d = 1; d < k; ++d) best = std::min(best, rank_of[look[d]]);
            chance[best] += looks.p[j];
        }
        Prefixes run{look_, shake_};
        for (size_t r = 0; r < ranked.size(); ++r)
            if (!run.step(std::min(std::get<0>(ranked[r]), from_buffer), chance[r])) break;
        return run.s;
    }

    std::vector<double> weights_;  // empty: a uniform bin; the others' last where there are others
    LookCache looks_;
    int others_, groups_ = 0, most_others_ = 0;
    double other_move_;
    uint64_t contents_ = 1, max_pairs_ = 0;
    uint64_t binom_[65][65] = {};
    PairIds pairs_;
    Table table_;
    bool timed_ = false;
    Clock::time_point deadline_;
    size_t max_states_ = 0;
};

}  // namespace

void bind_optimal(py::module_& m) {
    py::register_exception<OptimalTooLarge>(m, "OptimalCoreTooLarge", PyExc_RuntimeError);
    py::register_exception<OptimalTimeout>(m, "OptimalCoreTimeout", PyExc_RuntimeError);
    py::register_exception<OptimalStuck>(m, "OptimalCoreStuck", PyExc_RuntimeError);
    py::class_<OptimalCore>(m, "OptimalCore")
        .def(py::init<int, std::vector<int>, std::vector<int>, std::vector<std::vector<uint64_t>>, std::vector<double>,
                      double, double, int, int, std::vector<double>, size_t, int, double, double>(),
             py::arg("n_units"), py::arg("first"), py::arg("quantity"), py::arg("below"), py::arg("move"),
             py::arg("look"), py::arg("shake"), py::arg("visible"), py::arg("capacity"),
             py::arg("weights") = std::vector<double>{}, py::arg("look_cache_bytes") = size_t(0),
             py::arg("others") = 0, py::arg("other_move") = INF, py::arg("other_weight") = 1.0)
        .def("value", &OptimalCore::value, py::arg("mask"), py::arg("cons"), py::arg("buf"), py::arg("seconds"),
             py::arg("max_states"))
        .def("reserve", &OptimalCore::reserve, py::arg("states"))
        .def("set_ways", &OptimalCore::set_ways, py::arg("ways"))
        .def_static("bytes_for", &OptimalCore::bytes_for, py::arg("states"), py::arg("pairs"))
        .def_property_readonly("states", &OptimalCore::states)
        .def_property_readonly("bytes", &OptimalCore::bytes);
}
