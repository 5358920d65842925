// The exact optimum of a frontier window with the rest of the plan lumped (opportune.policies.window),
// compiled.
//
// The window is a plan of at most 64 units (the parts nearest the frontier, closed under their
// remaining ancestors), as the optimum's core (optimal.cpp) takes it; the plan's other remaining
// units are `others`: a count, not units of the state's masks.  They are in the bin, so they dilute
// the looks: a look is `visible` units drawn uniformly from the window's bin units and the others
// left in the bin, and its best move is an order statistic over the window's parts and one more
// group, the others, ranked last among equals (as a part declared after every window part).  An
// other seen can be buffered (a free location, `other_move`), not installed: the others come after
// the whole window, whose completion is the terminal state (value 0; what the others cost after it
// is the same whatever the window's policy did, so it does not change a decision).  A state is
// (installed window units, strategies, the window's buffer counts, others buffered).
//
// With `ready` (one mask a unit: the window units an other waits for, every one of its remaining
// ancestors a window unit), an other is ready once its mask is installed, and a ready one seen is
// installed (the others' move, `other_move`) less `ready_credit`, what it would cost after the window; one
// not ready may be buffered as without.  The state counts the ready others installed (which ones is not kept: a look sees
// one of the ready ones left, as many as are ready less those installed), so the window values installing
// first what unlocks the parts outside it.
//
// A joint window (several strategies' frontier windows at once) has `ends`: one mask a strategy, the
// units of that strategy's own window; a state of an open strategy whose end is installed is terminal,
// its value the window's units left (a move each, and a look each one not buffered) and that strategy's
// `end_costs` (the least where several end).  Without ends the full mask alone is terminal, at 0.
//
// The same operations as OptimalCore in the same order where there are no others, so the same
// doubles; the binomials are 128-bit where the bin holds more than 64 units.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <vector>

#include "memo_table.hpp"

namespace py = pybind11;

namespace {

using Clock = std::chrono::steady_clock;
using opportune_memo::PairIds;
using opportune_memo::PlanUnits;
using opportune_memo::Table;
using u128 = unsigned __int128;

struct WindowTooLarge : std::runtime_error {
    using std::runtime_error::runtime_error;
};
struct WindowTimeout : std::runtime_error {
    using std::runtime_error::runtime_error;
};

constexpr double INF = std::numeric_limits<double>::infinity();

class WindowCore : private PlanUnits {
public:
    WindowCore(int n_units, std::vector<int> first, std::vector<int> quantity,
               std::vector<std::vector<uint64_t>> below, std::vector<double> move, double look, double shake,
               int visible, int capacity, int others, double other_move, std::vector<uint64_t> ends,
               std::vector<double> end_costs, std::vector<uint64_t> ready, double ready_credit)
        : PlanUnits(n_units, std::move(first), std::move(quantity), std::move(below), std::move(move), look, shake,
                    visible, capacity),
          others_(others), other_move_(other_move), ends_(std::move(ends)), end_costs_(std::move(end_costs)),
          ready_(std::move(ready)), ready_credit_(ready_credit) {
        if ((int)ready_.size() > others_) throw std::invalid_argument("more ready others than others");
        ready_move_ = other_move_;  // with ready others: their move when installed
        if (!ready_.empty() && !(ready_move_ < INF)) throw std::invalid_argument("a ready other needs a finite move");
        for (uint64_t r : ready_)
            if (r & ~full_) throw std::invalid_argument("a ready other's window units are out of range");
        if (!(ready_credit_ >= 0.0) || ready_credit_ == INF)
            throw std::invalid_argument("the ready others' credit must be finite and at least 0");
        if (others_ < 0 || others_ > (1 << 20)) throw std::invalid_argument("the others' units are out of range");
        if (!ends_.empty() && ends_.size() != below_.size())
            throw std::invalid_argument("ends needs one mask per strategy (or none)");
        if (!end_costs_.empty() && end_costs_.size() != ends_.size())
            throw std::invalid_argument("end_costs needs one cost per end (or none)");
        for (uint64_t e : ends_)
            if (e & ~full_) throw std::invalid_argument("an end is out of range");
        most_buffered_ = capacity_ < 0 ? others_ : std::min(others_, capacity_);
        long double codes = buffers_ * (long double)(most_buffered_ + 1) * (long double)(ready_.size() + 1);
        if (codes > (long double)(uint64_t(1) << 62)) throw std::invalid_argument("too many buffer contents for 64-bit codes");
        contents_ = (uint64_t)codes;
        max_pairs_ = (~uint64_t(0) - 1) / contents_;
        // C(n, k) for the bin's units and k <= visible, exact in 128 bits (refused where it would not be)
        int top = n_units_ + others_, ks = std::min(visible_, top);
        binom_.assign((size_t)(top + 1) * (ks + 1), 0);
        ks_ = ks;
        for (int n = 0; n <= top; ++n) {
            binom(n, 0) = 1;
            for (int k = 1; k <= ks; ++k) {
                if (n == 0) continue;
                u128 a = binom(n - 1, k - 1), b = binom(n - 1, k);
                if (a >> 125 || b >> 125) throw std::invalid_argument("too many looks for 128-bit binomials");
                binom(n, k) = a + b;
            }
        }
    }

