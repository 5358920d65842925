// The exact optimum of the pile bin (opportune.policies.pile), compiled.
//
// The same recursion as the pure-Python PileSolver with no policy, with the same floating-point
// operations in the same order, so both give the same doubles:
//
//   V(s, W) = c_look + min(m(s, W), c_shake + S(s)),   S(s) = the shake loop over the windows W of s
//
// A state s is (installed units, consistent strategies, buffer counts); its windows are the sorted
// multisets of `visible` units of its bin, with the probabilities of drawing them one by one without
// replacement.  Every value is memoised in one open-addressing table of 16-byte slots (a 64-bit code
// of the state and window, and the value), at most half full: 32-64 bytes per stored value (reserved
// for the count known before the work, the table never doubles during it), plus the
// (installed, strategies) pairs interned once (fewer by the buffers and windows of each).  A state's
// values go into the table only once all of them are known, so a stop (the deadline, the state cap)
// leaves a table a later call goes on from.
//
// The pile's frontier window (opportune.policies.pile_window) is this programme on the window's plan with
// `others` more units lumped as one more group (index: the parts' count) after the parts, as window.cpp
// lumps them in the uniform bin: in the pile, in windows and in the buffer like a part's units, buffered
// at `other_move` (infinite: never), never installed; the window's plan complete is the terminal state.
// With no others the group is absent and the programme is the plain pile's.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <new>
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

struct PileTooLarge : std::runtime_error {
    using std::runtime_error::runtime_error;
};
struct PileTimeout : std::runtime_error {
    using std::runtime_error::runtime_error;
};
struct PileStuck : std::runtime_error {
    using std::runtime_error::runtime_error;
};

constexpr double INF = std::numeric_limits<double>::infinity();

using opportune_memo::PairIds;
using opportune_memo::PlanUnits;
using opportune_memo::Table;

struct Look {
    std::vector<int> window;  // sorted part indices
    double p;
};

class PileCore : private PlanUnits {
public:
    // The plan as PlanUnits takes it; `compensated`: the interpreter's sum() of floats is Neumaier's
    // (Python 3.12 on), else plain.
    PileCore(int n_units, std::vector<int> first, std::vector<int> quantity, std::vector<std::vector<uint64_t>> below,
             std::vector<double> move, double look, double shake, int visible, int capacity, bool compensated,
             int others, double other_move)
        : PlanUnits(n_units, std::move(first), std::move(quantity), std::move(below), std::move(move), look, shake,
                    visible, capacity),
          compensated_(compensated), others_(others), other_move_(other_move) {
        if (others_ < 0 || others_ > (1 << 20)) throw std::invalid_argument("the others' units are out of range");
        groups_ = parts_ + (others_ > 0);
        most_others_ = capacity_ < 0 ? others_ : std::min(others_, capacity_);
        // codes: ((pair id × buffers) + buffer) × windows + window, the last window code for S
        long double windows = 1;
        for (int j = 0; j < visible_; ++j) windows *= groups_ + 1;
        windows += 1;
        long double contents = buffers_ * (long double)(most_others_ + 1);
        if (contents * windows > (long double)(uint64_t(1) << 62))
            throw std::invalid_argument("too many buffer contents and windows for 64-bit codes");
        nbuffers_ = (uint64_t)contents;
        windows_ = (uint64_t)windows;
        max_pairs_ = (~uint64_t(0) - 1) / (nbuffers_ * windows_);
        no_order_.assign(groups_, 0);
        every_move_.assign(groups_, true);
    }

    double shake_value(uint64_t mask, uint64_t cons, std::vector<int> buf, double seconds, long long max_states) {
        check_buffer(buf);
        start(seconds, max_states);
        if (mask == full_) return 0.0;
        return S(mask, cons, buf);
    }

    double window_value(uint64_t mask, uint64_t cons, std::vector<int> buf, std::vector<int> window, double seconds,
                        long long max_states) {
        check_buffer(buf);
        std::sort(window.begin(), window.end());
        for (int w : window)
            if (w < 0 || w >= groups_) throw std::invalid_argument("a window's part is out of range");
        if ((int)window.size() > visible_) throw std::invalid_argument("a window larger than the visible units");
        start(seconds, max_states);
        if (mask == full_) return 0.0;
        return V(mask, cons, buf, window);
    }

