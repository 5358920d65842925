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
using opportune_memo::PairHash;
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
// bytes an interned (installed, strategies) pair takes: the vector's entry and the hash map's node
constexpr size_t PAIR_BYTES = sizeof(std::pair<uint64_t, uint64_t>) + 48;

class OptimalCore {
public:
    // `first[i]`, `quantity[i]`: part i's units first .. first+quantity-1; `below[s][u]`: the units
    // below unit u in strategy s; `move[i]`: the cost of moving a unit of part i; `capacity` < 0: none.
    OptimalCore(int n_units, std::vector<int> first, std::vector<int> quantity,
                std::vector<std::vector<uint64_t>> below, std::vector<double> move, double look, double shake,
                int visible, int capacity)
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
        long double buffers = 1;
        part_units_.resize(parts_);
        radix_.resize(parts_);
        for (int i = 0; i < parts_; ++i) {
            if (quantity_[i] < 1 || first_[i] < 0 || first_[i] + quantity_[i] > n_units_)
                throw std::invalid_argument("a part's units are out of range");
            radix_[i] = (uint64_t)buffers;
            buffers *= quantity_[i] + 1;
            uint64_t units = quantity_[i] == 64 ? ~uint64_t(0) : ((uint64_t(1) << quantity_[i]) - 1);
            part_units_[i] = units << first_[i];
        }
        if (buffers > (long double)(uint64_t(1) << 62)) throw std::invalid_argument("too many buffer contents for 64-bit codes");
        buffers_ = (uint64_t)buffers;
        max_pairs_ = (~uint64_t(0) - 1) / buffers_;
        // C(n, k) for n <= 64: at most C(64, 32) < 2^61, exact in 64 bits
        for (int n = 0; n <= 64; ++n) {
            binom_[n][0] = 1;
            for (int k = 1; k <= 64; ++k) binom_[n][k] = n == 0 ? 0 : binom_[n - 1][k - 1] + binom_[n - 1][k];
        }
    }

    double value(uint64_t mask, uint64_t cons, std::vector<int> buf, double seconds, long long max_states) {
        if ((int)buf.size() != parts_) throw std::invalid_argument("the buffer needs one count per part");
        for (int i = 0; i < parts_; ++i) {
            if (buf[i] < 0 || buf[i] + __builtin_popcountll(mask & part_units_[i]) > quantity_[i])
                throw std::invalid_argument("a buffer count is out of range");
        }
        if (mask & ~full_) throw std::invalid_argument("an installed unit is out of range");
        timed_ = seconds >= 0;
        if (timed_)
            deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
        max_states_ = max_states < 0 ? std::numeric_limits<size_t>::max() : (size_t)max_states;
        return V(mask, cons, buf);
    }

    void reserve(size_t n) { table_.reserve(n); }
    size_t states() const { return table_.size(); }
    size_t bytes() const { return table_.bytes() + pairs_.size() * PAIR_BYTES; }
    // the bytes a programme of `states` states over `pairs` (installed, strategies) pairs holds once reserved
    static size_t bytes_for(size_t states, size_t pairs) { return Table::bytes_for(states) + pairs * PAIR_BYTES; }

private:
    uint64_t pair_id(uint64_t mask, uint64_t cons) {
        auto it = ids_.find({mask, cons});
        if (it != ids_.end()) return it->second;
        uint64_t id = pairs_.size();
        if (id >= max_pairs_) throw OptimalTooLarge("too many states for 64-bit codes");
        ids_.emplace(std::make_pair(mask, cons), id);
        pairs_.emplace_back(mask, cons);
        return id;
    }

    uint64_t code(uint64_t mask, uint64_t cons, const std::vector<int>& buf) {
        uint64_t b = 0;
        for (int i = 0; i < parts_; ++i) b += (uint64_t)buf[i] * radix_[i];
        return pair_id(mask, cons) * buffers_ + b;
    }

    int next_unit(uint64_t mask, int part) const {
        for (int u = first_[part]; u < first_[part] + quantity_[part]; ++u)
            if (!(mask >> u & 1)) return u;
        return -1;
    }

    uint64_t consistent_after(uint64_t mask, uint64_t cons, int unit) const {
        uint64_t out = 0;
        for (size_t s = 0; s < below_.size(); ++s)
            if ((cons >> s & 1) && (below_[s][unit] & ~mask) == 0) out |= uint64_t(1) << s;
        return out;
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
        int n = 0;
        for (int i = 0; i < parts_; ++i) {
            int in_bin = quantity_[i] - __builtin_popcountll(mask & part_units_[i]) - buf[i];
            if (in_bin <= 0) continue;
            n += in_bin;
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
            ranked.emplace_back(best, i, in_bin);
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
        double s = shake_loop(ranked, n, from_buffer);
        if (s == INF) throw OptimalStuck("no look allows any action: the assembly cannot proceed");
        if (table_.size() >= max_states_) throw OptimalTooLarge("over the state limit");
        table_.put(c, s);
        return s;
    }

    // OptimalSolver._order_statistics and _shake_loop: the parts by rank, their chances of being the
    // best visible one, the least over the prefixes
    double shake_loop(std::vector<std::tuple<double, int, int>>& ranked, int n, double from_buffer) const {
        double acc_pm = 0.0, acc_p = 0.0, s = INF;
        auto step = [&](double m, double p) {
            if (m == INF) return false;
            acc_pm += p * m;
            acc_p += p;
            s = std::min(s, (look_ + acc_pm + (1.0 - acc_p) * shake_) / acc_p);
            return true;
        };
        if (n == 0) {  // every unit left is in the buffer: no part is seen
            step(from_buffer, 1.0);
            return s;
        }
        std::sort(ranked.begin(), ranked.end());
        int k = std::min(visible_, n);
        double total = (double)(int64_t)binom_[n][k];
        int rank = 0;
        for (auto& [best, part, units] : ranked) {
            (void)part;
            uint64_t hits = binom_[n - rank][k] - binom_[n - rank - units][k];
            rank += units;
            if (!step(std::min(best, from_buffer), (double)(int64_t)hits / total)) break;
        }
        return s;
    }

    int n_units_, parts_ = 0;
    std::vector<int> first_, quantity_;
    std::vector<std::vector<uint64_t>> below_;
    std::vector<double> move_;
    double look_, shake_;
    int visible_, capacity_;
    uint64_t full_ = 0, buffers_ = 1, max_pairs_ = 0;
    std::vector<uint64_t> part_units_, radix_;
    uint64_t binom_[65][65] = {};
    std::unordered_map<std::pair<uint64_t, uint64_t>, uint64_t, PairHash> ids_;
    std::vector<std::pair<uint64_t, uint64_t>> pairs_;
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
                      double, double, int, int>(),
             py::arg("n_units"), py::arg("first"), py::arg("quantity"), py::arg("below"), py::arg("move"),
             py::arg("look"), py::arg("shake"), py::arg("visible"), py::arg("capacity"))
        .def("value", &OptimalCore::value, py::arg("mask"), py::arg("cons"), py::arg("buf"), py::arg("seconds"),
             py::arg("max_states"))
        .def("reserve", &OptimalCore::reserve, py::arg("states"))
        .def_static("bytes_for", &OptimalCore::bytes_for, py::arg("states"), py::arg("pairs"))
        .def_property_readonly("states", &OptimalCore::states)
        .def_property_readonly("bytes", &OptimalCore::bytes);
}