    double value(uint64_t mask, uint64_t cons, std::vector<int> buf, int ob, double seconds, long long max_states) {
        start(mask, buf, ob, seconds, max_states);
        return V(mask, cons, buf, ob, 0);
    }

    // Installing a ready other seen at a state (none installed yet): its move less the credit, and the
    // value after; inf where no other is ready.
    double install_other(uint64_t mask, uint64_t cons, std::vector<int> buf, int ob, double seconds,
                         long long max_states) {
        start(mask, buf, ob, seconds, max_states);
        if (std::min(ready_count(mask), others_ - ob) <= 0) return INF;
        return other_move_ready() - ready_credit_ + V(mask, cons, buf, ob, 1);
    }

    // What a decision needs at a state, whatever its look: per window part, the expected cost after
    // installing its next unit from the bin, after buffering one, after installing one from the buffer
    // (inf where not allowed); then after buffering an other, and the state's own value (the shake's
    // continuation).  3 * parts + 2 values.
    std::vector<double> moves(uint64_t mask, uint64_t cons, std::vector<int> buf, int ob, double seconds,
                              long long max_states) {
        start(mask, buf, ob, seconds, max_states);
        std::vector<double> out(3 * (size_t)parts_ + 2, INF);
        bool free = capacity_ < 0 || used(buf, ob) < capacity_;
        for (int i = 0; i < parts_; ++i) {
            int u = next_unit(mask, i);
            uint64_t after = u < 0 ? 0 : consistent_after(mask, cons, u);
            if (in_bin(mask, buf, i) > 0) {
                if (after) out[3 * i] = move_[i] + V(mask | uint64_t(1) << u, after, buf, ob, 0);
                if (free) {
                    buf[i] += 1;
                    out[3 * i + 1] = move_[i] + V(mask, cons, buf, ob, 0);
                    buf[i] -= 1;
                }
            }
            if (buf[i] && after) {
                buf[i] -= 1;
                out[3 * i + 2] = move_[i] + V(mask | uint64_t(1) << u, after, buf, ob, 0);
                buf[i] += 1;
            }
        }
        if (free && ob < others_ && other_move_ < INF) out[3 * parts_] = other_move_ + V(mask, cons, buf, ob + 1, 0);
        out[3 * parts_ + 1] = V(mask, cons, buf, ob, 0);
        return out;
    }

    void reserve(size_t n) { table_.reserve(n); }
    size_t states() const { return table_.size(); }
    size_t bytes() const { return table_.bytes() + pairs_.bytes() + binom_.size() * sizeof(u128); }

private:
    u128& binom(int n, int k) { return binom_[(size_t)n * (ks_ + 1) + k]; }