    // PileSolver._after for a unit of `part` taken from `window` at (mask, cons, buf), leading to
    // (nmask, ncons, nbuf): the expectation over the hidden unit that replaces it, in one call
    double taken_value(uint64_t mask, uint64_t cons, std::vector<int> buf, std::vector<int> window, int part,
                       uint64_t nmask, uint64_t ncons, std::vector<int> nbuf, double seconds, long long max_states) {
        check_buffer(buf);
        check_buffer(nbuf);
        std::sort(window.begin(), window.end());
        auto at = std::find(window.begin(), window.end(), part);
        if (at == window.end()) throw std::invalid_argument("the part taken is not in the window");
        std::vector<int> hidden = bin_counts(mask, buf);
        for (int w : window) {
            if (w < 0 || w >= groups_) throw std::invalid_argument("a window's part is out of range");
            hidden[w] -= 1;
        }
        for (int c : hidden)
            if (c < 0) throw std::invalid_argument("a window that the bin cannot show");
        start(seconds, max_states);
        uint64_t base = nmask == full_ ? 0 : base_code(nmask, ncons, nbuf);
        return taken(nmask, ncons, nbuf, base, window, (size_t)(at - window.begin()), hidden);
    }

    // PileWindow._actions: S(s), then on every look of s the best move (ties: install, then buffer, then
    // `order`, the bin before the buffer) with its expected cost, None where the only moves install a part
    // `legal` refuses (the caller weighs the move against a shake); the same doubles as the Python loop over
    // the looks, in one call (every value it reads is stored by S(s)).
    // Look -> (kind, group, source, expected cost) or None.
    py::tuple actions(uint64_t mask, uint64_t cons, std::vector<int> buf, std::vector<int> order,
                      std::vector<bool> legal, double seconds, long long max_states) {
        check_buffer(buf);
        if ((int)order.size() != groups_ || (int)legal.size() != groups_)
            throw std::invalid_argument("one order and one legality per part (and the others)");
        start(seconds, max_states);
        if (mask == full_) throw std::invalid_argument("a complete state has no looks");
        double after_shake = S(mask, cons, buf);
        std::vector<int> bin = bin_counts(mask, buf);
        std::vector<Next> next = successors(mask, cons, buf, bin);
        py::dict out;
        py::str install("install"), buffer("buffer"), from_bin("bin"), from_buffer("buffer");
        for (const Look& l : looks(bin)) {
            Best best = best_move(mask, cons, buf, bin, next, l.window, order, legal);
            py::tuple key(l.window.size());
            for (size_t k = 0; k < l.window.size(); ++k) key[k] = py::int_(l.window[k]);
            if (best.kind < 0) {
                out[key] = py::none();
                continue;
            }
            out[key] = py::make_tuple(best.kind == 0 ? install : buffer, best.group,
                                      best.kind == 1 ? py::object(py::none())
                                                     : py::object(best.from_buffer ? from_buffer : from_bin),
                                      best.value);
        }
        return py::make_tuple(after_shake, out);
    }

    // Keep every expectation over the unit that replaces one taken (taken()): the same doubles, each
    // computed once however many moves lead into its state, in a second table (a state's rests, one unit
    // fewer than a look, are fewer than its looks where its bin holds more units than are visible; its
    // bytes counted in bytes()): for the windows' programmes, which live one state; the plain optimum's
    // table keeps its stated bytes per value
    void memo_taken(bool on) { memo_taken_ = on; }
    void reserve(size_t n) {  // the values' table and, on a plan written as ways, the sets decided live or dead
        table_.reserve(n);
        reserve_ways(n);
    }
    // a plan written as ways: per part, its ways as (blockers, needs) masks (PlanUnits::set_ways)
    void set_ways(std::vector<std::vector<opportune_memo::WaysLiveness::Way>> ways) { PlanUnits::set_ways(std::move(ways)); }
    size_t states() const { return table_.size(); }
    size_t bytes() const {
        return table_.bytes() + taken_.bytes() + pairs_.bytes() + ways_bytes();
    }

private:
    // ------------------------------------------------------------ plumbing

