// Markov chains on the completions of a partial order (opportune.engine.sampling), compiled.
//
// The same random-scan Gibbs moves and the same random stream (splitmix64) as the pure-Python
// CompletionChains.run, so both give the same sequences for the same seed; here each chain keeps the
// index of every step, so a move finds its last predecessor and first successor in O(degree) instead
// of scanning the sequence.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstdint>
#include <stdexcept>
#include <vector>

#include "splitmix.hpp"

namespace py = pybind11;

namespace {

double next_uniform(uint64_t& state) { return opportune::uniform53(state); }

// `chains` spread-out admissible sequences of the steps `remaining` (an up-set), by Kahn's algorithm
// with a uniformly drawn minimal step each time (CompletionChains._start_orders, the same draws).
std::vector<std::vector<int>> start_orders(int n, const std::vector<std::vector<int>>& preds,
                                           const std::vector<std::vector<int>>& succs,
                                           const std::vector<int>& remaining, int chains, uint64_t& state) {
    std::vector<uint8_t> in(n, 0);
    for (int u : remaining) {
        if (u < 0 || u >= n) throw std::invalid_argument("step out of range");
        in[u] = 1;
    }
    std::vector<int> waiting0(n, 0);
    for (int u : remaining)
        for (int v : preds[u])
            if (in[v]) ++waiting0[u];
    std::vector<std::vector<int>> out(chains);
    std::vector<int> waiting, minimal;
    for (int c = 0; c < chains; ++c) {
        waiting = waiting0;
        minimal.clear();
        for (int u : remaining)
            if (!waiting[u]) minimal.push_back(u);
        auto& order = out[c];
        order.reserve(remaining.size());
        while (!minimal.empty()) {
            size_t i = (size_t)(next_uniform(state) * minimal.size());
            int u = minimal[i];
            minimal[i] = minimal.back();
            minimal.pop_back();
            order.push_back(u);
            for (int v : succs[u])
                if (in[v] && --waiting[v] == 0) minimal.push_back(v);
        }
    }
    return out;
}

class Chains {
public:
    // a population started here from `remaining` (see start_orders); the stream goes on after its draws
    static Chains start(int n, std::vector<std::vector<int>> preds, std::vector<std::vector<int>> succs,
                        const std::vector<int>& remaining, int chains, uint64_t state) {
        if (chains < 1) throw std::invalid_argument("at least one chain");
        check(n, preds);
        check(n, succs);
        auto orders = start_orders(n, preds, succs, remaining, chains, state);
        return Chains(n, std::move(preds), std::move(succs), std::move(orders), state);
    }

    Chains(int n, std::vector<std::vector<int>> preds, std::vector<std::vector<int>> succs,
           std::vector<std::vector<int>> orders, uint64_t state)
        : n_(n), preds_(std::move(preds)), succs_(std::move(succs)), orders_(std::move(orders)),
          remaining_(n, 0), state_(state) {
        if ((int)preds_.size() != n || (int)succs_.size() != n) throw std::invalid_argument("neighbour lists of size n");
        for (auto& order : orders_)
            for (int u : order) {
                if (u < 0 || u >= n) throw std::invalid_argument("step out of range");
                remaining_[u] = 1;
            }
        pos_.resize(orders_.size());
        for (size_t c = 0; c < orders_.size(); ++c) reindex(c, 0);
    }

    // steps moves on every chain (CompletionChains.run)
    void run(long steps) {
        for (size_t c = 0; c < orders_.size(); ++c) {
            auto& order = orders_[c];
            auto& pos = pos_[c];
            const int len = (int)order.size();
            if (len < 2) continue;
            for (long k = 0; k < steps; ++k) {
                int i = (int)(uniform() * len);
                int u = order[i];
                int p = -1, q = len;
                for (int v : preds_[u])
                    if (remaining_[v] && pos[v] > p) p = pos[v];
                for (int v : succs_[u])
                    if (pos[v] < q) q = pos[v];
                if (q - p > 2) {
                    int j = p + 1 + (int)(uniform() * (q - 1 - p));   // the slot, counted without u
                    if (j > i) {            // without u, slot j is index j + 1 with it: shift left
                        for (int t = i; t < j; ++t) { order[t] = order[t + 1]; pos[order[t]] = t; }
                    } else {
                        for (int t = i; t > j; --t) { order[t] = order[t - 1]; pos[order[t]] = t; }
                    }
                    order[j] = u;
                    pos[u] = j;
                }
            }
        }
    }

    // drop installed steps from every sequence (CompletionChains.advance)
    void drop(const std::vector<int>& gone) {
        for (int u : gone)
            if (u >= 0 && u < n_) remaining_[u] = 0;
        for (size_t c = 0; c < orders_.size(); ++c) {
            auto& order = orders_[c];
            size_t w = 0;
            for (size_t r = 0; r < order.size(); ++r)
                if (remaining_[order[r]]) order[w++] = order[r];
            order.resize(w);
            reindex(c, 0);
        }
    }

    // per chain: 1 / slots of each unit of `first`, and the Rao-Blackwellised position of each of `positions`
    py::tuple read(const std::vector<int>& first, const std::vector<int>& positions) const {
        std::vector<std::vector<double>> f(orders_.size()), e(orders_.size());
        for (size_t c = 0; c < orders_.size(); ++c) {
            const auto& pos = pos_[c];
            const int len = (int)orders_[c].size();
            for (int u : first) {
                int q = len;
                for (int v : succs_[u])
                    if (pos[v] < q) q = pos[v];
                f[c].push_back(1.0 / q);
            }
            for (int u : positions) {
                int p = -1, q = len;
                for (int v : preds_[u])
                    if (remaining_[v] && pos[v] > p) p = pos[v];
                for (int v : succs_[u])
                    if (pos[v] < q) q = pos[v];
                e[c].push_back((p + q) / 2.0 + 1);
            }
        }
        return py::make_tuple(f, e);
    }

    std::vector<std::vector<int>> orders() const { return orders_; }
    uint64_t state() const { return state_; }

private:
    double uniform() { return next_uniform(state_); }

    static const std::vector<std::vector<int>>& check(int n, const std::vector<std::vector<int>>& lists) {
        if ((int)lists.size() != n) throw std::invalid_argument("neighbour lists of size n");
        for (const auto& l : lists)
            for (int v : l)
                if (v < 0 || v >= n) throw std::invalid_argument("neighbour out of range");
        return lists;
    }

    void reindex(size_t c, size_t from) {
        auto& pos = pos_[c];
        pos.assign(n_, -1);
        const auto& order = orders_[c];
        for (size_t t = from; t < order.size(); ++t) pos[order[t]] = (int)t;
    }

    int n_;
    std::vector<std::vector<int>> preds_, succs_, orders_, pos_;
    std::vector<uint8_t> remaining_;
    uint64_t state_;
};

}  // namespace

void bind_chains(py::module_& m) {
    py::class_<Chains>(m, "Chains")
        .def(py::init<int, std::vector<std::vector<int>>, std::vector<std::vector<int>>,
                      std::vector<std::vector<int>>, uint64_t>(),
             py::arg("n"), py::arg("preds"), py::arg("succs"), py::arg("orders"), py::arg("state"))
        .def_static("start", &Chains::start, py::arg("n"), py::arg("preds"), py::arg("succs"),
                    py::arg("remaining"), py::arg("chains"), py::arg("state"))
        .def("run", &Chains::run, py::arg("steps"))
        .def("drop", &Chains::drop, py::arg("gone"))
        .def("read", &Chains::read, py::arg("first"), py::arg("positions"))
        .def("orders", &Chains::orders)
        .def("state", &Chains::state);
}