    void start(uint64_t mask, const std::vector<int>& buf, int ob, double seconds, long long max_states) {
        opportune_memo::check_state(*this, mask, buf);
        if (ob < 0 || ob > most_buffered_ || (capacity_ >= 0 && used(buf, ob) > capacity_))
            throw std::invalid_argument("the others buffered are out of range");
        timed_ = seconds >= 0;
        if (timed_)
            deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
        max_states_ = max_states < 0 ? std::numeric_limits<size_t>::max() : (size_t)max_states;
    }

    static int used(const std::vector<int>& buf, int ob) {
        int n = ob;
        for (int x : buf) n += x;
        return n;
    }

    uint64_t code(uint64_t mask, uint64_t cons, const std::vector<int>& buf, int ob, int k) {
        uint64_t id = pairs_.id(mask, cons, max_pairs_);
        if (id == ~uint64_t(0)) throw WindowTooLarge("too many states for 64-bit codes");
        return id * contents_ + (buffer_code(buf) * (uint64_t)(most_buffered_ + 1) + (uint64_t)ob) * (ready_.size() + 1)
               + (uint64_t)k;
    }

    // The others ready at `mask`: every remaining ancestor of theirs is a window unit installed.
    int ready_count(uint64_t mask) const {
        int n = 0;
        for (uint64_t r : ready_) n += (r & ~mask) == 0;
        return n;
    }

    // A ready other's move (the others' mean; other_move_ is inf where others are installed when ready).
    double other_move_ready() const { return ready_move_; }

    // OptimalCore::V with the others: one more group in the looks, bufferable, never installed
    double V(uint64_t mask, uint64_t cons, std::vector<int>& buf, int ob, int k) {
        uint64_t c = code(mask, cons, buf, ob, k);
        const double* cached = table_.find(c);
        if (cached) return *cached;
        if (!ends_.empty()) {  // a joint window: its full mask is past every open strategy's end
            double e = end_value(mask, cons, buf);
            if (e < INF) {
                table_.put(c, e);
                return e;
            }
        }
        if (mask == full_) {
            table_.put(c, 0.0);
            return 0.0;
        }
        if (timed_ && Clock::now() > deadline_) throw WindowTimeout("the window's programme passed its deadline");
        if (table_.size() >= max_states_) throw WindowTooLarge("over the state limit");
        bool free = capacity_ < 0 || used(buf, ob) < capacity_;
        auto value = [&](uint64_t m, uint64_t s, std::vector<int>& b) { return V(m, s, b, ob, k); };
        std::vector<std::tuple<double, int, int>> ranked;  // (best move, part, units in the bin)
        int n = opportune_memo::rank_parts(*this, mask, cons, buf, free, value, ranked);
        if (!ready_.empty()) {  // the others ready installed when seen (credited), the rest seen as nothing
            int in_bin = others_ - ob - k, r = std::min(ready_count(mask) - k, in_bin);
            n += in_bin;
            if (r > 0) ranked.emplace_back(ready_move_ - ready_credit_ + V(mask, cons, buf, ob, k + 1), parts_, r);
            if (in_bin - r > 0)  // buffered if a location is free, as below
                ranked.emplace_back(free ? other_move_ + V(mask, cons, buf, ob + 1, k) : INF, parts_ + 1, in_bin - r);
        } else if (others_ > ob) {  // the others in the bin: buffered if a location is free, else no move
            n += others_ - ob;
            bool take = free && other_move_ < INF;  // an infinite move: the others are seen as nothing
            ranked.emplace_back(take ? other_move_ + V(mask, cons, buf, ob + 1, k) : INF, parts_, others_ - ob);
        }
        double from_buffer = opportune_memo::best_from_buffer(*this, mask, cons, buf, value);
        double s = shake_loop(ranked, n, from_buffer);
        if (s == INF) throw WindowTooLarge("no look allows any action in the window");
        if (table_.size() >= max_states_) throw WindowTooLarge("over the state limit");
        table_.put(c, s);
        return s;
    }