    void check_buffer(const std::vector<int>& buf) const {
        if ((int)buf.size() != groups_) throw std::invalid_argument("the buffer needs one count per part (and the others)");
        for (int i = 0; i < parts_; ++i)
            if (buf[i] < 0 || buf[i] > quantity_[i]) throw std::invalid_argument("a buffer count is out of range");
        if (groups_ > parts_ && (buf[parts_] < 0 || buf[parts_] > most_others_))
            throw std::invalid_argument("the others buffered are out of range");
    }

    void start(double seconds, long long max_states) {
        timed_ = seconds >= 0;
        if (timed_)
            deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
        max_states_ = max_states < 0 ? std::numeric_limits<size_t>::max() : (size_t)max_states;
    }

    uint64_t base_code(uint64_t mask, uint64_t cons, const std::vector<int>& buf) {
        uint64_t id = pairs_.id(mask, cons, max_pairs_);
        if (id == ~uint64_t(0)) throw PileTooLarge("too many states for 64-bit codes");
        uint64_t b = buffer_code(buf);
        if (groups_ > parts_) b += (uint64_t)buf[parts_] * (uint64_t)buffers_;
        return (id * nbuffers_ + b) * windows_;
    }

    uint64_t window_code(const std::vector<int>& w) const {
        uint64_t c = 0, r = 1;
        for (int x : w) {
            c += (uint64_t)(x + 1) * r;
            r *= groups_ + 1;
        }
        return c;
    }

    // Python's sum() of a generator of floats (started at the int 0)
    struct Sum {
        bool compensated, any = false;
        double f = 0.0, c = 0.0;
        void add(double x) {
            if (!any) {
                f = x;
                any = true;
                return;
            }
            double t = f + x;
            if (compensated) {
                if (std::fabs(f) >= std::fabs(x))
                    c += (f - t) + x;
                else
                    c += (x - t) + f;
            }
            f = t;
        }
        double result() const { return (compensated && c != 0.0 && std::isfinite(c)) ? f + c : f; }
    };

    // PileSolver._look_distribution: units drawn one by one without replacement (weights all 1).  Each
    // look (a sorted multiset, made in increasing order) sums the chances of its orders of drawing, in the
    // order the draw visits them (lexicographic: std::next_permutation from the sorted look), each order's
    // chance the product along its draws as the draw forms it, so the doubles are the draw's.
    double look_chance(const std::vector<int>& bin, int total) {
        order_.assign(drawn_.begin(), drawn_.end());
        double p = 0.0;
        do {
            double prob = 1.0;
            for (size_t d = 0; d < order_.size(); ++d) {
                int a = order_[d], before = 0;
                for (size_t e = 0; e < d; ++e) before += order_[e] == a;
                // sum(c * 1.0) of the counts left: whole numbers, exact
                prob = prob * (double)(bin[a] - before) * 1.0 / (double)(total - (int)d);
            }
            p = p + prob;
        } while (std::next_permutation(order_.begin(), order_.end()));
        return p;
    }

    void multisets(int k, int from, std::vector<int>& counts, const std::vector<int>& bin, int total,
                   std::vector<Look>& out) {
        if ((int)drawn_.size() == k) {
            out.push_back({drawn_, look_chance(bin, total)});
            return;
        }
        for (int i = from; i < groups_; ++i) {
            if (!counts[i]) continue;
            counts[i] -= 1;
            drawn_.push_back(i);
            multisets(k, i, counts, bin, total, out);
            drawn_.pop_back();
            counts[i] += 1;
        }
    }

    // the looks of a bin in increasing order (as sorted vectors), each with its chance
    std::vector<Look> looks(const std::vector<int>& bin) {
        int total = 0;
        for (int c : bin) total += c;
        int k = std::min(visible_, total);
        std::vector<Look> out;
        std::vector<int> counts(bin);
        drawn_.clear();
        multisets(k, 0, counts, bin, total, out);
        return out;
    }

    std::vector<int> bin_counts(uint64_t mask, const std::vector<int>& buf) const {
        std::vector<int> bin(groups_);
        for (int i = 0; i < parts_; ++i) bin[i] = in_bin(mask, buf, i);
        if (groups_ > parts_) bin[parts_] = others_ - buf[parts_];
        return bin;
    }

    // ------------------------------------------------------------ the recursion

    // V(s, W): the look at window W, the look's cost included
    double V(uint64_t mask, uint64_t cons, std::vector<int>& buf, const std::vector<int>& window) {
        if (mask == full_) return 0.0;
        return V_at(base_code(mask, cons, buf), mask, cons, buf, window);
    }

    // V(s, W) with the code of s (base_code) known
    double V_at(uint64_t base, uint64_t mask, uint64_t cons, std::vector<int>& buf, const std::vector<int>& window) {
        const double* v = table_.find(base + window_code(window));
        if (v) return *v;
        S(mask, cons, buf);  // stores every window's value of s
        v = table_.find(base + window_code(window));
        if (!v) throw std::invalid_argument("a window that the bin cannot show");
        return *v;
    }

    // S(s): a freshly drawn window
    double S(uint64_t mask, uint64_t cons, std::vector<int>& buf) {
        uint64_t base = base_code(mask, cons, buf);
        const double* cached = table_.find(base + windows_ - 1);
        if (cached) return *cached;
        // the clock at every new state: a state's work (its windows × moves × hidden units) is far more
        if (timed_ && Clock::now() > deadline_) throw PileTimeout("the pile's programme passed its deadline");
        std::vector<int> bin = bin_counts(mask, buf);
        std::vector<Look> ls = looks(bin);
        if (table_.size() + ls.size() + 1 > max_states_) throw PileTooLarge("over the state limit");
        std::vector<Next> next = successors(mask, cons, buf, bin);
        std::vector<double> m(ls.size());
        for (size_t j = 0; j < ls.size(); ++j) m[j] = move_value(mask, cons, buf, bin, next, ls[j].window);
        // OptimalSolver._solve_shake_loop over (m, p) sorted
        std::vector<std::pair<double, double>> mp(ls.size());
        for (size_t j = 0; j < ls.size(); ++j) mp[j] = {m[j], ls[j].p};
        std::sort(mp.begin(), mp.end());
        double acc_pm = 0.0, acc_p = 0.0, s = INF;
        for (auto& [mj, pj] : mp) {
            if (mj == INF) break;
            acc_pm += pj * mj;
            acc_p += pj;
            s = std::min(s, (look_ + acc_pm + (1.0 - acc_p) * shake_) / acc_p);
        }
        if (s == INF) throw PileStuck("no look allows any action: the assembly cannot proceed");
        // the state cap holds after the children too (they were stored since the check above)
        if (table_.size() + ls.size() + 1 > max_states_) throw PileTooLarge("over the state limit");
        double after_shake = shake_ + s;
        for (size_t j = 0; j < ls.size(); ++j)
            table_.put(base + window_code(ls[j].window), look_ + (m[j] == INF ? after_shake : std::min(m[j], after_shake)));
        table_.put(base + windows_ - 1, s);
        return s;
    }

    // The states a move of each group at s leads to, their codes found once for all the looks of s (not
    // once per look): installing the next unit (where an open strategy allows it: `after`), from the bin
    // or the buffer, and buffering a unit seen (where a location is free)
    struct Next {
        int unit = -1;
        uint64_t after = 0, install = 0, from_buffer = 0, buffered = 0;
        bool can_buffer = false;
    };
    // m(s, W): the best move's cost to go (INF: no move)
    double move_value(uint64_t mask, uint64_t cons, std::vector<int>& buf, const std::vector<int>& bin,
                      const std::vector<Next>& next, const std::vector<int>& window) {
        // every move a move (none refused), the ties' order of no matter: the least value, in the same calls
        return best_move(mask, cons, buf, bin, next, window, no_order_, every_move_).value;
    }

    std::vector<Next> successors(uint64_t mask, uint64_t cons, std::vector<int>& buf, const std::vector<int>& bin) {
        int used = 0;
        for (int c : buf) used += c;
        bool free = capacity_ < 0 || used < capacity_;
        std::vector<Next> out(groups_);
        for (int i = 0; i < groups_; ++i) {
            Next& n = out[i];
            n.can_buffer = free && bin[i] > 0 && (i < parts_ || other_move_ < INF);
            if (n.can_buffer) {
                buf[i] += 1;
                n.buffered = base_code(mask, cons, buf);
                buf[i] -= 1;
            }
            if (i == parts_ || (!bin[i] && !buf[i])) continue;
            n.unit = next_unit(mask, i);
            n.after = consistent_after(mask, cons, n.unit);
            uint64_t nmask = mask | uint64_t(1) << n.unit;
            if (!n.after || nmask == full_) continue;
            if (bin[i]) n.install = base_code(nmask, n.after, buf);
            if (buf[i]) {
                buf[i] -= 1;
                n.from_buffer = base_code(nmask, n.after, buf);
                buf[i] += 1;
            }
        }
        return out;
    }