    // OptimalCore::shake_loop, the binomials in 128 bits
    double shake_loop(std::vector<std::tuple<double, int, int>>& ranked, int n, double from_buffer) {
        opportune_memo::ShakeLoop loop{look_, shake_};
        if (n == 0) {
            loop.step(from_buffer, 1.0);
            return loop.value;
        }
        std::sort(ranked.begin(), ranked.end());
        int k = std::min(visible_, n);
        double total = (double)binom(n, k);
        int rank = 0;
        for (auto& [best, part, units] : ranked) {
            (void)part;
            u128 hits = binom(n - rank, k) - binom(n - rank - units, k);
            rank += units;
            if (!loop.step(std::min(best, from_buffer), (double)hits / total)) break;
        }
        return loop.value;
    }

    // A joint window's end in one of its open strategies: every unit of that strategy's end installed.
    // What it costs after: the window's units left, a look and a move each (a move for a buffered one), as
    // the others outside it, and that strategy's end cost (the least where several end).  INF: no end
    // (the window ends at its full mask alone, at 0).
    double end_value(uint64_t mask, uint64_t cons, const std::vector<int>& buf) const {
        double least = INF;
        for (size_t s = 0; s < ends_.size(); ++s)
            if ((cons >> s & 1) && (ends_[s] & ~mask) == 0)
                least = std::min(least, end_costs_.empty() ? 0.0 : end_costs_[s]);
        if (least == INF) return INF;
        for (int i = 0; i < parts_; ++i) {
            int left = quantity_[i] - __builtin_popcountll(mask & part_units_[i]);
            least += left * move_[i] + (left - buf[i]) * look_;
        }
        return least;
    }

    int others_;
    double other_move_;
    std::vector<uint64_t> ends_;
    std::vector<double> end_costs_;
    std::vector<uint64_t> ready_;
    double ready_credit_ = 0.0, ready_move_ = 1.0;
    int most_buffered_ = 0, ks_ = 0;
    uint64_t contents_ = 1, max_pairs_ = 0;
    std::vector<u128> binom_;
    PairIds pairs_;
    Table table_;
    bool timed_ = false;
    Clock::time_point deadline_;
    size_t max_states_ = 0;
};

}  // namespace

void bind_window(py::module_& m) {
    py::register_exception<WindowTooLarge>(m, "WindowCoreTooLarge", PyExc_RuntimeError);
    py::register_exception<WindowTimeout>(m, "WindowCoreTimeout", PyExc_RuntimeError);
    py::class_<WindowCore>(m, "WindowCore")
        .def(py::init<int, std::vector<int>, std::vector<int>, std::vector<std::vector<uint64_t>>, std::vector<double>,
                      double, double, int, int, int, double, std::vector<uint64_t>, std::vector<double>,
                      std::vector<uint64_t>, double>(),
             py::arg("n_units"), py::arg("first"), py::arg("quantity"), py::arg("below"), py::arg("move"),
             py::arg("look"), py::arg("shake"), py::arg("visible"), py::arg("capacity"), py::arg("others"),
             py::arg("other_move"), py::arg("ends") = std::vector<uint64_t>{}, py::arg("end_costs") = std::vector<double>{},
             py::arg("ready") = std::vector<uint64_t>{}, py::arg("ready_credit") = 0.0)
        .def("install_other", &WindowCore::install_other, py::arg("mask"), py::arg("cons"), py::arg("buf"),
             py::arg("others_buffered"), py::arg("seconds"), py::arg("max_states"))
        .def("value", &WindowCore::value, py::arg("mask"), py::arg("cons"), py::arg("buf"), py::arg("others_buffered"),
             py::arg("seconds"), py::arg("max_states"))
        .def("moves", &WindowCore::moves, py::arg("mask"), py::arg("cons"), py::arg("buf"), py::arg("others_buffered"),
             py::arg("seconds"), py::arg("max_states"))
        .def("reserve", &WindowCore::reserve, py::arg("states"))
        .def_property_readonly("states", &WindowCore::states)
        .def_property_readonly("bytes", &WindowCore::bytes);
}