    // A move ranked as PileWindow._actions ranks it: (value, kind: 0 install 1 buffer, order, from the buffer)
    struct Best {
        double value = INF;
        int kind = -1, order = 0, group = -1;
        bool from_buffer = false;
        void offer(double v, int k, int o, bool b, int g) {
            if (kind >= 0 && !(std::make_tuple(v, k, o, b) < std::make_tuple(value, kind, order, from_buffer))) return;
            value = v, kind = k, order = o, from_buffer = b, group = g;
        }
    };

    // The best move on `window` at s by that rank (installations of parts `legal` refuses left out); the
    // values as move_value computes them
    Best best_move(uint64_t mask, uint64_t cons, std::vector<int>& buf, const std::vector<int>& bin,
                   const std::vector<Next>& next, const std::vector<int>& window, const std::vector<int>& order,
                   const std::vector<bool>& legal) {
        Frame frame(*this);
        std::vector<int>& hidden = frame->hidden;
        hidden.assign(bin.begin(), bin.end());
        for (int w : window) hidden[w] -= 1;
        Best best;
        for (size_t a = 0; a < window.size(); ++a) {
            int i = window[a];
            if (a && window[a - 1] == i) continue;
            const Next& n = next[i];
            if (i == parts_) {
                if (n.can_buffer) {
                    buf[i] += 1;
                    best.offer(other_move_ + taken(mask, cons, buf, n.buffered, window, a, hidden), 1, order[i], false, i);
                    buf[i] -= 1;
                }
                continue;
            }
            if (n.after && legal[i])
                best.offer(move_[i] + taken(mask | uint64_t(1) << n.unit, n.after, buf, n.install, window, a, hidden), 0,
                           order[i], false, i);
            if (n.can_buffer) {
                buf[i] += 1;
                best.offer(move_[i] + taken(mask, cons, buf, n.buffered, window, a, hidden), 1, order[i], false, i);
                buf[i] -= 1;
            }
        }
        for (int i = 0; i < parts_; ++i) {
            const Next& n = next[i];
            if (!buf[i] || !legal[i] || !n.after) continue;
            uint64_t nmask = mask | uint64_t(1) << n.unit;
            double v = 0.0;
            if (nmask != full_) {
                buf[i] -= 1;
                v = V_at(n.from_buffer, nmask, n.after, buf, window);
                buf[i] += 1;
            }
            best.offer(move_[i] + v, 0, order[i], true, i);
        }
        return best;
    }

    // PileSolver._after for a unit taken from the window (window[a]): a hidden unit replaces it
    // (`base`: the code of the state after the move, base_code, unless it is complete)
    double taken(uint64_t mask, uint64_t cons, std::vector<int>& buf, uint64_t base, const std::vector<int>& window,
                 size_t a, const std::vector<int>& hidden) {
        Frame frame(*this);
        std::vector<int>& rest = frame->rest;
        rest.assign(window.begin(), window.end());
        rest.erase(rest.begin() + a);
        int total = 0;
        for (int c : hidden) total += c;
        bool done = mask == full_;
        if (total == 0) return done ? 0.0 : V_at(base, mask, cons, buf, rest);
        Sum sum{compensated_};
        std::vector<int>& next = frame->next;
        next.resize(rest.size() + 1);
        // the expectation is a function of the state after the move and the rest of the window alone (the
        // hidden units are that state's bin less the rest): kept, every other move into that state reads it
        uint64_t rest_code = done ? 0 : base + window_code(rest);
        if (!done && memo_taken_)
            if (const double* got = taken_.find(rest_code)) return *got;
        for (int j = 0; j < groups_; ++j) {
            int c = hidden[j];
            if (!c) continue;
            // sorted(rest + [j])
            size_t k = 0, r = 0;
            while (r < rest.size() && rest[r] <= j) next[k++] = rest[r++];
            next[k++] = j;
            while (r < rest.size()) next[k++] = rest[r++];
            double v = 0.0;
            if (!done) {
                const double* got = table_.find(base + window_code(next));
                v = got ? *got : V_at(base, mask, cons, buf, next);
            }
            sum.add((double)c / (double)total * v);
        }
        double out = sum.result();
        if (!done && memo_taken_) taken_.put(rest_code, out);
        return out;
    }

    // Scratch vectors per depth of the recursion (move_value -> taken -> V -> S -> move_value ...): a look's
    // moves allocate nothing once the deepest frame is made.  A deque: a new frame moves none of the others.
    struct Scratch {
        std::vector<int> hidden, rest, next;
    };
    std::deque<Scratch> frames_;
    size_t depth_ = 0;
    std::vector<int> drawn_, order_;  // looks()'s look being made, and an order of drawing it
    std::vector<int> no_order_;     // move_value's ranks: all equal
    std::vector<bool> every_move_;  // and nothing refused
    class Frame {
    public:
        explicit Frame(PileCore& core) : core_(core) {
            if (core_.depth_ == core_.frames_.size()) core_.frames_.emplace_back();
            scratch_ = &core_.frames_[core_.depth_++];
        }
        ~Frame() { --core_.depth_; }
        Frame(const Frame&) = delete;
        Frame& operator=(const Frame&) = delete;
        Scratch* operator->() const { return scratch_; }

    private:
        PileCore& core_;
        Scratch* scratch_;
    };

    bool compensated_;
    int others_, groups_ = 0, most_others_ = 0;
    double other_move_;
    uint64_t nbuffers_ = 1, windows_ = 1, max_pairs_ = 0;
    PairIds pairs_;
    Table table_;
    Table taken_;  // taken()'s expectations by the state after the move and the rest (memo_taken)
    bool memo_taken_ = false;
    bool timed_ = false;
    Clock::time_point deadline_;
    size_t max_states_ = 0;
};

}  // namespace

void bind_pile(py::module_& m) {
    py::register_exception<PileTooLarge>(m, "PileTooLarge", PyExc_RuntimeError);
    py::register_exception<PileTimeout>(m, "PileTimeout", PyExc_RuntimeError);
    py::register_exception<PileStuck>(m, "PileStuck", PyExc_RuntimeError);
    py::class_<PileCore>(m, "PileCore")
        .def(py::init<int, std::vector<int>, std::vector<int>, std::vector<std::vector<uint64_t>>, std::vector<double>,
                      double, double, int, int, bool, int, double>(),
             py::arg("n_units"), py::arg("first"), py::arg("quantity"), py::arg("below"), py::arg("move"),
             py::arg("look"), py::arg("shake"), py::arg("visible"), py::arg("capacity"), py::arg("compensated"),
             py::arg("others") = 0, py::arg("other_move") = INF)
        .def("shake_value", &PileCore::shake_value, py::arg("mask"), py::arg("cons"), py::arg("buf"),
             py::arg("seconds"), py::arg("max_states"))
        .def("window_value", &PileCore::window_value, py::arg("mask"), py::arg("cons"), py::arg("buf"),
             py::arg("window"), py::arg("seconds"), py::arg("max_states"))
        .def("taken_value", &PileCore::taken_value, py::arg("mask"), py::arg("cons"), py::arg("buf"), py::arg("window"),
             py::arg("part"), py::arg("nmask"), py::arg("ncons"), py::arg("nbuf"), py::arg("seconds"),
             py::arg("max_states"))
        .def("actions", &PileCore::actions, py::arg("mask"), py::arg("cons"), py::arg("buf"), py::arg("order"),
             py::arg("legal"), py::arg("seconds"), py::arg("max_states"))
        .def("reserve", &PileCore::reserve, py::arg("states"))
        .def("memo_taken", &PileCore::memo_taken, py::arg("on"))
        .def("set_ways", &PileCore::set_ways, py::arg("ways"))
        .def_property_readonly("states", &PileCore::states)
        .def_property_readonly("bytes", &PileCore::bytes);
}
